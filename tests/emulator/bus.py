"""A tiny test master over the in-process chain: datagrams, mailbox SDO, ENI InitCmds.

It speaks only through frame bytes (``Chain.process``) and encodes mailbox/CoE/SDO with
the wire package's codecs, so the emulator is checked against an independent encoder.
"""

from __future__ import annotations

import struct
from pathlib import Path

from lolacli.emulator.chain import Chain
from lolacli.eni.model import Eni, InitCmd
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram, decode_frame, encode_frame, make_frame
from lolacli.wire.mailbox import MailboxType, decode_mailbox, encode_mailbox, make_mailbox
from lolacli.wire.sdo import (
    SdoAbort,
    SdoDownloadRequest,
    SdoDownloadSegmentRequest,
    SdoUploadRequest,
    SdoUploadResponse,
    SdoUploadSegmentRequest,
    SdoUploadSegmentResponse,
    decode_sdo,
    encode_sdo,
)

EXAMPLES = Path(__file__).resolve().parents[2] / "lolacli" / "eni_examples"
CYCLE_NS = 1_000_000
POLLS = 50  # frames a master polls for what the slave's firmware does after a frame


class Bus:
    def __init__(self, chain: Chain) -> None:
        self.chain = chain
        self.t_ns = 1_000_000_000
        self.counter = 0

    def frame(self, *datagrams: Datagram) -> tuple[Datagram, ...]:
        raw = encode_frame(make_frame(list(datagrams)), pad=True)
        reply, _delay = self.chain.process(raw, self.t_ns)
        self.t_ns += 50_000
        assert reply is not None
        return decode_frame(reply).datagrams

    def one(self, cmd: int, adp: int, ado: int, data: bytes | int) -> Datagram:
        return self.frame(Datagram.physical(cmd, adp, ado, data))[0]

    def fprd(self, station: int, ado: int, n: int) -> bytes:
        d = self.one(Command.FPRD, station, ado, n)
        assert d.wkc == 1, f"FPRD 0x{station:04X}:0x{ado:04X} wkc {d.wkc}"
        return d.data

    def fpwr(self, station: int, ado: int, data: bytes) -> int:
        return self.one(Command.FPWR, station, ado, data).wkc

    # ------------------------------------------------------------ mailbox
    def mailbox_exchange(
        self, station: int, payload: bytes, out: tuple[int, int], inn: tuple[int, int]
    ) -> bytes:
        self.counter = self.counter % 7 + 1
        box = encode_mailbox(
            make_mailbox(MailboxType.CoE, payload, counter=self.counter), buffer_bytes=out[1]
        )
        assert self.fpwr(station, out[0], box) == 1
        # the slave's firmware answers after the frame: poll the read mailbox as masters do
        for _ in range(POLLS):
            if self.fprd(station, 0x080D, 1)[0] & 0x08:
                break
        else:
            raise AssertionError("mailbox in not full")
        reply = self.fprd(station, inn[0], inn[1])
        return decode_mailbox(reply).payload

    def sdo_upload(self, station: int, index: int, sub: int, mbx: tuple[tuple[int, int], ...]):
        out, inn = mbx
        first = decode_sdo(
            self.mailbox_exchange(station, encode_sdo(SdoUploadRequest(index, sub)), out, inn)
        )
        if isinstance(first, SdoAbort):
            return first
        assert isinstance(first, SdoUploadResponse)
        if first.expedited:
            return first.data
        data = bytearray(first.data)
        toggle = False
        while len(data) < first.complete_size:
            seg = decode_sdo(
                self.mailbox_exchange(
                    station, encode_sdo(SdoUploadSegmentRequest(toggle)), out, inn
                )
            )
            assert isinstance(seg, SdoUploadSegmentResponse), seg
            assert seg.toggle == toggle
            data += seg.data
            toggle = not toggle
            if seg.last:
                break
        return bytes(data[: first.complete_size])

    def sdo_download(
        self,
        station: int,
        index: int,
        sub: int,
        data: bytes,
        mbx: tuple[tuple[int, int], ...],
        *,
        segment_bytes: int = 0,
    ):
        out, inn = mbx
        if len(data) <= 4:
            request = SdoDownloadRequest(index, sub, data)
            return decode_sdo(self.mailbox_exchange(station, encode_sdo(request), out, inn))
        first = data[:segment_bytes] if segment_bytes else data
        request = SdoDownloadRequest(index, sub, first, expedited=False, complete_size=len(data))
        reply = decode_sdo(self.mailbox_exchange(station, encode_sdo(request), out, inn))
        rest, toggle = data[len(first) :], False
        while rest:
            chunk, rest = rest[:segment_bytes], rest[segment_bytes:]
            seg = SdoDownloadSegmentRequest(chunk, toggle=toggle, last=not rest)
            reply = decode_sdo(self.mailbox_exchange(station, encode_sdo(seg), out, inn))
            toggle = not toggle
        return reply

    # -------------------------------------------------------- ENI driving
    def init_cmd(self, cmd: InitCmd) -> Datagram:
        if cmd.logical_address is not None:
            d = Datagram.logical(cmd.cmd, cmd.logical_address, cmd.data)
        else:
            d = Datagram.physical(cmd.cmd, cmd.adp, cmd.ado, cmd.data)
        return self.frame(d)[0]

    def transition(self, eni: Eni, name: str) -> None:
        """Run the master's and every slave's InitCmds (and CoE InitCmds) of ``name``."""
        for cmd in eni.master.init_cmds:
            if name in cmd.transitions:
                self.init_cmd(cmd)
        for slave in eni.slaves:
            mb = slave.mailbox
            for cmd in slave.init_cmds:
                if name not in cmd.transitions:
                    continue
                if mb is not None and cmd.ado == 0x0120 and name == "PS":
                    self._coe_init(slave.station_address, mb, name)
                # a validated command is repeated until it matches (its validate timeout):
                # the slave's firmware handles a state request after the frame
                for _ in range(POLLS if cmd.validate_data is not None else 1):
                    result = self.init_cmd(cmd)
                    if cmd.validate_data is None:
                        break
                    mask = cmd.validate_mask or b"\xff" * len(cmd.validate_data)
                    got = bytes(a & m for a, m in zip(result.data, mask, strict=False))
                    if got == cmd.validate_data:
                        break
                if cmd.expected_wkc is not None:
                    assert result.wkc == cmd.expected_wkc, (slave.name, cmd.comment, result)
                if cmd.validate_data is not None:
                    assert got == cmd.validate_data, (slave.name, cmd.comment, result.data)

    def _coe_init(self, station: int, mb, name: str) -> None:
        mbx = ((mb.out_start, mb.out_length_bytes), (mb.in_start, mb.in_length_bytes))
        for c in mb.coe_init_cmds:
            if name in c.transitions:
                reply = self.sdo_download(station, c.index, c.subindex, c.data, mbx)
                assert not isinstance(reply, SdoAbort), (c.comment, reply)

    def cycle(self, eni: Eni, outputs: bytes | None = None) -> tuple[tuple[Datagram, ...], bytes]:
        """One cyclic frame of the ENI; returns the datagrams and the LRW/LRD data."""
        frame = eni.cyclic_frames[0]
        datagrams = []
        for c in frame.commands:
            if c.logical_address is not None:
                data = outputs if outputs is not None else bytes(c.data_length_bytes)
                datagrams.append(
                    Datagram.logical(
                        c.cmd, c.logical_address, data.ljust(c.data_length_bytes, b"\0")
                    )
                )
            else:
                datagrams.append(
                    Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes)
                )
        self.t_ns += CYCLE_NS
        replies = self.frame(*datagrams)
        return replies, replies[0].data

    def bring_up(self, eni: Eni) -> None:
        """INIT -> PREOP -> SAFEOP -> OP as the ENI says."""
        self.transition(eni, "IP")
        self.transition(eni, "PS")
        self.cycle(eni)
        self.transition(eni, "SO")


def u16(value: int) -> bytes:
    return struct.pack("<H", value)
