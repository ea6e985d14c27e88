"""Mailbox data link layer (ETG.1000.4 §6.7, the slave stack's mailbox handler) against a
master that re-sends.

The ESC takes a mailbox write at once and sets the write SM full; the slave's firmware
reads it after the frame (the emulator runs that work after the answer, as on hardware).
SOEM's ``ecx_srconfirm`` sends the identical frame again when no answer came within
EC_TIMEOUTRET (2 ms), so a slave sees repeats of a write: into a full mailbox (refused,
WKC 0), or after the firmware took the first one (dropped by its unchanged counter). The
repeat request (toggle of SM1 activate 0x080E bit 1) puts the last answer into the read mailbox
again. Frames here go through ``Chain.process(..., defer_cycles=True)`` as the raw-socket
server calls it, the firmware running when the server would run it.
"""

from __future__ import annotations

import struct
from dataclasses import replace

import pytest

from lolacli.emulator.core import core_available
from lolacli.emulator.slave import build_chain
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Datagram, decode_frame, encode_frame, make_frame
from lolacli.wire.mailbox import MailboxType, decode_mailbox, encode_mailbox, make_mailbox
from lolacli.wire.sdo import SdoUploadRequest, SdoUploadResponse, decode_sdo, encode_sdo
from tests.emulator.bus import EXAMPLES, Bus
from tests.emulator.test_general_path import count_register_frames

ENI = load_eni(EXAMPLES / "single_drive.xml")
SLAVE = ENI.slaves[0]
STATION = SLAVE.station_address
assert SLAVE.mailbox is not None
OUT = (SLAVE.mailbox.out_start, SLAVE.mailbox.out_length_bytes)
IN = (SLAVE.mailbox.in_start, SLAVE.mailbox.in_length_bytes)
SM0_STATUS, SM1_STATUS = 0x0805, 0x080D
FULL = 0x08


class Master:
    """Frames as a master sends them, through the chain as the server runs it."""

    def __init__(self, engine: str | None = None) -> None:
        self.chain = build_chain(ENI, engine=engine)
        bus = Bus(self.chain)
        bus.transition(ENI, "IP")  # mailboxes configured, PREOP
        self.t_ns = bus.t_ns
        self.esc = self.chain.slaves[0]

    def send(self, cmd: int, ado: int, data: bytes | int, index: int = 0) -> Datagram:
        d = replace(Datagram.physical(cmd, STATION, ado, data), index=index)
        frame = encode_frame(make_frame([d]), pad=True)
        self.t_ns += 20_000
        reply, _ = self.chain.process(frame, self.t_ns, defer_cycles=True)
        assert reply is not None
        return decode_frame(reply).datagrams[0]

    def firmware(self) -> None:
        """The server's idle time after an answer: the slave's firmware runs."""
        self.chain.run_deferred_cycles()

    def write_box(self, counter: int, index: int, sub: int = 0) -> bytes:
        box = make_mailbox(
            MailboxType.CoE, encode_sdo(SdoUploadRequest(index, sub)), counter=counter
        )
        return encode_mailbox(box, buffer_bytes=OUT[1])

    def status(self, register: int) -> int:
        return self.send(C.FPRD, register, 1).data[0]

    def read_box(self) -> Datagram:
        return self.send(C.FPRD, IN[0], IN[1])


def _answer(d: Datagram) -> SdoUploadResponse:
    message = decode_sdo(decode_mailbox(d.data).payload)
    assert isinstance(message, SdoUploadResponse), message
    return message


def test_a_write_into_the_full_mailbox_is_not_taken_and_the_retry_is() -> None:
    m = Master()
    first = m.write_box(1, 0x1000)
    assert m.send(C.FPWR, OUT[0], first).wkc == 1
    assert m.status(SM0_STATUS) & FULL  # taken by the ESC, not yet by the firmware
    second = m.write_box(2, 0x1018, 1)
    assert m.send(C.FPWR, OUT[0], second).wkc == 0  # full: the bytes go nowhere
    m.firmware()
    assert not m.status(SM0_STATUS) & FULL
    assert m.status(SM1_STATUS) & FULL
    answer = _answer(m.read_box())
    assert answer.index == 0x1000  # the first request's answer, not overwritten
    assert m.send(C.FPWR, OUT[0], second).wkc == 1  # the master's retry
    m.firmware()
    assert _answer(m.read_box()).index == 0x1018
    assert m.esc.counters.mailbox_requests == 2


def test_a_repeated_write_with_the_same_counter_is_served_once() -> None:
    """SOEM sends the identical frame again when the answer to its write was lost: the
    firmware took the first copy already, the second has the same counter."""
    m = Master()
    box = m.write_box(3, 0x1000)
    assert m.send(C.FPWR, OUT[0], box, index=7).wkc == 1  # ...this answer lost
    m.firmware()
    assert m.status(SM1_STATUS) & FULL
    assert m.send(C.FPWR, OUT[0], box, index=7).wkc == 1  # the copy: SM0 was empty again
    m.firmware()  # the firmware leaves it while its answer waits in SM1
    assert m.status(SM0_STATUS) & FULL
    assert _answer(m.read_box()).index == 0x1000
    m.firmware()  # now it reads the copy ...
    assert not m.status(SM0_STATUS) & FULL
    assert not m.status(SM1_STATUS) & FULL  # ... and drops it: one answer only
    assert m.read_box().wkc == 0  # an empty read mailbox gives nothing
    assert m.esc.counters.mailbox_requests == 1
    next_box = m.write_box(4, 0x1018, 2)  # the next service, next counter
    assert m.send(C.FPWR, OUT[0], next_box).wkc == 1
    m.firmware()
    assert _answer(m.read_box()).index == 0x1018


def test_counter_zero_is_never_a_repeat() -> None:
    """Counter 0: a master without mailbox counters; every write is a new service."""
    m = Master()
    for _ in range(3):
        assert m.send(C.FPWR, OUT[0], m.write_box(0, 0x1000)).wkc == 1
        m.firmware()
        assert _answer(m.read_box()).index == 0x1000
    assert m.esc.counters.mailbox_requests == 3


@pytest.mark.parametrize(
    "engine",
    [
        "python",
        pytest.param("c", marks=pytest.mark.skipif(not core_available(), reason="no C core")),
    ],
)
def test_the_repeat_request_puts_the_last_answer_in_the_mailbox_again(engine: str) -> None:
    """The master's read of the answer came back damaged: it toggles SM1's repeat bit
    (0x080E bit 1), waits for the PDI acknowledge (0x080F bit 1) and reads again. With the
    C core, the toggle takes its register path, which has the mailbox's work done after."""
    m = Master(engine)
    assert m.send(C.FPWR, OUT[0], m.write_box(5, 0x1018, 1)).wkc == 1
    m.firmware()
    first = m.read_box()
    assert first.wkc == 1 and not m.status(SM1_STATUS) & FULL  # read: the slave forgets
    activate = m.send(C.FPRD, 0x080E, 2).data
    toggled = bytes([activate[0] ^ 0x02, activate[1]])
    taken = count_register_frames(m.chain)
    assert m.send(C.FPWR, 0x080E, toggled).wkc == 1
    assert taken[0] == (engine == "c")
    m.firmware()
    assert m.send(C.FPRD, 0x080F, 1).data[0] & 0x02 == toggled[0] & 0x02  # acknowledged
    assert m.status(SM1_STATUS) & FULL
    again = m.read_box()
    assert again.data == first.data  # the same answer, byte for byte
    assert m.esc.counters.mailbox_requests == 1


def test_init_forgets_the_counter() -> None:
    """Back in INIT the mailbox handler stops: the next service may reuse counter 1."""
    m = Master()
    assert m.send(C.FPWR, OUT[0], m.write_box(1, 0x1000)).wkc == 1
    m.firmware()
    m.read_box()
    assert m.send(C.FPWR, 0x0120, struct.pack("<H", 0x01)).wkc == 1
    m.firmware()
    assert m.esc.al_state == 1
    bus = Bus(m.chain)
    bus.t_ns = m.t_ns
    bus.transition(ENI, "IP")
    m.t_ns = bus.t_ns
    assert m.send(C.FPWR, OUT[0], m.write_box(1, 0x1018, 1)).wkc == 1
    m.firmware()
    assert _answer(m.read_box()).index == 0x1018


@pytest.mark.skipif(not core_available(), reason="no C core")
def test_a_repeat_into_a_read_mailbox_among_the_registers_answers_as_the_reference() -> None:
    """A master may put the read mailbox's buffer among the registers (0x0F00 here) and
    toggle its repeat bit in the same write: the repeat stores the last answer there at
    once, so a read of it later in the frame sees it. The C core's register path, which
    does the mailbox's work after the frame, leaves such a frame to the Python path."""
    replies = []
    for engine in ("c", "python"):
        m = Master(engine)
        assert m.send(C.FPWR, OUT[0], m.write_box(5, 0x1018, 1)).wkc == 1
        m.firmware()
        assert m.read_box().wkc == 1
        sm1 = bytearray(m.send(C.FPRD, 0x0808, 8).data)
        struct.pack_into("<HH", sm1, 0, 0x0F00, 16)  # the buffer among the registers
        sm1[6] ^= 0x02  # and the repeat requested
        datagrams = [
            Datagram.physical(C.FPWR, STATION, 0x0808, bytes(sm1[:7])),
            Datagram.physical(C.FPRD, STATION, 0x0F00, 16),
        ]
        m.t_ns += 20_000
        reply, _ = m.chain.process(encode_frame(make_frame(datagrams), pad=True), m.t_ns)
        replies.append((reply, [bytes(esc.mem) for esc in m.chain.slaves]))
        assert decode_frame(reply).datagrams[1].data != bytes(16)  # the answer, again
    assert replies[0] == replies[1]
