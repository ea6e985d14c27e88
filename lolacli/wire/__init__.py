"""EtherCAT wire codec: frames, datagrams, mailbox, CoE, SDO. Pure: bytes in, values out.

The names below are imported from their modules on first use: importing a submodule
(``lolacli.wire.commands``, as ``capture analyze`` does) does not import
:mod:`lolacli.wire.frame` (~3 ms of its dataclasses).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from lolacli.wire.commands import Command, mnemonic
    from lolacli.wire.frame import (
        ETHERTYPE_ECAT,
        Datagram,
        EthernetHeader,
        Frame,
        decode_any,
        decode_datagrams,
        decode_ecat_payload,
        decode_frame,
        encode_frame,
        frame_bytes_on_wire,
        make_frame,
    )

__all__ = [
    "ETHERTYPE_ECAT",
    "Command",
    "Datagram",
    "EthernetHeader",
    "Frame",
    "decode_any",
    "decode_datagrams",
    "decode_ecat_payload",
    "decode_frame",
    "encode_frame",
    "frame_bytes_on_wire",
    "make_frame",
    "mnemonic",
]

#: each public name and the module that defines it
_MODULES: dict[str, str] = {
    name: "commands" if name in ("Command", "mnemonic") else "frame" for name in __all__
}


def __getattr__(name: str) -> Any:
    """A name of :data:`__all__`, imported from its module (then kept here)."""
    module = _MODULES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
