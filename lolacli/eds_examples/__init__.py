"""EDS files of the LOLA CAN gateway's sensor nodes (written by tools/make_gateway_eds.py)."""
