"""Our master's parts for SDO, against the emulated chain in process (virtual time):
the configuration of a bus without an ENI from its SII (lolacli.master.preop), the SDO
Information service over our mailbox (lolacli.master.sdo_info), and what a bus that does
not answer does (exit 4)."""

from __future__ import annotations

import dataclasses

import pytest

from lolacli.emulator.esc import EscConfig
from lolacli.emulator.run import EmulateOptions, make_chain
from lolacli.errors import TransportError
from lolacli.master.preop import FIRST_STATION, PreopBus, configure_from_sii
from lolacli.master.sdo_info import od_list, read_dictionary
from lolacli.master.transport import ChainTransport
from lolacli.sdo.lola_client import LolaBus
from tests.conftest import CORPUS
from tests.live import EXAMPLES, LOLA

ELMO_ESI = CORPUS / "esi" / "elmo_ethercat_sdk__Elmo_ECAT_00010420_V11.xml"


def _eni(path=LOLA):
    from lolacli.files import load_eni

    return load_eni(path)


def test_a_bus_configured_from_its_sii_is_the_enis() -> None:
    """Without an ENI: stations 0x1001… in line order; identity, names and mailboxes read
    from the SII are those the ENI gave the emulated slaves."""
    eni = _eni()
    chain = make_chain(eni, EmulateOptions())
    found, master = configure_from_sii(ChainTransport(chain), where="chain")
    assert len(found.slaves) == len(eni.slaves)
    for got, want in zip(found.slaves, eni.slaves, strict=True):
        assert got.station_address == FIRST_STATION + want.position - 1
        assert (got.name, got.identity) == (want.name, want.identity)
        if want.mailbox is None:
            assert got.mailbox is None
        else:
            assert got.mailbox is not None
            assert (got.mailbox.out_start, got.mailbox.out_length_bytes) == (
                want.mailbox.out_start,
                want.mailbox.out_length_bytes,
            )
            assert (got.mailbox.in_start, got.mailbox.in_length_bytes) == (
                want.mailbox.in_start,
                want.mailbox.in_length_bytes,
            )
            assert got.mailbox.protocols == ("CoE",)
    assert [esc.station_address for esc in chain.slaves] == [
        FIRST_STATION + k for k in range(len(eni.slaves))
    ]
    bus = PreopBus(found, master.transport, master=master)
    up = bus.bring_up(found.slaves[21])
    assert chain.slaves[21].al_state == 2 and chain.slaves[20].al_state == 1
    assert bus.master.sdo(up).upload(0x1008, 0) == b"CAN Gateway (IMU, FTS)"


def test_sii_read_4_bytes_at_a_time_and_an_eeprom_held_by_the_pdi() -> None:
    """An ESC that reads 4 bytes per EEPROM command, and one whose PDI holds the EEPROM
    (0x0500 bit 0): the master takes it over and hands it back."""
    eni = _eni(EXAMPLES / "single_drive.xml")
    chain = make_chain(eni, EmulateOptions())
    esc = chain.slaves[0]
    esc.config = dataclasses.replace(esc.config or EscConfig(), eeprom_8_byte_reads=False)
    esc.reset()
    esc.mem[0x0500] = 0x01
    found, _master = configure_from_sii(ChainTransport(chain))
    assert found.slaves[0].identity == eni.slaves[0].identity
    assert found.slaves[0].name == eni.slaves[0].name
    assert esc.mem[0x0500] & 0x01


def test_esi_siis_name_the_slaves_as_the_esi() -> None:
    if not ELMO_ESI.is_file():
        pytest.skip("corpus not found")
    from lolacli.files import load_esi

    eni = _eni()
    chain = make_chain(eni, EmulateOptions(), esi=[load_esi(ELMO_ESI)])
    found, _master = configure_from_sii(ChainTransport(chain))
    drive = found.slaves[4]
    assert drive.identity.vendor_id == 0x9A and drive.mailbox is not None
    assert drive.name and drive.name != eni.slaves[4].name  # the ESI's device name


def test_sdo_information_in_fragments() -> None:
    """The slave's SDO Information answers cut into fragments much smaller than its
    mailbox: joined, they give the same dictionary as in one piece."""
    eni = _eni()
    whole = LolaBus(ChainTransport(make_chain(eni, EmulateOptions())), eni, where="here")
    chain = make_chain(eni, EmulateOptions())
    chain.slaves[4].app.sdo.mailbox_bytes = 20  # 8 bytes of data per fragment
    cut = LolaBus(ChainTransport(chain), eni, where="here")
    a = whole.client(whole.slaves()[4])
    b = cut.client(cut.slaves()[4])
    assert od_list(a.mailbox) == od_list(b.mailbox)
    assert len(od_list(a.mailbox)) > 10
    assert list(read_dictionary(a.mailbox)) == list(read_dictionary(b.mailbox))
    objects = {o.index: o for o in read_dictionary(b.mailbox)}
    assert objects[0x1008].name == "Manufacturer device name"
    assert [e.name for e in objects[0x1018]][1:] == [
        "Vendor ID",
        "Product code",
        "Revision",
        "Serial number",
    ]
    listed = b.dictionary()
    assert listed is not None and listed.source == "sdo-info"
    assert listed.entry(0x6041, 0) is not None and listed.entry(0x6041, 0).access == "ro"


def test_a_slave_whose_mailbox_does_not_answer() -> None:
    eni = _eni()
    chain = make_chain(eni, EmulateOptions())
    chain.slaves[4].app.sdo = None  # the firmware takes requests and never answers
    bus = LolaBus(ChainTransport(chain), eni, where="here", timeout_s=0.2)
    client = bus.client(bus.slaves()[4])
    with pytest.raises(TransportError, match="mailbox timeout"):
        client.upload(0x1000, 0)


@pytest.mark.parametrize("with_eni", [True, False])
def test_a_cut_line_is_a_transport_error(with_eni: bool) -> None:
    eni = _eni()
    chain = make_chain(eni, EmulateOptions(link_down_after=0))
    with pytest.raises(TransportError):
        bus = LolaBus(ChainTransport(chain), eni if with_eni else None, where="here")
        bus.client(bus.slaves()[4]).upload(0x1000, 0)


def test_a_line_cut_after_slave_3() -> None:
    """Slaves behind the cut are not there: configured from the SII, the bus has 3."""
    eni = _eni()
    chain = make_chain(eni, EmulateOptions(link_down_after=3))
    bus = LolaBus(ChainTransport(chain), None, where="here", name="cut")
    assert [s.name for s in bus.slaves()] == [s.name for s in eni.slaves[:3]]
    assert bus.client(bus.slaves()[2]).upload(0x1000, 0) == bytes.fromhex("92010200")
