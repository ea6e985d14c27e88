"""The one place that opens a raw EtherCAT socket (Linux AF_PACKET, ethertype 0x88A4).

Both sides use it: the emulator serving a chain on an interface
(:mod:`lolacli.emulator.rawsock`) and the master talking to a bus
(:class:`lolacli.master.transport.RawSocketTransport`).
"""

from __future__ import annotations

import errno
import socket

from lolacli.errors import TransportError

ETH_P_ECAT = 0x88A4
PACKET_OUTGOING = 4  # sll_pkttype of a frame this host sent
MAX_FRAME_BYTES = 1600
#: SO_TIMESTAMPNS (= SCM_TIMESTAMPNS) of asm-generic/socket.h, 64-bit struct timespec:
#: the kernel stamps each received frame with CLOCK_REALTIME when it enters the stack
SO_TIMESTAMPNS = 35


def open_socket(iface: str) -> socket.socket:
    """A raw packet socket bound to ``iface`` for ethertype 0x88A4; TransportError if not."""
    try:
        sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_ECAT))
    except PermissionError as exc:
        raise TransportError(
            f"no permission for a raw socket ({exc.strerror}); run as root "
            "or give python CAP_NET_RAW"
        ) from None
    except OSError as exc:
        raise TransportError(f"cannot open a raw socket: {exc.strerror or exc}") from None
    try:
        sock.bind((iface, ETH_P_ECAT))
    except OSError as exc:
        sock.close()
        if exc.errno in (errno.ENODEV, errno.ENXIO) or "No such device" in str(exc):
            raise TransportError(f"no such interface: {iface}") from None
        raise TransportError(f"cannot bind to {iface}: {exc.strerror or exc}") from None
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    return sock
