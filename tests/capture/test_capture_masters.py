"""Acceptance: captures of real masters (SOEM through pysoem, KickCAT) driving
`lolacli bus emulate` over a veth pair, recorded with dumpcap, get the right verdict.

The master runs in a network namespace of its own, with its end of the veth pair; the
emulator serves the other end. Two dumpcaps record the master's side at once: its
interface (Ethernet, what an engineer captures) and the namespace's "any" device (Linux
cooked v2), whose packet type is the kernel's own word on each frame's direction: the
oracle for the direction the analysis infers (KickCAT's source MAC already has the
locally administered bit). The other oracles: the emulator's count of frames received and
answered (--drop-p drops the rest), and what the master itself saw (WKC per cycle, states).

Needs root, iproute2 and dumpcap; skipped cleanly otherwise.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from lolacli.capture.analyze import analyze_file
from lolacli.files import load_eni

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "lolacli" / "eni_examples"
DRIVER = Path(__file__).resolve().parent / "drive_master.py"
pytestmark = [pytest.mark.root, pytest.mark.slow]

#: keys that describe the file and how direction was told, not the bus
FILE_KEYS = ("file", "format", "engine", "other", "direction_rule")

SCENARIOS = {
    "pysoem-healthy": ("pysoem", "lola.xml", []),
    "pysoem-stuck-safeop": ("pysoem", "lola.xml", ["--stuck-safeop", "3"]),
    "pysoem-drop": ("pysoem", "lola.xml", ["--drop-p", "0.02", "--seed", "3"]),
    "kickcat-healthy": ("kickcat", "lola.xml", []),
    "kickcat-stuck-safeop": ("kickcat", "single_drive.xml", ["--stuck-safeop", "1"]),
    "kickcat-drop": ("kickcat", "lola.xml", ["--drop-p", "0.01", "--seed", "3"]),
}


def _need() -> None:
    if os.geteuid() != 0:
        pytest.skip("needs root for a network namespace and a veth pair")
    for tool in ("ip", "dumpcap", "tshark"):
        if shutil.which(tool) is None:
            pytest.skip(f"needs {tool}")


def _run(*cmd: str) -> None:
    subprocess.run(cmd, check=True, capture_output=True)


class Recording:
    """One run: master in namespace ``a8n…``, emulator on the root side, two dumpcaps."""

    def __init__(self, folder: Path, master: str, eni: Path, faults: list[str]) -> None:
        tag = f"{os.getpid() % 1000:03d}{time.monotonic_ns() % 100:02d}"
        self.ns, self.a, self.b = f"a8n{tag}", f"a8m{tag}", f"a8e{tag}"
        self.folder, self.master, self.eni, self.faults = folder, master, eni, faults
        self.eth, self.sll2 = folder / "master.pcapng", folder / "master-any.pcapng"

    def __enter__(self) -> Recording:
        _run("ip", "netns", "add", self.ns)
        _run("ip", "link", "add", self.a, "type", "veth", "peer", "name", self.b)
        _run("ip", "link", "set", self.a, "netns", self.ns)
        for ns, iface in ((self.ns, self.a), (None, self.b)):
            pre = ["ip", "netns", "exec", ns] if ns else []
            subprocess.run([*pre, "sysctl", "-qw", f"net.ipv6.conf.{iface}.disable_ipv6=1"],
                           capture_output=True, check=False)
            _run(*pre, "ip", "link", "set", iface, "up")
        return self

    def record(self, cycles: int = 300) -> dict:
        inside = ["ip", "netns", "exec", self.ns]
        caps = [subprocess.Popen([*inside, "dumpcap", "-q", "-i", iface, *extra, "-w", str(out)],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
                for iface, extra, out in ((self.a, [], self.eth),
                                          ("any", ["-y", "LINUX_SLL2"], self.sll2))]
        emulator = None
        try:
            _wait_for(lambda: self.eth.exists() and self.sll2.exists(), "dumpcap to start")
            emulator = subprocess.Popen(
                [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", self.b,
                 "--eni", str(self.eni), "--quiet", *self.faults],
                cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
            assert emulator.stderr is not None
            line = emulator.stderr.readline()
            assert "emulating" in line, line + emulator.stderr.read()
            done = subprocess.run(
                [*inside, sys.executable, str(DRIVER), self.master, self.a, "--cycles",
                 str(cycles), "--period", "0.002"],
                cwd=ROOT, capture_output=True, text=True, timeout=600)
            assert done.returncode == 0, done.stderr
            seen = json.loads(done.stdout.strip().splitlines()[-1])
        finally:
            if emulator is not None:
                emulator.send_signal(2)
                _out, err = emulator.communicate(timeout=30)
            time.sleep(0.5)  # the last answers reach the files
            for cap in caps:
                cap.send_signal(2)
                cap.communicate(timeout=30)
        stopped = [x for x in err.splitlines() if x.startswith("stopped:")][-1]
        # "stopped: N frames received, M answered"
        words = stopped.replace(",", "").split()
        seen["emulator"] = {"received": int(words[1]), "answered": int(words[4])}
        return seen

    def __exit__(self, *exc: object) -> None:
        subprocess.run(["ip", "link", "del", self.b], capture_output=True, check=False)
        subprocess.run(["ip", "netns", "del", self.ns], capture_output=True, check=False)


def _wait_for(ready, what: str, timeout_s: float = 20.0) -> None:  # noqa: ANN001
    end = time.monotonic() + timeout_s
    while not ready():
        if time.monotonic() > end:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.05)
    time.sleep(0.5)  # dumpcap writes the file header before it captures


def _packet_types(path: Path) -> Counter:
    """tshark's reading of the kernel's packet type of every EtherCAT frame (4: sent)."""
    out = subprocess.run(["tshark", "-r", str(path), "-Y", "ecat", "-T", "fields", "-e",
                          "sll.pkttype"], capture_output=True, text=True, check=True).stdout
    return Counter(int(x) for x in out.split())


def _bus(rep: dict) -> dict:
    """What both recordings of one run must agree on: not their timestamps' own order (two
    dumpcaps on two CPUs: a frame stamped on one CPU can enter one ring after a later-stamped
    frame of the other, so one file may step back once where the other does not)."""
    out = {k: v for k, v in rep.items() if k not in FILE_KEYS + ("timestamp_findings",)}
    out["findings"] = [f for f in rep["findings"] if f["kind"] != "timestamps-backwards"]
    return out


def _datagram(rep: dict, cmd: str) -> dict:
    found = [g for g in rep["wkc"]["datagrams"] if g["cmd"] == cmd]
    assert len(found) == 1, rep["wkc"]["datagrams"]
    return found[0]


@pytest.mark.timeout(900)
@pytest.mark.parametrize("name", SCENARIOS)
def test_master_capture_verdict(name, tmp_path):
    _need()
    master, eni_name, faults = SCENARIOS[name]
    eni_path = EXAMPLES / eni_name
    eni = load_eni(eni_path)
    with Recording(tmp_path, master, eni_path, faults) as rec:
        seen = rec.record()
    emu = seen["emulator"]
    types = _packet_types(rec.sll2)
    sent = types[4]
    eth = analyze_file(rec.eth).to_dict()
    cooked = analyze_file(rec.sll2).to_dict()

    # direction: the MAC (pysoem) or inferred (KickCAT), as the kernel saw it
    assert eth["direction_rule"] == ("mac" if master == "pysoem" else "inferred")
    assert cooked["direction_rule"] == "packet_type"
    assert (eth["outgoing_frames"], eth["returned_frames"]) == (sent, sum(types.values()) - sent)
    assert _bus(eth) == _bus(cooked)  # the same pairs, losses and verdicts either way

    # pairs and lost frames, against the emulator's own count (veth loses nothing). Seen
    # once, at the start of a run under load: the emulator counted one frame more than
    # either capture holds, and both hold its answer (an unmatched return), so the
    # request reached the emulator without passing the master's capture point.
    assert eth["outgoing_frames"] + eth["unmatched_returned"] == emu["received"]
    assert eth["returned_frames"] == emu["answered"]
    assert eth["pairs"] == emu["answered"] - eth["unmatched_returned"]
    assert eth["unmatched_returned"] <= 1
    dropped = emu["received"] - emu["answered"]
    assert eth["lost_frames"] + eth["in_flight_at_end"] == dropped
    kinds = {f["kind"] for f in eth["findings"] if f["severity"] == "failure"}
    assert ("lost" in kinds) == (eth["lost_frames"] > 0)

    # the engines agree on real captures too
    for engine in ("python",):
        other = analyze_file(rec.eth, engine=engine).to_dict()
        assert _bus(other) == _bus(eth), engine

    with_eni = analyze_file(rec.eth, eni=eni).to_dict()
    assert with_eni["wkc_reference"] == "eni" and with_eni["wkc_checked"] > 0
    _check_wkc(master, seen, eth, with_eni, eni)
    _check_states(name, seen, eth, with_eni)
    # The verdict is a failure exactly when the bus failed by the other oracles: frames the
    # emulator dropped (and not merely in flight at the end), a slave the master saw out of
    # OP, a WKC the master found wrong. (A "healthy" run fails when the loaded host keeps a
    # slave from OP: the master says so, and so must the capture.)
    if master == "pysoem":
        master_bad = seen["bad_wkc"] > 0 or any(s != 8 for s in seen.get("states", []))
    else:
        master_bad = not seen["reached_op"]
    failed = dropped > eth["in_flight_at_end"] or master_bad
    assert eth["verdict"] == with_eni["verdict"] == ("fail" if failed else "pass"), (
        seen, eth["findings"])
    if name.endswith("drop"):
        assert dropped > 0


def _check_wkc(master: str, seen: dict, eth: dict, with_eni: dict, eni) -> None:  # noqa: ANN001
    """The expected WKC is the master's own (pysoem's expected_wkc; KickCAT: 1 per slave
    with inputs for its LRD, 1 per slave with outputs for its LWR), with and without the
    ENI; the mismatches are the returns the master itself found wrong."""
    if "slaves" not in seen:
        return  # KickCAT never came up (--drop-p): no cyclic frame to judge
    if master == "pysoem":
        sent = sum(seen["wkcs"].values())  # one LRW per cycle
        back_in_time = sum(n for w, n in seen["wkcs"].items() if int(w) >= 0)
        for rep, basis in ((eth, "capture-fmmu"), (with_eni, "eni+capture-fmmu")):
            lrw = _datagram(rep, "LRW")
            assert (lrw["expected"], lrw["basis"]) == (seen["expected_wkc"], basis)
            # an answer later than pysoem's timeout is -1 to pysoem, a (late) return here
            late = lrw["returns"] - back_in_time
            assert 0 <= late <= sent - back_in_time
            assert seen["bad_wkc"] <= lrw["mismatches"] + lrw["bring_up"] <= seen["bad_wkc"] + late
        return
    inputs = sum(1 for s in eni.slaves if s.inputs_bits)
    outputs = sum(1 for s in eni.slaves if s.outputs_bits)
    wkc_errors = sum(n for k, n in seen["errors"].items() if "orking" in k or "wkc" in k.lower())
    for rep in (eth, with_eni):
        if not any(g["cmd"] == "LRD" for g in rep["wkc"]["datagrams"]):
            continue  # the bring-up failed before process data
        assert _datagram(rep, "LRD")["expected"] == inputs
        assert _datagram(rep, "LWR")["expected"] == outputs
        if not wkc_errors:
            assert rep["wkc_mismatches"] == 0


def _check_states(name: str, seen: dict, eth: dict, with_eni: dict) -> None:
    """Slaves the master saw out of OP are the capture's not-op findings."""
    unknown: set[int] = set()
    if name.startswith("pysoem"):
        # pysoem's last read_state reads every slave in one FPRD frame after a BRD that
        # shows mixed states; when --drop-p drops that frame, every state reads 0: the
        # master does not know them, and neither does the capture (it holds the request)
        states = seen.get("states", [])
        unknown = {i + 1 for i, s in enumerate(states) if s == 0}
        not_op = {i + 1 for i, s in enumerate(states) if s not in (0, 8)}
    elif name == "kickcat-stuck-safeop":
        not_op = {1}
    else:
        return
    for rep in (eth, with_eni):
        found = {f["message"] for f in rep["findings"] if f["kind"] == "not-op"}
        positions = {int(m.split("(position ")[1].split(")")[0]) for m in found
                     if "(position " in m}  # (BRD reads say it of the whole bus)
        assert not_op <= positions <= not_op | unknown, found
        if unknown and not not_op:
            assert found, "the capture shows no slave out of OP, the master read no state"
    if name.endswith("stuck-safeop"):
        assert not_op and not seen["reached_op"]
