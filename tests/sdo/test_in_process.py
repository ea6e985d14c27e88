"""The default transport: lolacli's own master against the emulated chain in this process.

No interface, no root: ``lolacli sdo read 5 0x1000`` builds the embedded LOLA chain (or
``--eni``'s), brings slave 5 to PREOP through the ENI's InitCmds (its mailbox sync
managers among them) and uploads over the master's CoE mailbox. The same reads, writes
and aborts as against ``bus emulate`` over veth (test_live_bus.py), and what is particular
to the in-process chain: only the slaves asked for leave INIT, a slave whose ENI mailbox
configuration is wrong refuses PREOP, every corpus ENI either answers with its slaves'
identities or names the InitCmd its emulated slave refused.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import pytest

from lolacli.devices.cia402 import Cia402Drive
from lolacli.errors import SdoAbortError, TransportError, UsageError
from lolacli.sdo import read, write
from lolacli.sdo.session import LolaSession, TransportOptions, open_session
from tests.conftest import CORPUS, corpus_files, corpus_ids
from tests.live import LOLA, ROOT

ELMO_ESI = CORPUS / "esi" / "elmo_ethercat_sdk__Elmo_ECAT_00010420_V11.xml"
WRONG_LENGTH_LOW = WRONG_LENGTH_HIGH = {"0x06070010"}  # see test_live_bus.py


def _eni():
    from lolacli.files import load_eni

    return load_eni(LOLA)


def _json(cli, *args: str) -> tuple[int, dict]:
    code, out, _err = cli("sdo", *args, "-f", "json")
    return code, json.loads(out) if out.strip() else {}


def test_reads_of_the_acceptance(cli) -> None:
    eni = _eni()
    code, doc = _json(cli, "read", "5", "0x1000")
    assert code == 0 and doc["value"] == 0x00020192 and doc["type_source"] == "sdo-info"
    assert doc["schema"] == "lolacli.sdo/1" and doc["raw_hex"] == "92010200"
    assert doc["name"] == "Device type"  # the slave's own name (SDO Information)
    code, doc = _json(cli, "read", "5", "0x1018:01")
    assert code == 0 and doc["value"] == eni.slaves[4].identity.vendor_id
    assert doc["name"] == "Vendor ID"
    code, doc = _json(cli, "read", "5", "0x1C13:01")  # SM3's first assigned TxPDO
    assert code == 0 and doc["name"] == "PDO" and doc["value"] == 0x1A00  # the slave's word
    code, doc = _json(cli, "read", "5", "0x1008")  # segmented upload
    assert code == 0 and doc["value"] == Cia402Drive.LONG_NAME
    room = eni.slaves[4].mailbox.in_length_bytes - 6 - 2 - 8  # mailbox, CoE, SDO initiate
    assert len(bytes.fromhex(doc["raw_hex"])) > room
    code, doc = _json(cli, "read", "22", "0x1008")  # 22 bytes: a normal (not expedited) upload
    assert code == 0 and doc["value"] == "CAN Gateway (IMU, FTS)"
    code, doc = _json(cli, "read", "@1025", "0x1018:02")
    assert code == 0 and doc["value"] == eni.slaves[24].identity.product_code
    code, doc = _json(cli, "read", "Joint05", "0x1018:04")
    assert code == 0 and doc["value"] == eni.slaves[4].identity.serial


def test_aborts_exit_1_with_code_and_text(cli) -> None:
    for args, codes in (
        (("read", "5", "0x2345"), {"0x06020000"}),
        (("read", "5", "0x1018:09"), {"0x06090011"}),
        (("write", "5", "0x1000", "1"), {"0x06010002"}),
        (("write", "5", "0x607F", "1", "--type", "u16"), WRONG_LENGTH_LOW),
        (("write", "5", "0x607F", "1", "--type", "u64"), WRONG_LENGTH_HIGH),
    ):
        code, doc = _json(cli, *args)
        assert code == 1 and doc["error"]["abort_code"] in codes, (args, doc)
        assert doc["error"]["message"] and doc["index"] == int(args[2].split(":")[0], 16)
        code, _out, err = cli("sdo", *args)
        assert code == 1 and doc["error"]["abort_code"] in err and doc["error"]["message"] in err


def test_write_then_read_in_one_session() -> None:
    """The emulated chain lives as long as the session: what is written is read back
    (a second session emulates a fresh chain)."""
    with open_session(TransportOptions()) as session:
        target = session.target("5")
        written = write(target.client, 0x607F, 0, "250000", data_type=0x0007)
        assert written.raw == bytes.fromhex("90d00300")
        got = read(target.client, 0x607F, 0, data_type=0x0007)
        assert got.value == 250000
        with pytest.raises(SdoAbortError) as abort:
            target.client.download(0x1000, 0, b"\x01\x00\x00\x00")
        assert abort.value.code == 0x06010002
    with open_session(TransportOptions()) as session:
        assert read(session.target("5").client, 0x607F, 0, data_type=0x0007).value == 0


def test_a_write_takes_its_type_from_sdo_information_and_says_it_is_not_kept(cli) -> None:
    """No --type and no dictionary file: the slave's SDO Information gives 0x607F's type
    (UNSIGNED32), and stderr says the emulated chain (and the value) ends with the process."""
    code, out, err = cli("sdo", "write", "5", "0x607F", "250000", "-f", "json")
    doc = json.loads(out)
    assert code == 0 and (doc["data_type"], doc["type_source"]) == ("UNSIGNED32", "sdo-info")
    assert doc["raw_hex"] == "90d00300"
    assert err.count("lolacli: note:") == 1 and "gone when it ends" in " ".join(err.split())
    assert all(len(line) <= 80 for line in err.splitlines())  # wrapped, as all human output


def test_only_the_slaves_asked_for_leave_init() -> None:
    """Slave 5 reaches PREOP through the mailbox sync managers of its ENI InitCmds;
    every other slave stays in INIT, untouched."""
    eni = _eni()
    session = open_session(TransportOptions())
    assert isinstance(session, LolaSession)
    with session:
        chain = session.bus.transport.processor  # type: ignore[attr-defined]
        assert all(esc.al_state == 1 for esc in chain.slaves)
        session.target("5")
        session.target("Joint05")  # the same slave: nothing more happens
        states = [esc.al_state for esc in chain.slaves]
        assert states == [1] * 4 + [2] + [1] * 20
        esc, mailbox = chain.slaves[4], eni.slaves[4].mailbox
        sm0 = esc.sync_manager(0)
        sm1 = esc.sync_manager(1)
        assert (sm0.start, sm0.length) == (mailbox.out_start, mailbox.out_length_bytes)
        assert (sm1.start, sm1.length) == (mailbox.in_start, mailbox.in_length_bytes)
        assert esc.station_address == eni.slaves[4].station_address
        session.target("22")
        assert [esc.al_state for esc in chain.slaves].count(2) == 2


def test_a_wrong_mailbox_configuration_is_refused() -> None:
    """The master really configures SM0/SM1 from the ENI: move SM0 in the ENI and the
    emulated slave refuses PREOP (AL status code 0x0016, invalid mailbox configuration)."""
    from lolacli.emulator.run import EmulateOptions, make_chain
    from lolacli.master.transport import ChainTransport
    from lolacli.sdo.lola_client import LolaBus

    eni = _eni()
    slave = eni.slaves[4]
    cmds = tuple(
        dataclasses.replace(c, data=b"\x00\x1a" + c.data[2:])
        if c.comment == "SM0 mailbox out"
        else c
        for c in slave.init_cmds
    )
    broken = dataclasses.replace(
        eni, slaves=(*eni.slaves[:4], dataclasses.replace(slave, init_cmds=cmds), *eni.slaves[5:])
    )
    bus = LolaBus(ChainTransport(make_chain(eni, EmulateOptions())), broken, where="here")
    with pytest.raises(TransportError, match="0x0016"):
        bus.client(bus.slaves()[4])
    assert bus.client(bus.slaves()[5]).upload(0x1000, 0) == bytes.fromhex("92010200")


def test_slaves_without_mailbox_and_unknown_slaves(cli) -> None:
    code, _out, err = cli("sdo", "read", "23", "0x1000")
    assert code == 2 and "no mailbox" in err and "GPIO Coupler" in err
    code, _out, err = cli("sdo", "read", "26", "0x1000")
    assert code == 2 and "position 26" in err
    code, _out, err = cli("sdo", "read", "Joint99", "0x1000")
    assert code == 2 and "Joint99" in err
    for bad, why in (
        (ROOT / "nosuch.xml", "no such file"),
        (ROOT / "lolacli", "is a directory"),
        (ROOT / "README.md", "not well-formed XML"),
    ):
        code, _out, err = cli("sdo", "read", "5", "0x1000", "--eni", str(bad))
        assert code == 3 and str(bad) in err and why in err, err
    code, _out, err = cli("sdo", "read", "5", "0x1000", "--esi", str(ROOT / "README.md"))
    assert code == 3 and "README.md" in err
    with pytest.raises(UsageError):
        open_session(TransportOptions(backend="soem"))


def test_complete_access_and_sdo_information(cli) -> None:
    code, doc = _json(cli, "read", "5", "0x1018", "--complete")
    assert code == 0 and doc["value"][0] == {
        "subindex": 0,
        "name": "Number of entries",
        "data_type": "UNSIGNED8",
        "value": 4,
    }
    assert doc["value"][4]["value"] == _eni().slaves[4].identity.serial
    assert (doc["data_type"], doc["type_source"], doc["name"]) == ("RECORD", "sdo-info", "Identity")
    code, doc = _json(cli, "list", "5")
    assert code == 0 and doc["source"] == "sdo-info"
    objects = {o["index"]: o for o in doc["objects"]}
    assert {0x1000, 0x1008, 0x1018, 0x1A00, 0x6040, 0x6041, 0x607F} <= set(objects)
    ident = objects[0x1018]
    assert ident["object_code"] == "RECORD" and len(ident["entries"]) == 5
    assert [e["access"] for e in ident["entries"]] == ["ro"] * 5
    assert objects[0x607F]["entries"][0]["access"] == "rw"
    assert objects[0x6041]["entries"][0]["pdo_mapping"] is True


def test_esi_gives_sii_and_types(cli, corpus) -> None:
    """With --esi the emulated drives take their SII from the Elmo ESI (as `bus emulate
    --esi`) and the value types come from its dictionary."""
    code, doc = _json(cli, "read", "5", "0x6060", "--esi", str(ELMO_ESI))
    assert code == 0 and (doc["data_type"], doc["type_source"]) == ("INTEGER8", "esi")
    assert doc["name"] == "Modes of operation" and doc["value"] == 8
    with open_session(TransportOptions(esi=(ELMO_ESI,))) as session:
        chain = session.bus.transport.processor  # type: ignore[attr-defined]
        from lolacli.emulator.run import EmulateOptions, make_chain

        plain = make_chain(_eni(), EmulateOptions())
        assert bytes(chain.slaves[4].sii) != bytes(plain.slaves[4].sii)
        assert read(session.target("5").client, 0x1018, 1).value == 0x9A


def test_the_check_file_of_the_docs(cli, tmp_path) -> None:
    text = (ROOT / "docs" / "sdo.md").read_text(encoding="utf-8")
    example = text.split("```yaml\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "drive5.yaml"
    path.write_text(example)
    code, out, err = cli("sdo", "check", str(path), "-f", "json")
    doc = json.loads(out)
    assert code == 0, (err, [r for r in doc["results"] if not r["ok"]])
    assert doc["checks"] == 7 and doc["failed"] == 0


def test_a_whole_process() -> None:
    """As CI calls it: a process of its own."""
    done = subprocess.run(
        [sys.executable, "-m", "lolacli", "sdo", "read", "5", "0x1000"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={"PATH": "/usr/bin:/bin"},
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "5 0x1000:00  Device type  UNSIGNED32 = 131474 (0x00020192)\n"


CORPUS_ENIS = corpus_files("eni", "*.xml")


@pytest.mark.parametrize("path", CORPUS_ENIS, ids=corpus_ids(CORPUS_ENIS))
def test_every_corpus_chain_answers_or_names_the_refusal(path, corpus) -> None:
    """Each CoE slave of each corpus ENI, emulated in process: its identity objects are
    the ENI's, or bringing it to PREOP fails naming the InitCmd its emulated slave
    refused (exit 4, never a traceback)."""
    from lolacli.files import load_eni

    eni = load_eni(path)
    coe = [
        s
        for s in eni.slaves
        if s.mailbox is not None and "CoE" in (s.mailbox.protocols or ("CoE",))
    ]
    with open_session(TransportOptions(eni=path)) as session:
        for slave in coe:
            try:
                target = session.target(str(slave.position))
            except TransportError as exc:
                assert "did not reach PREOP" in str(exc) and "InitCmd" in str(exc)
                continue
            got = read(target.client, 0x1018, 2)
            assert got.value == slave.identity.product_code, slave.name


def test_the_library_example_of_the_docs() -> None:
    import os

    script = ROOT / "docs" / "examples" / "sdo_access.py"
    done = subprocess.run(
        [sys.executable, str(script)],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:3] == ["198948", "250000 90d00300", "40 Statusword"]
