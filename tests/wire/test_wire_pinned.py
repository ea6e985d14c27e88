"""Pinned bytes of real frames (capture file and frame number in each test): our decoder
gives the right fields and our encoder gives the same bytes back.

Frame numbers are tshark's (1-based). The bytes are copied from the corpus captures
(ethercrab-rs/ethercrab, MIT OR Apache-2.0); only these few frames are embedded.
"""

from __future__ import annotations

from lolacli.wire.coe import CoeService, decode_coe_header
from lolacli.wire.commands import Command
from lolacli.wire.frame import decode_any, decode_frame, encode_frame
from lolacli.wire.mailbox import MailboxType, decode_mailbox, encode_mailbox
from lolacli.wire.registers import (
    AlState,
    Fmmu,
    FmmuType,
    SyncManager,
    al_state,
    decode_fmmu,
    decode_sync_manager,
    decode_system_time_difference,
    encode_fmmu,
    encode_sync_manager,
)
from lolacli.wire.sdo import (
    SdoAbort,
    SdoAbortCode,
    SdoUploadRequest,
    SdoUploadResponse,
    abort_text,
    decode_sdo,
    encode_sdo,
)

# ethercrab__replay-issue-255.pcapng, frame 2850: returning LRW + 3 × FPRD AL status.
ISSUE_255_LRW = bytes.fromhex(
    "ffffffffffff12101010101088a439100c9400000000038000000000000400049500103001028000"
    "000800010004960110300102800000080001000497021030010200000008000100"
)
# ethercrab__twincat-scan-boxes.pcapng, frame 591: two APRD SII data reads (0x0508).
SCAN_BOXES_SII = bytes.fromhex(
    "01010501000002000000000088a4201001a0020008050480000002000000010001000100080504000000"
    "020000000100000000000000000000000000"
)
# ethercrab__replay-sdo-error.pcapng, frame 544: SDO abort 0x06020000 in the read mailbox.
SDO_ERROR_ABORT = bytes.fromhex(
    "ffffffffffff12101010101088a40c11040f00100011000100000a0000000063002080011000000002"
    "06454b31393134446961676e6f7365204d433200566f6c746167657461676573697665017010700080"
    "018002800e80019000a000f008f010f050f080f880f980fa81fa82fa1c1ccdf90d4b8af5adf33d75f5"
    "3f3c8b75abd2da2c3aeab7c75368ffc2f3938e3fba4ac352cea524e1f617fefde10ff72a6451ad8cb6"
    "378ba66bfafe719ed3af274c79172e695e5c5dd95ccc3debeb7b9eb25edee7c64483d991fce3f1799f"
    "6c722ce8c3c481a292b11067a022361d6aa6bb364b9ac3faafe4d56e3e5d6ae3aada4fdeaa6dffa9f1"
    "4c9763a716778ef92b17715aadd53a2e0dc094e42537690f22514f7acf39b3aa4f059a240100"
)
# ethercrab__replay-ek1914-segmented-upload.pcapng, frame 964: normal (not expedited)
# upload response, complete size 6, "EK1914" (object 0x1008, device name).
EK1914_UPLOAD = bytes.fromhex(
    "ffffffffffff12101010101088a40c1104e1001000110001000010000000001300304108100006000000"
    "454b3139313431d03fe7c1c224d97b457ce267db03f9bb221ef9fb224d53f4d7a4a35f27b30ff4938e"
    "9fb84a21e2d385de95405c3e5b3f5e79266f8f5884984edaf9ce8e1c3ccd790d4b8af5adf33d7de12f"
    "388a558bc2da2c386ab6874368ffcaf3938c3ffa4acb52cfe50ce0e617ffd9e10ff728a451ad0cb637"
    "8ba66bfafe719ed2af254c79172c685e5c5dc84ccc3d8be15b1a935edea7c6ce83d9f194e3f5598e6c"
    "7228a8c3c080a392b14866b032261d6aa69f26cb1ac3faaee4d16e3e596ae3aa9a4f5eae6df9e1b1cc"
    "9363bb1677cef90b07715ea5d53a2e89c090c41fa7f10322510f78cf79a28a0f059e070100"
)
# ethercrab__twincat-akd-nc-mode.pcapng, frame 3821: ARMW at 0x0910 (DC system time).
AKD_ARMW = bytes.fromhex(
    "01010501000002000000000088a410100dc20100100904000000c41def4901000000000000000000"
    "0000000000000000000000000000000000000000"
)
# ethercrab__twincat-akd-nc-mode.pcapng, frame 3378: EoE mailbox read from 0x1C00.
AKD_EOE = bytes.fromhex(
    "01010501000002000000000088a4231004b7e903001c0a8000000400000000120300000001000400e903"
    "ff1f01000000000100000000000000000000"
)
# ethercrab__replay-dc.pcapng, frame 3028: FPRD of 0x092C (system time difference).
DC_DIFFERENCE = bytes.fromhex(
    "ffffffffffff12101010101088a4101004ed02102c0904000000fd00000001000000000000000000"
    "0000000000000000000000000000000000000000"
)
# ethercrab__replay-ek1100-el2828-el2889.pcapng, frames 2281 and 2285: SM0 and FMMU0
# configuration written to slave 0x1002 (EL2889 outputs at logical address 1).
SM0_WRITE = bytes.fromhex(
    "ffffffffffff10101010101088a4141005740210000808000000000f0100440001000000"
)
FMMU0_WRITE = bytes.fromhex(
    "ffffffffffff10101010101088a41c10057602100006100000000100000001000007000f0002010000000000"
)


def test_lrw_frame_issue_255() -> None:
    frame = decode_frame(ISSUE_255_LRW)
    assert frame.ethernet.returned
    assert [d.mnemonic for d in frame.datagrams] == ["LRW", "FPRD", "FPRD", "FPRD"]
    lrw = frame.datagrams[0]
    assert (lrw.index, lrw.logical_address, lrw.data, lrw.wkc) == (0x94, 0, bytes(3), 4)
    assert [d.more for d in frame.datagrams] == [True, True, True, False]
    for d, adp in zip(frame.datagrams[1:], (0x1000, 0x1001, 0x1002), strict=True):
        assert (d.adp, d.ado, d.wkc) == (adp, 0x0130, 1)
        assert al_state(int.from_bytes(d.data, "little")) == AlState.OP
    assert encode_frame(frame) == ISSUE_255_LRW


def test_sii_read_scan_boxes() -> None:
    frame = decode_frame(SCAN_BOXES_SII)
    first, second = frame.datagrams
    assert first.cmd == second.cmd == Command.APRD
    assert (first.index, first.adp, first.ado, first.data) == (0xA0, 2, 0x0508, b"\x02\0\0\0")
    assert (second.index, second.adp, second.data, second.wkc) == (0, 1, b"\x02\0\0\0", 1)
    assert frame.padding == bytes(12)
    assert encode_frame(frame) == SCAN_BOXES_SII


def test_sdo_abort_replay_sdo_error_frame_544() -> None:
    (d,) = decode_frame(SDO_ERROR_ABORT).datagrams
    assert (d.cmd, d.adp, d.ado, d.length, d.wkc) == (Command.FPRD, 0x1000, 0x1100, 256, 1)
    mailbox = decode_mailbox(d.data)
    assert (mailbox.mailbox_type, mailbox.counter, mailbox.header.length) == (
        MailboxType.CoE,
        6,
        10,
    )
    abort = decode_sdo(mailbox.payload)
    assert abort == SdoAbort(0x1001, 0, SdoAbortCode.NO_OBJECT, CoeService.SDO_REQUEST)
    assert abort.text == "object does not exist"
    assert abort_text(0x06020000) == abort.text
    assert encode_sdo(abort) == mailbox.payload
    assert encode_mailbox(mailbox) == d.data[:16]
    assert encode_frame(decode_frame(SDO_ERROR_ABORT)) == SDO_ERROR_ABORT


def test_normal_upload_response_ek1914() -> None:
    (d,) = decode_frame(EK1914_UPLOAD).datagrams
    mailbox = decode_mailbox(d.data)
    response = decode_sdo(mailbox.payload)
    assert isinstance(response, SdoUploadResponse)
    assert (response.index, response.subindex) == (0x1008, 0)
    assert not response.expedited and response.size_indicated
    assert response.complete_size == 6 and response.data == b"EK1914"
    assert encode_sdo(response) == mailbox.payload


def test_expedited_upload_request_and_response() -> None:
    # replay-ek1914-no-complete-access.pcapng frames 937 (request) and 944 (response),
    # CoE payloads only.
    request = decode_sdo(bytes.fromhex("002040131c0000000000"))
    assert request == SdoUploadRequest(0x1C13, 0)
    response = decode_sdo(bytes.fromhex("00304f131c0002000000"))
    assert isinstance(response, SdoUploadResponse)
    assert response.expedited and response.data == b"\x02" and response.filler == bytes(3)
    assert encode_sdo(response).hex() == "00304f131c0002000000"


def test_armw_system_time_akd() -> None:
    frame = decode_frame(AKD_ARMW)
    (d,) = frame.datagrams
    assert (d.cmd, d.index, d.adp, d.ado, d.wkc) == (Command.ARMW, 0xC2, 1, 0x0910, 1)
    assert int.from_bytes(d.data, "little") == 0x49EF1DC4
    assert encode_frame(frame) == AKD_ARMW


def test_eoe_mailbox_akd() -> None:
    frame = decode_any(AKD_EOE)
    mailbox = decode_mailbox(frame.datagrams[0].data)
    assert mailbox.mailbox_type == MailboxType.EoE
    assert (mailbox.header.length, mailbox.counter, mailbox.payload) == (4, 1, b"\x03\0\0\0")
    assert encode_frame(frame) == AKD_EOE


def test_system_time_difference_replay_dc() -> None:
    (d,) = decode_frame(DC_DIFFERENCE).datagrams
    assert (d.cmd, d.adp, d.ado) == (Command.FPRD, 0x1002, 0x092C)
    assert decode_system_time_difference(d.data) == 253
    assert decode_system_time_difference(b"\xfd\x00\x00\x80") == -253


def test_sync_manager_and_fmmu_writes_el2828() -> None:
    (sm_dgram,) = decode_frame(SM0_WRITE).datagrams
    sm = decode_sync_manager(sm_dgram.data)
    assert sm == SyncManager(0x0F00, 1, 0x44, 0, 1, 0)
    assert sm.enabled and sm.master_writes and not sm.mailbox
    assert encode_sync_manager(sm) == sm_dgram.data
    (fmmu_dgram,) = decode_frame(FMMU0_WRITE).datagrams
    fmmu = decode_fmmu(fmmu_dgram.data)
    assert fmmu == Fmmu(1, 1, 0, 7, 0x0F00, 0, FmmuType.WRITE, 1)
    assert fmmu.enabled
    assert encode_fmmu(fmmu) == fmmu_dgram.data
    assert decode_coe_header(b"\x00\x30").service == CoeService.SDO_RESPONSE
