"""`lolacli bus simulate`: the acceptance numbers, faults against `capture analyze` of the
simulator's own pcapng, tshark and mcap as oracles of the recordings, bad input, Ctrl-C,
shared memory driven from a second process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lolacli.files import load_eni
from lolacli.master.shm import ShmClient

ROOT = Path(__file__).resolve().parents[2]
LOLA = ROOT / "lolacli" / "eni_examples" / "lola.xml"


def run(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "lolacli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_acceptance_lola_10s_at_2khz_matches_bus_timing() -> None:
    sim = run("bus", "simulate", "--rate", "2000", "--duration", "10s", "--format", "json")
    assert sim.returncode == 0, sim.stderr
    doc = json.loads(sim.stdout)
    assert doc["schema"] == "lolacli.simulate/1"
    assert (doc["cycles"], doc["slaves"], doc["frame_bytes"]) == (20_000, 25, 846)
    assert doc["wire_time_us"] == 67.68
    assert doc["wkc_mismatches"] == 0 and doc["lost_frames"] == 0
    assert doc["drives_enabled"] == doc["drives"] == 21
    assert doc["drive_faults"] == []
    timing = json.loads(run("bus", "timing", "--format", "json").stdout)
    assert (
        doc["round_trip_us"]["mean"] == doc["round_trip_us"]["max"] == timing["predicted_total_us"]
    )
    assert doc["max_rate_hz"] > doc["max_rate_with_software_hz"] > 0
    assert set(doc["sections_us"]) == {
        "rx",
        "copy_rx",
        "proc_data",
        "control",
        "copy_tx",
        "send",
        "admin",
    }
    assert doc["realtime_factor"] > 0 and doc["dc_max_error_ns"] is not None


FAULTS = [
    ("--drop-p", "0.02", "--seed", "7"),
    ("--stuck-safeop", "5"),
    ("--link-down", "10@0.4"),
    ("--link-down", "3"),
    ("--drift-ppb", "3000"),
    ("--drop-p", "0.05", "--link-down", "20@0.3", "--stuck-safeop", "2"),
]


@pytest.mark.parametrize("faults", FAULTS, ids=[" ".join(f) for f in FAULTS])
def test_faults_simulator_counts_equal_capture_analyze(
    tmp_path: Path, faults: tuple[str, ...]
) -> None:
    pcap = tmp_path / "sim.pcapng"
    sim = run(
        "bus", "simulate", "--duration", "1s", "--pcap", str(pcap), "--format", "json", *faults
    )
    assert sim.returncode in (0, 1), sim.stderr
    doc = json.loads(sim.stdout)
    ana = run("capture", "analyze", str(pcap), "--eni", str(LOLA), "--format", "json")
    cap = json.loads(ana.stdout)
    assert cap["malformed_frames"] == 0
    assert cap["outgoing_frames"] == doc["frames_sent"]
    assert cap["unmatched_outgoing"] == doc["lost_frames"]
    assert cap["cyclic_frames"] == doc["cyclic_frames"]
    assert cap["cyclic_unmatched"] == doc["cyclic_lost_frames"]
    assert cap["wkc_mismatches"] == doc["wkc_mismatches"]
    assert cap["wkc"]["checked_datagrams"] == doc["wkc_checked"]
    assert cap["round_trip_cyclic_us"]["mean"] == pytest.approx(
        doc["round_trip_us"]["mean"], abs=1e-3
    )
    assert cap["cycle_period_us"]["median"] == pytest.approx(500.0)
    assert sim.returncode == (
        1 if doc["lost_frames"] or doc["wkc_mismatches"] or doc["refusals"] else 0
    )
    if "--stuck-safeop" in faults:
        assert any(r["al_status_code"] == "0x0019" for r in doc["refusals"])
    if "--drift-ppb" in faults:
        assert doc["dc_max_error_ns"] > 0


def test_recordings_decode_in_tshark_and_mcap(tmp_path: Path) -> None:
    pcap, mcap = tmp_path / "a.pcapng", tmp_path / "a.mcap"
    sim = run(
        "bus",
        "simulate",
        "--cycles",
        "400",
        "--pcap",
        str(pcap),
        "--mcap",
        str(mcap),
        "--format",
        "json",
        "--drop-p",
        "0.01",
    )
    doc = json.loads(sim.stdout)
    shark = subprocess.run(
        [
            "tshark",
            "-r",
            str(pcap),
            "-T",
            "fields",
            "-e",
            "frame.number",
            "-e",
            "ecat.cmd",
            "-e",
            "_ws.malformed",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    rows = [line.split("\t") for line in shark.stdout.splitlines()]
    assert len(rows) == doc["pcap"]["frames"]
    assert all(r[1] for r in rows) and not any(r[2] for r in rows if len(r) > 2)
    from mcap.reader import make_reader

    with open(mcap, "rb") as f:
        reader = make_reader(f)
        topics: dict[str, int] = {}
        joints = None
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            topics[channel.topic] = topics.get(channel.topic, 0) + 1
            if channel.topic == "/joints":
                joints = json.loads(message.data)
    assert topics["/cycle"] == doc["cycles"] + doc["startup_cycles"]
    assert topics["/joints"] >= doc["cycles"] and "/dc" in topics
    assert joints is not None and len(joints["names"]) == 21
    assert joints["target"] != [0] * 21


def _eni_without_cyclic(tmp_path: Path) -> Path:
    text = (ROOT / "lolacli" / "eni_examples" / "single_drive.xml").read_text()
    start, end = text.index("<Cyclic>"), text.index("</Cyclic>") + len("</Cyclic>")
    path = tmp_path / "eni-no-cyclic.xml"
    path.write_text(text[:start] + text[end:])
    return path


@pytest.mark.parametrize(
    "args, code, words",
    [
        (("--watch", "Joint04 L Knee.Inputs.Position actual valu"), 2, "did you mean"),
        (("--set", "Joint04 L Knee.Outputs.Target position=1.5"), 2, "not a value of type"),
        (("--set", "Joint04 L Knee.Inputs.Statusword=1"), 2, "is an input"),
        (("--pcap", "/nonexistent-dir/x.pcapng"), 2, "cannot write"),
        (("--mcap", "/"), 2, "is a directory"),
        (("--link-down", "0"), 4, "no answer"),
        (("--rate", "0"), 2, "--rate"),
    ],
)
def test_bad_input_is_one_line_with_its_exit_code(args, code: int, words: str) -> None:
    r = run("bus", "simulate", "--cycles", "10", *args)
    assert r.returncode == code, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in r.stderr


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("--eni", "lola.xml", "--pcap", "lola.xml"), "--pcap lola.xml: is the same file as --eni"),
        (("--eni", "lola.xml", "--mcap", "./link.xml"), "--mcap link.xml: is the same file as"),
        (("--pcap", "out.x", "--mcap", "out.x"), "--mcap out.x: is the same file as --pcap"),
        (("--pcap", "fifo"), "--pcap fifo: is a FIFO"),
    ],
)
def test_a_recording_over_an_input_or_a_fifo_is_refused(cli, tmp_path: Path, args, says) -> None:
    """The recordings are opened for writing and cut to length at the end: one that is
    an input (the ENI, by a link too), the other recording, or a FIFO is refused, exit 2,
    one line, before the run; the ENI stays as it was."""
    eni = tmp_path / "lola.xml"
    eni.write_bytes(LOLA.read_bytes())
    (tmp_path / "link.xml").symlink_to("lola.xml")
    os.mkfifo(tmp_path / "fifo")
    cwd = Path.cwd()
    os.chdir(tmp_path)
    try:
        code, out, err = cli("bus", "simulate", "--cycles", "10", "--quiet", *args)
    finally:
        os.chdir(cwd)
    assert code == 2, err
    assert err.count("\n") == 1 and says in err and out == ""
    assert eni.read_bytes() == LOLA.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo", "link.xml", "lola.xml"]


def test_a_bare_duration_is_seconds_as_in_bus_emulate() -> None:
    """`--duration 1` is one second (as `bus emulate --duration` and `sdo serve --duration`
    take it), not 1 µs, which ran 0 cycles and passed."""
    doc = json.loads(run("bus", "simulate", "--duration", "1", "--format", "json").stdout)
    assert doc["cycles"] == 2000


def test_an_eni_without_cyclic_frames_is_exit_3(tmp_path: Path) -> None:
    r = run("bus", "simulate", "--cycles", "10", "--eni", str(_eni_without_cyclic(tmp_path)))
    assert r.returncode == 3 and "no cyclic frame" in r.stderr and len(r.stderr.splitlines()) == 1


def test_watch_and_set_variables() -> None:
    r = run(
        "bus",
        "simulate",
        "--cycles",
        "50",
        "--format",
        "json",
        "--set",
        "GPIO 8DI 8DO.Channel 2.Output=1",
        "--watch",
        "GPIO 8DI 8DO.Channel 2.Input",
    )
    doc = json.loads(r.stdout)
    assert r.returncode == 0, r.stderr
    assert doc["watch"] == {"GPIO 8DI 8DO.Channel 2.Input": True}


def test_ctrl_c_keeps_a_readable_pcapng(tmp_path: Path) -> None:
    pcap = tmp_path / "cut.pcapng"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "lolacli",
            "bus",
            "simulate",
            "--duration",
            "3600s",
            "--pcap",
            str(pcap),
            "--format",
            "json",
            "--quiet",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while (not pcap.exists() or pcap.stat().st_size < 2_000_000) and time.monotonic() < deadline:
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    doc = json.loads(out)
    assert doc["interrupted"] and doc["cycles"] > 0
    cap = json.loads(
        run("capture", "analyze", str(pcap), "--eni", str(LOLA), "--format", "json").stdout
    )
    assert cap["outgoing_frames"] == doc["frames_sent"] and cap["malformed_frames"] == 0
    assert cap["unmatched_outgoing"] == 0


def test_shm_a_second_process_moves_a_joint_and_sees_it_follow() -> None:
    name = f"lolacli-test-{os.getpid()}"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "lolacli",
            "bus",
            "simulate",
            "--duration",
            "600s",
            "--pace",
            "--shm",
            name,
            "--quiet",
            "--format",
            "json",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        client = ShmClient(name, load_eni(LOLA), timeout_s=60)
        actual = "Joint04 L Knee.Inputs.Position actual value"
        status = "Joint04 L Knee.Inputs.Statusword"
        deadline = time.monotonic() + 60
        while client.get(status) & 0x6F != 0x27 and time.monotonic() < deadline:
            time.sleep(0.01)  # wait for the drive to be enabled
        start = client.read()
        goal = client.get(actual, start) + 123_456
        client.set("Joint04 L Knee.Outputs.Target position", goal)
        client.commit()
        while time.monotonic() < deadline:
            snap = client.read()
            if client.get(actual, snap) == goal:
                break
            time.sleep(0.005)
        assert client.get(actual, snap) == goal and snap.cycle > start.cycle
        client.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert not Path(f"/dev/shm/{name}").exists()
