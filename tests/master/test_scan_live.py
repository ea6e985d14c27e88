"""Acceptance of `lolacli bus scan` over a veth pair: `bus emulate` in its own process
(with its faults), our scan as a whole process, pysoem's view of the same bus as the
oracle. Needs root; skipped cleanly otherwise."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from lolacli.files import load_eni
from tests.live import (
    LOLA,
    LiveBus,
    inside,
    run,
    run_json,
    start_emulator,
    stop_emulator,
)

pytestmark = [pytest.mark.root, pytest.mark.slow]


def test_finds_the_25_lola_slaves(bus) -> None:
    eni = load_eni(LOLA)
    proc = start_emulator(bus)
    try:
        code, doc, err = run_json("bus", "scan", "--iface", bus.master, "--eni", str(LOLA), bus=bus)
    finally:
        stop_emulator(proc)
    assert code == 0, err
    assert doc["schema"] == "lolacli.scan/1" and doc["matches_eni"] is True
    assert doc["slaves_counted"] == doc["slaves_expected"] == 25
    assert [s["name"] for s in doc["slaves"]] == [s.name for s in eni.slaves]
    assert [(s["vendor_id"], s["product_code"], s["revision"]) for s in doc["slaves"]] == [
        (s.identity.vendor_id, s.identity.product_code, s.identity.revision) for s in eni.slaves
    ]
    assert {s["al_state"] for s in doc["slaves"]} == {"INIT"}
    assert [s["station_address"] for s in doc["slaves"]] == [0] * 25  # nothing assigned
    assert [s["ports"][1]["open"] for s in doc["slaves"]] == [True] * 24 + [False]
    assert doc["differences"] == doc["findings"] == []


def test_link_down_names_the_slave_where_the_line_ends(bus) -> None:
    proc = start_emulator(bus, "--link-down", "10@0.3")
    try:
        time.sleep(0.6)
        code, doc, err = run_json("bus", "scan", "--iface", bus.master, "--eni", str(LOLA), bus=bus)
        human = run("bus", "scan", "--iface", bus.master, "--eni", str(LOLA), bus=bus)
    finally:
        stop_emulator(proc)
    assert human.returncode == 1
    assert "differs: the line ends at slave 10 (Joint10 R Hip Pitch)" in human.stdout
    assert "10 slaves on" in human.stdout and "16 differences from the ENI" in human.stdout
    assert code == 1, err
    assert doc["slaves_counted"] == 10
    end = doc["differences"][0]
    assert (end["kind"], end["position"]) == ("line_ends", 10)
    assert end["message"] == (
        "the line ends at slave 10 (Joint10 R Hip Pitch): port 1 closed, no link, "
        "lost link counter 1; the ENI has slaves 11-25 behind it"
    )
    assert [(d["kind"], d["position"]) for d in doc["differences"][1:]] == [
        ("missing_slave", k) for k in range(11, 26)
    ]
    assert doc["slaves"][9]["error_counters"]["lost_link"] == [0, 1, 0, 0]
    assert [(f["kind"], f["position"]) for f in doc["findings"]] == [("lost_link", 10)]


def test_pysoem_counts_the_same_cut_line(bus) -> None:
    """pysoem's config_init on a line cut after slave 10 finds the 10 slaves our scan
    names, the last of them the same one."""
    pysoem = pytest.importorskip("pysoem")
    proc = start_emulator(bus, "--link-down", "10@0.3")
    try:
        time.sleep(0.6)
        code, doc, err = run_json("bus", "scan", "--iface", bus.master, "--eni", str(LOLA), bus=bus)
        master = pysoem.Master()
        with inside(bus):
            master.open(bus.master)
        try:
            counted = master.config_init()
            last = master.slaves[counted - 1] if counted > 0 else None
            theirs = (counted, last.man, last.id, last.rev) if last is not None else (counted,)
        finally:
            master.close()
    finally:
        stop_emulator(proc)
    assert code == 1, err
    end = doc["slaves"][-1]
    assert (doc["slaves_counted"], end["vendor_id"], end["product_code"], end["revision"]) == theirs
    assert theirs[0] == 10 and doc["differences"][0]["position"] == 10


def test_stuck_safeop_is_named_once_op_is_asked_for(bus) -> None:
    proc = start_emulator(bus, "--stuck-safeop", "5")
    try:
        code, plain, err = run_json("bus", "scan", "--iface", bus.master, bus=bus)
        assert code == 0, err
        code, doc, err = run_json(
            "bus", "scan", "--iface", bus.master, "--eni", str(LOLA), "--state", "op", bus=bus
        )
    finally:
        stop_emulator(proc)
    assert plain["slaves"][4]["al_state"] == "INIT"  # a stuck slave looks like any other
    assert code == 1, err
    assert [(d["kind"], d["position"]) for d in doc["differences"]] == [("state_not_reached", 5)], (
        doc["differences"]
    )
    five = doc["slaves"][4]
    assert (five["al_state"], five["al_status_code"], five["al_status_text"]) == (
        "SAFEOP+ERR",
        "0x0019",
        "No valid outputs",
    )
    assert [s["al_state"] for s in doc["slaves"]].count("OP") == 24
    assert [(r["position"], r["transition"]) for r in doc["refusals"]] == [(5, "SO")]
    assert doc["requested_state"] == "OP"


def test_a_wrong_revision_in_the_eni_file_is_exit_1(bus, tmp_path: Path) -> None:
    text = LOLA.read_text()
    marker = "<Name>GPIO 8DI 8DO</Name>"
    head, tail = text.split(marker, 1)
    start = tail.index("<RevisionNo>")
    end = tail.index("</RevisionNo>")
    edited = tmp_path / "lola-rev.xml"
    edited.write_text(head + marker + tail[:start] + "<RevisionNo>#x00100099" + tail[end:])
    proc = start_emulator(bus)
    try:
        code, doc, err = run_json(
            "bus", "scan", "--iface", bus.master, "--eni", str(edited), bus=bus
        )
    finally:
        stop_emulator(proc)
    assert code == 1, err
    assert [(d["kind"], d["position"]) for d in doc["differences"]] == [("wrong_revision", 24)]
    assert doc["differences"][0]["expected"]["revision"] == 0x00100099


def test_pysoem_sees_the_same_bus(bus) -> None:
    """pysoem's config_init (SOEM: addresses 0x1001…, SII identity and names, PREOP) and
    then our scan of the bus it left: the same slaves, names, identities, states, AL
    status codes; then pysoem asks for OP with slave 3 stuck, and our plain scan reads
    the codes pysoem reads."""
    pysoem = pytest.importorskip("pysoem")
    proc = start_emulator(bus, "--stuck-safeop", "3")
    try:
        theirs = _pysoem_view(pysoem, bus, try_op=False)
        code, first, err = run_json("bus", "scan", "--iface", bus.master, bus=bus)
        assert code == 0, err
        after_op = _pysoem_view(pysoem, bus, try_op=True)
        code, second, err = run_json("bus", "scan", "--iface", bus.master, bus=bus)
        assert code == 0, err
    finally:
        stop_emulator(proc)
    # SOEM copies the SII of the first slave with the same identity instead of reading
    # it again (ecx_lookup_prev_sii: "SII is constant for same slave ID"), so pysoem
    # names every joint drive after the first; we read each slave's own strings
    first_named: dict[tuple[int, int, int], str] = {}
    for s in first["slaves"]:
        first_named.setdefault((s["vendor_id"], s["product_code"], s["revision"]), s["name"])
    ours = [
        (
            first_named[(s["vendor_id"], s["product_code"], s["revision"])],
            s["vendor_id"],
            s["product_code"],
            s["revision"],
            s["al_state"],
            int(s["al_status_code"], 16),
        )
        for s in first["slaves"]
    ]
    assert ours == theirs
    assert [s["name"] for s in first["slaves"]] == [s.name for s in load_eni(LOLA).slaves]
    assert {s["al_state"] for s in first["slaves"]} == {"PREOP"}
    assert [s["station_address"] for s in first["slaves"]] == list(range(0x1001, 0x101A))
    assert after_op[2][4:] == ("SAFEOP+ERR", 0x0019)  # slave 3 refused OP
    scanned = [(s["al_state"], int(s["al_status_code"], 16)) for s in second["slaves"]]
    assert scanned[2] == ("SAFEOP+ERR", 0x0019)
    errors = {f["position"]: f["message"] for f in second["findings"] if f["kind"] == "al_error"}
    assert "SAFEOP+ERR, AL status code 0x0019 No valid outputs" in errors[3]
    # the others were OP while pysoem cycled; the watchdog (0x001B) may have tripped since
    others = [code for i, (_state, code) in enumerate(scanned) if i != 2]
    assert set(others) <= {0x0000, 0x001B}, scanned


def _pysoem_view(pysoem, bus: LiveBus, *, try_op: bool) -> list[tuple]:
    """(name, vendor, product, revision, AL state, AL status code) of every slave as
    pysoem sees it after config_init (and, with ``try_op``, after asking for OP)."""
    from lolacli.wire.registers import al_state_name

    master = pysoem.Master()
    with inside(bus):  # SOEM's socket is opened in the bus's namespace
        master.open(bus.master)
    try:
        assert master.config_init() == 25
        if try_op:
            master.config_map()
            master.state = pysoem.OP_STATE
            master.write_state()
            for _ in range(200):
                master.send_processdata()
                master.receive_processdata(5000)
                time.sleep(0.002)
        master.read_state()
        slaves = [master.slaves[i] for i in range(25)]
        return [(s.name, s.man, s.id, s.rev, al_state_name(s.state), s.al_status) for s in slaves]
    finally:
        master.close()


def test_nothing_answering_and_no_interface_are_exit_4(bus) -> None:
    started = time.monotonic()
    done = run("bus", "scan", "--iface", bus.master, "--timeout", "10ms", "--retries", "1", bus=bus)
    assert done.returncode == 4
    assert done.stderr == f"lolacli: error: no slave answers on {bus.master} (no frame came back)\n"
    assert time.monotonic() - started < 20
    done = run("bus", "scan", "--iface", "nosuchif0")
    assert (done.returncode, done.stderr) == (4, "lolacli: error: no such interface: nosuchif0\n")


def test_bad_options_are_exit_2() -> None:
    done = run("bus", "scan", "--iface", "lo", "--state", "op")
    assert done.returncode == 2 and "--state needs --eni" in done.stderr
    done = run("bus", "scan", "--iface", "lo", "--eni", str(LOLA), "--state", "boot")
    assert done.returncode == 2 and "expected init, preop, safeop or op" in done.stderr
    done = run("bus", "scan", "--iface", "lo", "--timeout", "0ms")
    assert done.returncode == 2
