"""lolacli: EtherCAT bus commissioning and diagnostics, from the command line and from
Python.

The library is layered (docs/python-api.md): ``wire`` (frame codec), ``eni`` (network
description), ``timing`` (frame-time model), ``capture`` (pcap/pcapng analysis),
``emulator`` and ``devices`` (a slave chain in software), ``master`` (an ENI-driven
master and the Bus Variables), ``sdo`` (SDO over EtherCAT and CANopen), ``cli`` (the
command line). Importing ``lolacli`` imports nothing heavy; :func:`load_eni` (``None``:
the embedded LOLA chain) is the way in.
"""

from lolacli.files import load_eni, lola_path

__version__ = "0.1.0"
__all__ = ["__version__", "load_eni", "lola_path"]
