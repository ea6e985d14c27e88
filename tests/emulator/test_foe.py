"""The emulated slave's mailbox protocols: FoE in BOOT with the SII's bootstrap mailbox
(ETG.1000.6 §5.9), CoE beside it, the mailbox error for the rest (ETG.1000.4 Table 30).

A small master here speaks frames to the in-process chain and the FoE messages with the
wire codec: INIT → BOOT with SM0/SM1 at the bootstrap mailbox the SII states, a file
written and read back, the errors a drive's bootloader answers with.
"""

from __future__ import annotations

import random
import struct

import pytest

from lolacli.emulator import registers as r
from lolacli.emulator.mailbox.foe import MAX_FILE_BYTES
from lolacli.emulator.registers import AlState
from lolacli.emulator.slave import build_chain
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.foe import (
    FOE_HEADER_BYTES,
    FoeAck,
    FoeBusy,
    FoeData,
    FoeError,
    FoeErrorCode,
    FoeReadRequest,
    FoeWriteRequest,
    decode_foe,
    encode_foe,
)
from lolacli.wire.mailbox import (
    MAILBOX_HEADER_BYTES,
    MailboxErrorDetail,
    MailboxType,
    decode_mailbox,
    decode_mailbox_error,
    encode_mailbox,
    make_mailbox,
)
from lolacli.wire.registers import AlStatusCode, SyncManager, encode_sync_manager
from lolacli.wire.sdo import SdoUploadRequest, SdoUploadResponse, decode_sdo, encode_sdo
from lolacli.wire.sii import SiiWord
from tests.emulator.bus import EXAMPLES, POLLS, Bus

ENI = load_eni(EXAMPLES / "single_drive.xml")
STATION = ENI.slaves[0].station_address
PASSWORD = 0x5EC2E7


class BootMaster(Bus):
    """A master that takes the single drive to BOOT and speaks FoE with it."""

    def __init__(self, password: int = PASSWORD) -> None:
        super().__init__(build_chain(ENI, foe_password=password))
        self.transition(ENI, "IP")  # station address, standard mailbox, PREOP
        self.esc = self.chain.slaves[0]
        words = struct.unpack_from("<4H", self.esc.sii, SiiWord.BOOTSTRAP_RX_MAILBOX_OFFSET * 2)
        self.out = (words[0], words[1])
        self.inn = (words[2], words[3])

    def state(self, state: int) -> int:
        self.fpwr(STATION, r.AL_CONTROL, struct.pack("<H", state | 0x10))
        for _ in range(POLLS):
            status = self.fprd(STATION, r.AL_STATUS, 1)[0]
            if status & 0x0F == state or status & 0x10:
                break
        return struct.unpack("<H", self.fprd(STATION, r.AL_STATUS_CODE, 2))[0]

    def boot(self, out: tuple[int, int] | None = None) -> int:
        """INIT, SM0/SM1 at ``out``/the bootstrap mailbox, BOOT: the AL status code."""
        assert self.state(AlState.INIT) == 0
        out = out or self.out
        sm0 = SyncManager(out[0], out[1], 0x26, activate=1)
        sm1 = SyncManager(self.inn[0], self.inn[1], 0x22, activate=1)
        self.fpwr(STATION, 0x0800, encode_sync_manager(sm0) + encode_sync_manager(sm1))
        return self.state(AlState.BOOT)

    def ask(self, mailbox_type: int, payload: bytes, out: tuple[int, int], inn: tuple[int, int]):
        self.counter = self.counter % 7 + 1
        box = make_mailbox(mailbox_type, payload, counter=self.counter)
        assert self.fpwr(STATION, out[0], encode_mailbox(box, buffer_bytes=out[1])) == 1
        for _ in range(POLLS):
            if self.fprd(STATION, 0x080D, 1)[0] & 0x08:
                return decode_mailbox(self.fprd(STATION, inn[0], inn[1]))
        raise AssertionError("no answer in the read mailbox")

    def foe(self, message: object):
        reply = self.ask(MailboxType.FoE, encode_foe(message), self.out, self.inn)  # type: ignore[arg-type]
        assert reply.mailbox_type == MailboxType.FoE, reply
        return decode_foe(reply.payload)

    @property
    def chunk(self) -> int:
        return self.out[1] - MAILBOX_HEADER_BYTES - FOE_HEADER_BYTES

    def write(self, name: str, data: bytes, password: int = PASSWORD) -> list[object]:
        """The answers of a whole write; busy answers make the packet go again."""
        answers = [self.foe(FoeWriteRequest(name, password))]
        if answers[-1] != FoeAck(0):
            return answers
        packet, offset = 1, 0
        while True:
            piece = data[offset : offset + self.chunk]
            answer = self.foe(FoeData(packet, piece))
            answers.append(answer)
            if isinstance(answer, FoeBusy):
                continue
            if answer != FoeAck(packet):
                return answers
            offset += len(piece)
            packet += 1
            if len(piece) < self.chunk:
                return answers

    def read(self, name: str, password: int = PASSWORD) -> bytes | FoeError:
        data = bytearray()
        answer = self.foe(FoeReadRequest(name, password))
        while True:
            if isinstance(answer, FoeError):
                return answer
            assert isinstance(answer, FoeData)
            data += answer.data
            if len(answer.data) < self.chunk:
                self.counter = self.counter % 7 + 1  # the last ack has no answer
                box = make_mailbox(MailboxType.FoE, encode_foe(FoeAck(answer.packet)))
                self.fpwr(STATION, self.out[0], encode_mailbox(box, buffer_bytes=self.out[1]))
                return bytes(data)
            answer = self.foe(FoeAck(answer.packet))


def _firmware(size: int, seed: int = 1) -> bytes:
    return random.Random(seed).randbytes(size)


def test_the_sii_states_a_bootstrap_mailbox_apart_from_the_standard_one() -> None:
    m = BootMaster()
    mb = ENI.slaves[0].mailbox
    assert mb is not None
    assert m.out == (mb.out_start, 0x400) and m.inn == (mb.out_start + 0x400, 0x400)
    assert m.esc.layout.bootstrap_out_bytes == 0x400


def test_firmware_written_in_boot_reads_back_and_survives_boot_to_init() -> None:
    m = BootMaster()
    assert m.boot() == 0 and m.esc.al_state == AlState.BOOT
    firmware = _firmware(10 * m.chunk + 37)
    answers = m.write("app.bin", firmware)
    assert answers[:3] == [FoeAck(0), FoeBusy(0, 100, "erasing flash"), FoeAck(1)]
    assert answers[-1] == FoeAck(11) and len(answers) == 1 + 1 + 11
    assert m.read("app.bin") == firmware
    assert m.state(AlState.INIT) == 0 and m.esc.al_state == AlState.INIT
    assert m.boot() == 0
    assert m.read("app.bin") == firmware
    # BOOT -> INIT -> PREOP: the application runs with its mailbox again
    assert m.state(AlState.INIT) == 0
    m.transition(ENI, "IP")
    assert m.esc.al_state == AlState.PREOP


def test_a_file_of_whole_packets_ends_with_an_empty_one() -> None:
    m = BootMaster()
    assert m.boot() == 0
    firmware = _firmware(3 * m.chunk)
    assert m.write("whole", firmware)[-1] == FoeAck(4)
    assert m.read("whole") == firmware


def test_wrong_password_and_unknown_file_get_the_foe_errors() -> None:
    m = BootMaster()
    assert m.boot() == 0
    assert m.write("fw", b"x", password=PASSWORD + 1) == [FoeError(FoeErrorCode.NO_RIGHTS, "")]
    assert m.read("fw") == FoeError(FoeErrorCode.NOT_FOUND, "")
    m.write("fw", b"abc")
    assert m.read("fw", password=0) == FoeError(FoeErrorCode.NO_RIGHTS, "")
    assert m.read("fw") == b"abc"


def test_outside_boot_foe_gets_bootstrap_only_and_coe_still_answers() -> None:
    m = BootMaster()  # PREOP, standard mailbox
    mb = ENI.slaves[0].mailbox
    assert mb is not None
    out, inn = (mb.out_start, mb.out_length_bytes), (mb.in_start, mb.in_length_bytes)
    reply = m.ask(MailboxType.FoE, encode_foe(FoeWriteRequest("fw", PASSWORD)), out, inn)
    assert decode_foe(reply.payload) == FoeError(FoeErrorCode.BOOTSTRAP_ONLY, "")
    reply = m.ask(MailboxType.CoE, encode_sdo(SdoUploadRequest(0x1018, 1)), out, inn)
    assert isinstance(decode_sdo(reply.payload), SdoUploadResponse)


@pytest.mark.parametrize("mailbox_type", [MailboxType.EoE, MailboxType.SoE, 0x0E])
def test_other_protocols_get_the_mailbox_error(mailbox_type: int) -> None:
    m = BootMaster()
    mb = ENI.slaves[0].mailbox
    assert mb is not None
    out, inn = (mb.out_start, mb.out_length_bytes), (mb.in_start, mb.in_length_bytes)
    reply = m.ask(mailbox_type, b"\x00" * 8, out, inn)
    assert reply.mailbox_type == MailboxType.ERR
    assert decode_mailbox_error(reply.payload).detail == MailboxErrorDetail.UNSUPPORTED_PROTOCOL


def test_in_boot_coe_is_not_served() -> None:
    m = BootMaster()
    assert m.boot() == 0
    reply = m.ask(MailboxType.CoE, encode_sdo(SdoUploadRequest(0x1018, 1)), m.out, m.inn)
    assert reply.mailbox_type == MailboxType.ERR
    assert decode_mailbox_error(reply.payload).detail == MailboxErrorDetail.UNSUPPORTED_PROTOCOL


def test_answers_carry_the_slaves_own_counter_in_turn() -> None:
    m = BootMaster()
    assert m.boot() == 0
    counters = []
    for _ in range(9):
        reply = m.ask(MailboxType.FoE, encode_foe(FoeAck(1)), m.out, m.inn)
        counters.append(reply.counter)
    assert counters == [(counters[0] - 1 + k) % 7 + 1 for k in range(9)]


def test_packets_out_of_turn_and_without_a_transfer() -> None:
    m = BootMaster()
    assert m.boot() == 0
    assert m.foe(FoeData(1, b"x")) == FoeError(FoeErrorCode.ILLEGAL, "")
    assert m.foe(FoeWriteRequest("fw", PASSWORD)) == FoeAck(0)
    assert m.foe(FoeData(2, b"x")) == FoeError(FoeErrorCode.PACKET_NUMBER_WRONG, "")
    assert m.foe(FoeAck(3)) == FoeError(FoeErrorCode.ILLEGAL, "")
    assert m.read("fw") == FoeError(FoeErrorCode.NOT_FOUND, "")  # nothing was stored


def test_leaving_boot_drops_a_file_half_written() -> None:
    m = BootMaster()
    assert m.boot() == 0
    assert m.foe(FoeWriteRequest("fw", PASSWORD)) == FoeAck(0)
    assert isinstance(m.foe(FoeData(1, bytes(m.chunk))), FoeBusy)
    assert m.foe(FoeData(1, bytes(m.chunk))) == FoeAck(1)
    assert m.state(AlState.INIT) == 0 and m.boot() == 0
    assert m.read("fw") == FoeError(FoeErrorCode.NOT_FOUND, "")


def test_boot_needs_the_bootstrap_mailbox_and_a_bootloader() -> None:
    m = BootMaster()
    assert m.boot(out=(m.out[0] + 2, m.out[1])) == AlStatusCode.INVALID_MAILBOX_CONFIGURATION_BOOT
    assert m.esc.al_state == AlState.INIT and m.esc.al_error
    coupler = Bus(build_chain(load_eni(EXAMPLES / "ek1100_io.xml")))
    coupler.one(C.APWR, 0, r.AL_CONTROL, b"\x13\x00")
    esc = coupler.chain.slaves[0]
    assert esc.al_error and esc.al_status_code == AlStatusCode.BOOTSTRAP_NOT_SUPPORTED


def test_a_file_too_large_for_the_flash_gets_disk_full() -> None:
    m = BootMaster()
    assert m.boot() == 0
    foe = m.esc.app.foe
    assert foe.max_file_bytes == MAX_FILE_BYTES
    foe.max_file_bytes = 20 * m.chunk  # a small flash: the test sends less
    assert m.foe(FoeWriteRequest("big", PASSWORD)) == FoeAck(0)
    packets = foe.max_file_bytes // m.chunk + 1
    chunk = bytes(m.chunk)
    answer: object = None
    for packet in range(1, packets + 2):
        answer = m.foe(FoeData(packet, chunk))
        if isinstance(answer, FoeBusy):
            answer = m.foe(FoeData(packet, chunk))
        if isinstance(answer, FoeError):
            break
    assert answer == FoeError(FoeErrorCode.DISK_FULL, "")


def test_an_emergency_counts_on_the_same_counter_as_the_answers() -> None:
    m = BootMaster()  # PREOP, standard mailbox
    mb = ENI.slaves[0].mailbox
    assert mb is not None
    out, inn = (mb.out_start, mb.out_length_bytes), (mb.in_start, mb.in_length_bytes)
    first = m.ask(MailboxType.CoE, encode_sdo(SdoUploadRequest(0x1018, 1)), out, inn)
    m.chain.drive_fault(1)  # a CoE emergency, posted unasked
    emergency = decode_mailbox(m.fprd(STATION, inn[0], inn[1]))
    assert emergency.mailbox_type == MailboxType.CoE and emergency.payload[1] >> 4 == 1
    last = m.ask(MailboxType.CoE, encode_sdo(SdoUploadRequest(0x1018, 1)), out, inn)
    after = first.counter % 7 + 1
    assert [emergency.counter, last.counter] == [after, after % 7 + 1]
