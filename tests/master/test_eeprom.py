"""The one SII reader (lolacli.master.eeprom) that `bus scan` and the PREOP bring-up use,
in process against the emulated chain: what it reads equals the image each emulated ESC
holds, by position and by station, for every ENI we have; and a slave whose EEPROM
interface reports an error, stays busy or has a bad checksum flag, as hardware can."""

from __future__ import annotations

import dataclasses
import re
import struct
from pathlib import Path

import pytest

from lolacli.emulator.chain import Chain
from lolacli.emulator.run import EmulateOptions, make_chain
from lolacli.eni.model import Eni, ProcessImage
from lolacli.eni.model import Master as EniMaster
from lolacli.errors import TransportError
from lolacli.files import load_eni
from lolacli.master import eeprom
from lolacli.master.core import Master, MasterOptions
from lolacli.master.preop import FIRST_STATION, configure_from_sii
from lolacli.master.scan import scan
from lolacli.master.transport import ChainTransport
from lolacli.wire.commands import Command
from lolacli.wire.frame import decode_frame, encode_frame
from lolacli.wire.registers import Register, SiiStatus
from lolacli.wire.sii import decode_sii
from tests.conftest import corpus_files
from tests.live import EXAMPLES, LOLA

ENIS = [LOLA, EXAMPLES / "single_drive.xml", EXAMPLES / "ek1100_io.xml"] + corpus_files(
    "eni", "*.xml"
)
_U16 = struct.Struct("<H")


def _whole(chain: Chain, k: int):
    return decode_sii(bytes(chain.slaves[k].sii))


@pytest.mark.parametrize("path", ENIS, ids=lambda p: Path(p).name[:32])
def test_scan_and_bring_up_read_what_every_image_says(path: Path) -> None:
    eni = load_eni(path)
    chain = make_chain(eni, EmulateOptions())
    report = scan(ChainTransport(chain))
    found, _master = configure_from_sii(ChainTransport(make_chain(eni, EmulateOptions())))
    assert len(report.slaves) == len(found.slaves) == len(eni.slaves)
    for k, (scanned, configured) in enumerate(zip(report.slaves, found.slaves, strict=True)):
        whole = _whole(chain, k)
        assert scanned.sii_error is None and scanned.sii is not None
        assert scanned.sii.header == whole.header
        assert (scanned.sii.strings, scanned.sii.general) == (whole.strings, whole.general)
        assert configured.name == whole.name == eni.slaves[k].name[:255]
        assert configured.identity.serial == whole.header.serial


class FaultyEeprom:
    """The emulated chain, but the slave at ``position`` (1-based) shows ``bits`` in every
    EEPROM status it answers (0x0502), as an ESC whose EEPROM misbehaves would."""

    def __init__(self, chain: Chain, position: int, bits: int) -> None:
        self.chain, self.position, self.bits = chain, position, bits
        self.station = FIRST_STATION + position - 1

    def _targets(self, d) -> bool:
        if d.ado != Register.SII_CONTROL_STATUS or d.length < 2:
            return False
        if d.cmd == Command.APRD:
            return d.adp == (-(self.position - 1)) & 0xFFFF
        return d.cmd == Command.FPRD and d.adp == self.station

    def process(self, frame: bytes, t_ns: int):
        asked = decode_frame(frame)
        out, done = self.chain.process(frame, t_ns)
        hit = [i for i, d in enumerate(asked.datagrams) if self._targets(d)]
        if out is None or not hit:
            return out, done
        back = decode_frame(out)
        datagrams = list(back.datagrams)
        for i in hit:
            data = bytearray(datagrams[i].data)
            _U16.pack_into(data, 0, _U16.unpack_from(data)[0] | self.bits)
            datagrams[i] = dataclasses.replace(datagrams[i], data=bytes(data))
        return encode_frame(dataclasses.replace(back, datagrams=tuple(datagrams))), done


def _master(processor) -> Master:
    eni = Eni(EniMaster(), (), (), ProcessImage(0, 0))
    return Master(eni, ChainTransport(processor), options=MasterOptions())


@pytest.mark.parametrize(
    ("bits", "error"),
    [
        (SiiStatus.COMMAND_ERROR, "SII read of word 0x0: EEPROM error (status 0x2"),
        (SiiStatus.BUSY, "SII read of word 0x0: EEPROM stays busy"),
        (SiiStatus.CHECKSUM_ERROR, None),  # the words still read
    ],
    ids=["command-error", "busy", "checksum-flag"],
)
def test_a_misbehaving_eeprom_fails_that_slave_only(bits: int, error: str | None) -> None:
    eni = load_eni(EXAMPLES / "ek1100_io.xml")
    chain = make_chain(eni, EmulateOptions())
    master = _master(FaultyEeprom(chain, 2, bits))
    n = len(eni.slaves)
    got = eeprom.read_sii(master, [(-k) & 0xFFFF for k in range(n)], auto_increment=True)
    for k, r in enumerate(got):
        if k == 1 and error is not None:
            assert r.error is not None and r.error.startswith(error) and r.info is None
        else:
            whole = _whole(chain, k)
            assert r.error is None and r.info is not None
            assert (r.info.header, r.info.strings, r.info.general) == (
                whole.header,
                whole.strings,
                whole.general,
            )


def test_the_bring_up_names_the_station_whose_eeprom_fails() -> None:
    eni = load_eni(EXAMPLES / "ek1100_io.xml")
    chain = make_chain(eni, EmulateOptions())
    with pytest.raises(TransportError, match=r"station 0x1002: SII read of word 0x0: EEPROM err"):
        configure_from_sii(ChainTransport(FaultyEeprom(chain, 2, SiiStatus.COMMAND_ERROR)))


def test_a_failure_after_the_header_keeps_the_header() -> None:
    """An EEPROM that fails once the header is read: `bus scan` still shows the identity."""
    eni = load_eni(LOLA)
    chain = make_chain(eni, EmulateOptions())
    faulty = FaultyEeprom(chain, 3, 0)
    real = faulty.process

    def process(frame: bytes, t_ns: int):
        # from the first category word on, slave 3's reads fail
        for d in decode_frame(frame).datagrams:
            if (
                d.cmd == Command.APWR
                and d.ado == Register.SII_CONTROL_STATUS
                and d.adp == (-2 & 0xFFFF)
            ):
                faulty.bits = SiiStatus.COMMAND_ERROR if d.data[2] >= 0x40 else 0
        return real(frame, t_ns)

    faulty.process = process  # type: ignore[method-assign]
    report = scan(ChainTransport(faulty))
    s = report.slaves[2]
    assert s.sii is not None and s.sii.header == _whole(chain, 2).header
    assert s.sii.general is None and s.sii_error is not None
    assert re.match(r"SII read of word 0x4[0-9A-F]: EEPROM error", s.sii_error)  # a category
    assert s.identity is not None and s.name is None
    assert [d.kind for d in report.findings if d.position == 3] == ["sii_unreadable"]
    assert all(x.sii_error is None for i, x in enumerate(report.slaves) if i != 2)
