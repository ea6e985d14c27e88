"""One datagram per frame through a master, with the least work: the mailbox's port.

Mailbox traffic is one datagram per frame (the FPWR of a request, the FPRD polls of the
answer), and on an in-process chain its cost is mostly the master's own: building a
frame from objects and decoding the answer into objects takes longer than the emulated
slaves take to process it. :class:`SinglePort` does what :meth:`Master.exchange` does
for one datagram — the master's next frame index, its source MAC, the cycles due before
the frame, the frame sent again when lost, the same statistics — with the frame packed
and its answer read in place (:func:`lolacli.wire.frame.encode_single` /
:func:`~lolacli.wire.frame.decode_single`, which give the general codec's bytes). A
:class:`~lolacli.master.mailbox.MailboxClient` takes it as its port.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from lolacli.errors import TransportError
from lolacli.wire.frame import Datagram, decode_frame, decode_single, encode_single, ethernet_head

if TYPE_CHECKING:
    from lolacli.master.core import Master


class SinglePort:
    """A :class:`~lolacli.master.mailbox.DatagramPort` over ``master``."""

    def __init__(self, master: Master) -> None:
        self.master = master
        self.transport = master.transport
        self._head = ethernet_head(master.eni.master.destination_mac, master.source_mac)

    def now_ns(self) -> int:
        return self.transport.now_ns()

    def idle(self, duration_ns: int) -> None:
        self.master.idle(duration_ns)

    def exchange_one(self, datagram: Datagram) -> Datagram:
        """``datagram`` in a frame of its own and as it came back; TransportError after
        the master's retries."""
        master = self.master
        master.run_due_cycles()
        stats = master.stats
        options = master.options
        for _ in range(options.frame_retries + 1):
            index = master.new_index()
            frame = encode_single(self._head, datagram.cmd, index, datagram.address, datagram.data)
            master.last_sent_ns = self.transport.send(frame)
            stats.frames_sent += 1
            stats.acyclic_frames += 1
            got = master.await_frame(index, options.frame_timeout_ns, master.last_sent_ns)
            if got is None:
                stats.frames_lost += 1
                continue
            one = decode_single(got.frame)
            if one is None:  # not a single datagram after all: the general decoder
                return decode_frame(got.frame).datagrams[0]
            cmd, index, address, data, wkc = one
            return Datagram(cmd, index, address, data, wkc)
        raise TransportError(
            f"no answer to {datagram.mnemonic} 0x{datagram.adp:04X}:0x{datagram.ado:04X} "
            f"after {options.frame_retries + 1} frames"
        )


__all__ = ["SinglePort"]
