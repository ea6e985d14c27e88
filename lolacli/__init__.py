"""lolacli: EtherCAT bus commissioning and diagnostics.

The library is layered (see docs/ARCHITECTURE in DESIGN.md): ``wire`` (frame codec), ``eni``
(network description), ``timing`` (frame-time model), ``capture`` (pcap/pcapng analysis),
``emulator`` and ``devices`` (a slave chain in software), ``cli`` (the command line).
Importing ``lolacli`` imports nothing heavy.
"""

__version__ = "0.1.0"
