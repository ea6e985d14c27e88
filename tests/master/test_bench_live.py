"""Acceptance of the bench verbs (`bus reg`, `bus sii`, `bus alias`, `bus state`) over a
veth pair: `bus emulate` of the LOLA chain in its own process, the CLI as a whole process,
SOEM's own `slaveinfo` as the oracle of what the EEPROMs say. Needs root; skipped cleanly
otherwise."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from lolacli.files import load_eni
from lolacli.wire.sii import crc8_sii
from tests.live import LOLA, LiveBus, run, run_json, start_emulator, stop_emulator

pytestmark = [pytest.mark.root, pytest.mark.slow]

LOLA_SLAVES = 25


def _cli(bus: LiveBus, *args: str) -> tuple[int, dict, str]:
    return run_json(*args, "--iface", bus.master, bus=bus, timeout=180)


def _human(bus: LiveBus, *args: str) -> subprocess.CompletedProcess[str]:
    return run(*args, "--iface", bus.master, bus=bus, timeout=180)


# ------------------------------------------------------------------------ SII vs slaveinfo
@pytest.fixture(scope="module")
def soem() -> dict[str, Path]:
    from tests.emulator.soem_tools import soem_tools

    tools, why = soem_tools()
    if tools is None:
        pytest.skip(f"SOEM's tools cannot be built here: {why}")
    return tools


def _slaveinfo_blocks(text: str) -> list[dict]:
    """slaveinfo -map per slave: name, identity, SMs, the mapped entries per SM."""
    out = []
    for block in text.split("\nSlave:")[1:]:
        name = re.search(r"^ Name:(.*)$", block, re.M)
        ident = re.search(r"Man: (\w+) ID: (\w+) Rev: (\w+)", block)
        assert name and ident, block[:300]
        sms = [
            (int(m[0]), int(m[1], 16), int(m[2]), int(m[3]))
            for m in re.findall(r"^ SM(\d+) A:(\w+) L:\s*(\d+) F:\w+ Type:(\d+)", block, re.M)
        ]
        mapped: dict[int, list[tuple[int, int, int]]] = {}
        names: list[str] = []
        sm = None
        for line in block.splitlines():
            head = re.match(r"^  SM(\d+) (outputs|inputs|RXPDO|TXPDO)", line)
            if head:  # CoE: one head per SM; SII: one per PDO
                sm = int(head[1])
                mapped.setdefault(sm, [])
            entry = re.match(r"^  \[0x\w+\.\d\] 0x(\w+):0x(\w+) 0x(\w+) +\S+ +(.*)$", line)
            if entry and sm is not None:
                mapped[sm].append((int(entry[1], 16), int(entry[2], 16), int(entry[3], 16)))
                names.append(entry[4].strip())
        out.append(
            {
                "name": name[1],
                "identity": tuple(int(g, 16) for g in ident.groups()),
                "sms": sms,
                "mapped": mapped,
                "entry_names": names,
                "by": "CoE" if "PDO mapping according to CoE" in block else "SII",
            }
        )
    return out


def test_sii_read_of_every_slave_agrees_with_soem_slaveinfo(bus: LiveBus, soem) -> None:
    proc = start_emulator(bus)
    try:
        done = subprocess.run(
            bus.command(str(soem["slaveinfo"]), bus.master, "-map"),
            capture_output=True,
            text=True,
            timeout=180,
        )
        ours = [_cli(bus, "bus", "sii", "read", str(k)) for k in range(1, LOLA_SLAVES + 1)]
        human = _human(bus, "bus", "sii", "read", "3")
    finally:
        stop_emulator(proc)
    assert done.returncode == 0, done.stdout + done.stderr
    theirs = _slaveinfo_blocks(done.stdout)
    assert len(theirs) == LOLA_SLAVES
    first_name: dict[tuple[int, int, int], str] = {}
    for k, ((code, doc, err), soem_slave) in enumerate(zip(ours, theirs, strict=True), 1):
        assert code == 0, err
        assert doc["schema"] == "lolacli.sii/1" and doc["slave"]["position"] == k
        sii = doc["sii"]
        assert sii["checksum_ok"] is True
        ident = sii["identity"]
        identity = (ident["vendor_id"], ident["product_code"], ident["revision"])
        assert identity == soem_slave["identity"], k
        # SOEM names a slave by the first one of its identity (ecx_lookup_prev_sii)
        first_name.setdefault(identity, sii["general"]["name"][:40])
        assert soem_slave["name"] == first_name[identity], k
        # the sync managers SOEM set up are where and what the SII says
        kinds = {"mailbox_out": 1, "mailbox_in": 2, "outputs": 3, "inputs": 4}
        sms = {s["index"]: s for s in sii["sync_managers"]}
        for index, start, length, kind in soem_slave["sms"]:
            if kind == 0:
                continue
            assert sms[index]["start"] == start and kinds[sms[index]["type"]] == kind, k
            if kind in (1, 2):
                assert sms[index]["bytes"] == length, k
        # the PDO mapping: entries (index, subindex, bits) per SM, in order, and the sizes
        mapped: dict[int, list[tuple[int, int, int]]] = {}
        for p in sii["rx_pdos"] + sii["tx_pdos"]:
            if p["sync_manager"] is not None:
                mapped.setdefault(p["sync_manager"], []).extend(
                    (int(e["index"], 16), e["subindex"], e["bits"])
                    for e in p["entries"]
                    if e["index"] != "0x0000"  # padding: SOEM lists no gap
                )
        assert {sm: v for sm, v in mapped.items() if v} == {
            sm: v for sm, v in soem_slave["mapped"].items() if v
        }, k
        if soem_slave["by"] == "SII":  # names from the SII's STRINGS, as ours
            ours_named = [e["name"] or "" for p in sii["rx_pdos"] + sii["tx_pdos"]
                          if p["sync_manager"] is not None for e in p["entries"]
                          if e["index"] != "0x0000"]  # fmt: skip
            assert sorted(ours_named) == sorted(soem_slave["entry_names"]), k
        for index, _start, length, kind in soem_slave["sms"]:
            if kind in (3, 4) and length:
                bits = sum(p["bits"] for p in sii["rx_pdos"] + sii["tx_pdos"]
                           if p["sync_manager"] == index)  # fmt: skip
                assert (bits + 7) // 8 == length, k
    assert human.returncode == 0, human.stderr
    assert "vendor 0x0000009A" in human.stdout and "checksum 0x" in human.stdout
    assert max(len(line) for line in human.stdout.splitlines()) <= 80


# ------------------------------------------------------------------------------- alias
def _aliases(bus: LiveBus) -> list[int]:
    code, doc, err = _cli(bus, "bus", "scan", "--no-sii")
    assert code == 0, err
    return [s["station_alias"] for s in doc["slaves"]]


def test_alias_shows_in_scan_and_survives_a_reload(bus: LiveBus) -> None:
    proc = start_emulator(bus)
    try:
        before = _aliases(bus)
        code, set3, err = _cli(bus, "bus", "alias", "3", "0x1234")
        after3 = _aliases(bus)
        code4, set4, err4 = _cli(bus, "bus", "alias", "Joint04", "77", "--no-reload")
        not_yet = _aliases(bus)
        code_sii, sii4, err_sii = _cli(bus, "bus", "sii", "read", "4")
        # the ESC reloads its configuration area from the EEPROM, as at power-up: the
        # reload command written to SII control 0x0502 (command 4 in bits 8-10)
        code_rl, reload4, err_rl = _cli(bus, "bus", "reg", "write", "4", "sii_control_status",
                                     "0x0400")  # fmt: skip
        code_rl3, _doc3, _e = _cli(bus, "bus", "reg", "write", "3", "sii_control_status",
                                   "0x0400")  # fmt: skip
        reloaded = _aliases(bus)
        scan_text = _human(bus, "bus", "scan", "--no-sii")
        human = _human(bus, "bus", "alias", "5", "0")
    finally:
        stop_emulator(proc)
    assert before == [0] * LOLA_SLAVES
    assert code == 0, err
    assert set3["schema"] == "lolacli.alias/1"
    assert (set3["previous"], set3["alias"], set3["register"]) == (0, 0x1234, 0x1234)
    assert set3["words_written"] == 2  # word 4 and the checksum, word 7
    assert after3 == [0, 0, 0x1234] + [0] * 22
    assert code4 == 0, err4
    assert (set4["slave"]["position"], set4["reloaded"], set4["register"]) == (4, False, 0)
    assert not_yet == after3  # in the EEPROM only, until the ESC reloads it
    assert code_sii == 0, err_sii
    assert sii4["sii"]["station_alias"] == 77 and sii4["sii"]["checksum_ok"] is True
    assert code_rl == 0 and code_rl3 == 0, err_rl
    assert reload4["written"] == "0004" and reload4["verified"] is False  # done: cleared
    assert reloaded == [0, 0, 0x1234, 77] + [0] * 21
    assert "alias 4660" in scan_text.stdout and "alias 77" in scan_text.stdout
    assert human.returncode == 0, human.stderr
    assert human.stdout.startswith("slave 5: alias 0x0000 (0) -> 0x0000 (0) in the EEPROM")


# ------------------------------------------------------------------------------ states
def _reached(doc: dict) -> list[str]:
    return [s["reached"] for s in doc["slaves"]]


def test_state_walks_the_lola_chain_up_and_down(bus: LiveBus) -> None:
    eni = load_eni(LOLA)
    no_mailbox = {s.position for s in eni.slaves if s.mailbox is None}
    assert no_mailbox  # the GPIO terminals: no bootstrap mailbox, no BOOT
    steps = [
        ("all", "PREOP"), ("all", "SAFEOP"), ("all", "OP"), ("all", "SAFEOP"), ("all", "PREOP"),
        ("all", "INIT"), ("all", "OP"), ("all", "INIT"), ("all", "BOOT"), ("all", "INIT"),
        ("3", "BOOT"), ("3", "OP"), ("2 @0x0000 Joint04", "SAFEOP"), ("all", "OP"),
        ("all", "INIT"),
    ]  # fmt: skip
    proc = start_emulator(bus)
    results = []
    try:
        for who, state in steps:
            results.append(_cli(bus, "bus", "state", *who.split(), state))
        human = _human(bus, "bus", "state", "BOOT")
        al = _cli(bus, "bus", "reg", "read", "1", "0x0130:6")
    finally:
        stop_emulator(proc)
    for (who, state), (code, doc, err) in zip(steps, results, strict=True):
        assert doc.get("schema") == "lolacli.state/1", err
        if (who, state) == ("all", "BOOT"):
            assert code == 1, err
            for s in doc["slaves"]:
                if s["position"] in no_mailbox:
                    assert (s["reached"], s["refused"], s["al_status_code"]) == (
                        "INIT+ERR", "INIT -> BOOT", "0x0013"
                    )
                    assert s["al_status_text"] == "Bootstrap not supported"
                else:
                    assert s["reached"] == "BOOT" and s["ok"], s
            continue
        assert code == 0, (who, state, err, doc)
        if who == "all":
            assert _reached(doc) == [state] * LOLA_SLAVES, (who, state)
        elif who == "3":
            assert _reached(doc) == [state]
        else:
            assert [s["position"] for s in doc["slaves"]] == [2, 1, 4]
            assert _reached(doc) == [state] * 3
    up = results[steps.index(("3", "OP"))][1]["slaves"][0]
    assert up["steps"] == ["BOOT -> INIT", "INIT -> PREOP", "PREOP -> SAFEOP", "SAFEOP -> OP"]
    assert human.returncode == 1
    assert "Bootstrap not supported" in human.stdout
    assert max(len(line) for line in human.stdout.splitlines()) <= 80
    code, doc, err = al
    assert code == 0, err
    assert [(f["name"], f["text"]) for f in doc["fields"]] == [
        ("al_status", "BOOT"), ("al_status_code", "0x0000 No error")  # the last: BOOT
    ]  # fmt: skip


def test_state_refusal_named_with_its_al_status_code(bus: LiveBus) -> None:
    proc = start_emulator(bus, "--stuck-safeop", "5")
    try:
        code, doc, err = _cli(bus, "bus", "state", "OP")
        human = _human(bus, "bus", "state", "5", "OP")
        regs = _cli(bus, "bus", "reg", "read", "5", "al_status_code")
    finally:
        stop_emulator(proc)
    assert code == 1, err
    refused = [s for s in doc["slaves"] if not s["ok"]]
    assert [(s["position"], s["refused"], s["al_status_code"], s["al_status_text"])
            for s in refused] == [(5, "SAFEOP -> OP", "0x0019", "No valid outputs")]  # fmt: skip
    assert refused[0]["reached"] == "SAFEOP+ERR"
    assert [s["reached"] for s in doc["slaves"] if s["ok"]] == ["OP"] * 24
    assert human.returncode == 1
    assert "SAFEOP -> OP refused: 0x0019" in human.stdout
    assert "1 slave of 1 did not reach OP" in human.stdout
    assert regs[0] == 0 and regs[1]["fields"][0]["text"] == "0x0019 No valid outputs"


# ----------------------------------------------------------------- registers, bad input
def test_registers_and_bad_input(bus: LiveBus, tmp_path: Path) -> None:
    proc = start_emulator(bus)
    try:
        counters = _cli(bus, "bus", "reg", "read", "3", "0x0300:20")
        dl = _cli(bus, "bus", "reg", "read", "25", "dl_status")
        outside = _human(bus, "bus", "reg", "read", "3", "0x10000")
        past_end = _human(bus, "bus", "reg", "read", "3", "0xFFFF:2")
        unknown = _human(bus, "bus", "reg", "read", "3", "al_stattus")
        bad_state = _human(bus, "bus", "state", "SAFE-OPERATIONAL")
        saved = tmp_path / "slave3.bin"
        code, doc, err = _cli(bus, "bus", "sii", "read", "3", "-o", str(saved))
        image = bytearray(saved.read_bytes())
        wrong = bytearray(image)
        wrong[14] ^= 0xFF  # the checksum byte of word 7
        (tmp_path / "wrong.bin").write_bytes(wrong)
        refused = _human(bus, "bus", "sii", "write", "3", str(tmp_path / "wrong.bin"))
        other = bytearray(image)
        other[16:20] = (0x2).to_bytes(4, "little")  # another vendor
        (tmp_path / "other.bin").write_bytes(other)
        not_its = _human(bus, "bus", "sii", "write", "3", str(tmp_path / "other.bin"))
        unchanged = _cli(bus, "bus", "sii", "read", "3", "-o", str(tmp_path / "after.bin"))
        changed = bytearray(image)
        changed[0x1C:0x20] = (0xCAFE).to_bytes(4, "little")  # the serial (word 0x0E)
        (tmp_path / "serial.bin").write_bytes(changed)
        written = _cli(bus, "bus", "sii", "write", "3", str(tmp_path / "serial.bin"))
        state = _cli(bus, "bus", "state", "3", "OP")
        guarded = _human(bus, "bus", "reg", "write", "3", "sm2", "0")
        sm2 = _cli(bus, "bus", "reg", "read", "3", "sm2")
        forced = _cli(bus, "bus", "reg", "write", "3", "al_control", "0x0001", "--force")
    finally:
        stop_emulator(proc)
    code_c, doc_c, err_c = counters
    assert code_c == 0, err_c
    names = [f["name"] for f in doc_c["fields"]]
    assert names == ["rx_error_counter", "forwarded_rx_error_counter",
                     "processing_unit_error_counter", "pdi_error_counter",
                     "lost_link_counter"]  # fmt: skip
    assert doc_c["fields"][0]["text"].startswith("port 0: invalid frame 0, RX error 0")
    code_d, doc_d, err_d = dl
    assert code_d == 0, err_d
    text = doc_d["fields"][0]["text"]
    assert text.startswith("port 0: link, open, communication; port 1: no link, closed")
    for done in (outside, past_end, unknown, bad_state, guarded):
        assert done.returncode == 2, done.stderr
        assert done.stdout == "" and len(done.stderr.strip().splitlines()) == 1, done.stderr
        assert "Traceback" not in done.stderr
    assert "outside the ESC's address space" in outside.stderr
    assert "runs past the ESC's address space" in past_end.stderr
    assert "does not exist" in bad_state.stderr
    assert "--force" in guarded.stderr
    assert code == 0, err
    assert len(image) == doc["sii"]["bytes"] and crc8_sii(bytes(image[:14])) == image[14]
    for done in (refused, not_its):
        assert done.returncode == 3, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1 and "nothing written" in done.stderr
    assert "checksum 0x" in refused.stderr and "identity" in not_its.stderr
    assert unchanged[0] == 0 and (tmp_path / "after.bin").read_bytes() == bytes(image)
    code_w, doc_w, err_w = written
    assert code_w == 0, err_w
    assert (doc_w["words_written"], doc_w["verified"]) == (1, True)
    assert doc_w["sii"]["identity"]["serial"] == 0xCAFE
    assert state[0] == 0, state[2]
    code_s, doc_s, err_s = sm2
    assert code_s == 0 and doc_s["al_state"] == "OP", err_s
    assert doc_s["fields"][0]["text"].endswith("on")  # the guarded write did not happen
    code_f, doc_f, err_f = forced
    assert code_f == 0, err_f
    assert doc_f["written"] == "0100" and doc_f["verified"] is True
