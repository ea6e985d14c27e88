"""The emulated EtherCAT slave chain.

Pure core (frame bytes in, frame bytes out): :class:`~lolacli.emulator.esc.Esc` (one slave
controller), :class:`~lolacli.emulator.chain.Chain` (a line of them with its timing model),
:mod:`~lolacli.emulator.sii` (EEPROM images), the mailbox protocols in
:mod:`~lolacli.emulator.mailbox` (the SDO server, FoE).
:func:`build_chain` turns an ENI model into a chain with device models behind every ESC.
Transport: :mod:`lolacli.emulator.rawsock` serves a chain on a network interface.

    from lolacli.files import load_eni
    from lolacli.emulator import build_chain

    chain = build_chain(load_eni("lolacli/eni_examples/lola.xml"))
    reply, delay_ns = chain.process(frame_bytes, t_ns)
"""

from lolacli.emulator.chain import Chain, ChainTiming, Faults
from lolacli.emulator.esc import DcClock, Esc, EscConfig
from lolacli.emulator.slave import build_chain, build_slave, device_of

__all__ = [
    "Chain",
    "ChainTiming",
    "DcClock",
    "Esc",
    "EscConfig",
    "Faults",
    "build_chain",
    "build_slave",
    "device_of",
]
