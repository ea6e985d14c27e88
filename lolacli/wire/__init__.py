"""EtherCAT wire codec: frames, datagrams, mailbox, CoE, SDO. Pure: bytes in, values out."""

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
