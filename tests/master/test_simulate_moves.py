"""`bus simulate --move` / `--trajectory`: S-curves streamed to the drives in CSP through
the Bus Variables. A move ends at its start plus its distance, takes the planner's time,
and its following error (set-point sent against actual received) is reported; the C
chain core and the Python reference give the same moves; a drive whose velocity limit
the move outruns lags and, with its following-error monitor on, faults; bad values are
one-line usage errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from lolacli.emulator.core import ENGINE_VARIABLE, core_available
from lolacli.files import load_eni
from lolacli.motion.scurve import plan
from lolacli.simulate import options_from_cli, simulate
from lolacli.simulate.moves import DEFAULT_A, DEFAULT_J, DEFAULT_V

ROOT = Path(__file__).resolve().parents[2]
LOLA = ROOT / "lolacli" / "eni_examples" / "lola.xml"
SINGLE = ROOT / "lolacli" / "eni_examples" / "single_drive.xml"
ANCHOR = "<CoE>\n\t\t\t\t\t<InitCmds>\n"


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "lolacli", "bus", "simulate", *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)


def _sim(eni: Path = LOLA, **kw: object) -> dict:
    options = options_from_cli(**kw)  # type: ignore[arg-type]
    return simulate(load_eni(eni), options).doc


def test_a_move_reaches_its_distance_in_the_planners_time() -> None:
    rate = 2000.0
    doc = _sim(rate_hz=rate, duration="1s",
               moves=("Joint04 L Knee:20000", "11:-15000:50000:5e5:1e7"))
    assert doc["verdict"] == "pass", doc["findings"]
    moves = {m["slave"]: m for m in doc["moves"]}
    assert set(moves) == {4, 11}
    for slave, (distance, v, a, j) in {4: (20000, DEFAULT_V, DEFAULT_A, DEFAULT_J),
                                       11: (-15000, 5e4, 5e5, 1e7)}.items():
        m = moves[slave]
        assert m["unit"] == "increments" and m["complete"] and m["goals"] == 1
        assert m["distance"] == distance
        assert m["target_position"] == m["start_position"] + distance
        # the drive's actual position at the end: start + distance within the error
        assert abs(m["end_position"] - (m["start_position"] + distance)) <= m[
            "following_error_max"]
        assert m["duration_s"] == pytest.approx(plan(distance, v, a, j, cycle_s=1 / rate)
                                                .duration, abs=1e-9)
        # the joint lags its set-points by the bus's delay: a few cycles at most at speed
        assert 0 < m["following_error_rms"] <= m["following_error_max"] <= 3 * v / rate
    assert "planner" in doc["sections_us"] and doc["sections_us"]["planner"]["count"] > 0


def test_the_default_run_has_no_moves_and_no_planner_section() -> None:
    doc = _sim(duration="100ms")
    assert doc["moves"] is None and "planner" not in doc["sections_us"]


def test_all_moves_every_drive_and_a_trajectory_goal_interrupts(tmp_path: Path) -> None:
    traj = tmp_path / "goals.csv"
    traj.write_text("# a knee goal interrupted mid-way, then every drive\n"
                    "time_s,joint,distance,v,a,j\n"
                    "0,L Knee,40000,100000,1000000,20000000\n"
                    "0.1,Joint04,-5000,100000,1000000,20000000\n"
                    "0.3,all,3000,100000,1000000,20000000\n")
    doc = _sim(duration="1s", trajectory=traj)
    assert doc["verdict"] == "pass", doc["findings"]
    assert len(doc["moves"]) == doc["drives"] == 21
    knee = next(m for m in doc["moves"] if m["slave"] == 4)
    assert knee["goals"] == 3 and knee["distance"] == 3000
    assert knee["end_position"] == knee["start_position"] + 3000
    others = [m for m in doc["moves"] if m["slave"] != 4]
    assert all(m["end_position"] == m["start_position"] + 3000 for m in others)
    # the knee was turned round at 0.1 s at speed: its error peaks higher than the others'
    assert knee["following_error_max"] >= max(m["following_error_max"] for m in others)


def test_json_trajectory_and_its_bad_row(tmp_path: Path) -> None:
    good = tmp_path / "goals.json"
    good.write_text(json.dumps({"goals": [{"time_s": 0, "joint": "7", "distance": 1234}]}))
    doc = _sim(duration="500ms", trajectory=good)
    (m,) = doc["moves"]
    assert m["joint"] == "Joint07 L Toe" and m["end_position"] == m["start_position"] + 1234
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,joint,distance\n0,7,100\n-1,7,100\n")
    done = run("--duration", "100ms", "-q", "--trajectory", str(bad))
    assert done.returncode == 3
    assert done.stderr.count("\n") == 1 and f"{bad}:3" in done.stderr


@pytest.mark.parametrize(
    ("move", "says"),
    [
        ("Joint99:5", "no slave 'Joint99'"),
        ("4:nan", "finite"),
        ("4:100:-1:1e6:1e7", "velocity limit must be > 0"),
        ("4:100:1e5:1e6:0", "jerk limit must be > 0"),
        ("22:100", "not a CiA 402 drive"),
        ("GPIO 2AI:100", "not a CiA 402 drive"),
        ("4", "no distance"),
        ("4:100:5", "V, A and J go together"),
        ("all:1e300", "is over 2,147,483,647 increments"),
        ("all:1e12:1e-12:1e-12:1e-12", "is over"),
    ],
)
def test_bad_move_is_a_one_line_usage_error(move: str, says: str) -> None:
    done = run("--duration", "100ms", "-q", "--move", move)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and says in done.stderr
    assert len(done.stderr.rstrip("\n")) <= 80, done.stderr
    assert "Traceback" not in done.stderr and done.stdout == ""


def test_move_with_no_middleware_is_a_usage_error() -> None:
    done = run("--duration", "100ms", "-q", "--move", "4:100", "--no-middleware")
    assert done.returncode == 2 and "--no-middleware" in done.stderr


@pytest.mark.skipif(not core_available(), reason="the C core is not built")
def test_the_c_core_and_the_python_reference_move_the_same(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    docs = {}
    for engine in ("c", "python"):
        monkeypatch.setenv(ENGINE_VARIABLE, engine)
        docs[engine] = _sim(duration="500ms", moves=("all:8000", "3:-6000:40000:4e5:8e6"))
    keys = ("slave", "start_position", "end_position", "following_error_rms",
            "following_error_max", "duration_s")
    c, py = ([{k: m[k] for k in keys} for m in docs[e]["moves"]] for e in ("c", "python"))
    assert c == py and len(c) == 21


def _limited_drive(tmp_path: Path, max_velocity: int, window: int | None) -> Path:
    """The single drive with 0x607F (and 0x6065/0x6066) written by InitCmds."""
    def cmd(index: int, data: bytes) -> str:
        return ("<InitCmd><Transition>PS</Transition><Timeout>3000</Timeout><Ccs>1</Ccs>"
                f"<Index>#x{index:04x}</Index><SubIndex>0</SubIndex>"
                f"<Data>{data.hex()}</Data></InitCmd>\n")
    cmds = cmd(0x607F, max_velocity.to_bytes(4, "little"))
    if window is not None:
        cmds += cmd(0x6065, window.to_bytes(4, "little")) + cmd(0x6066, (5).to_bytes(2, "little"))
    text = SINGLE.read_text()
    assert text.count(ANCHOR) == 1
    path = tmp_path / "drive.xml"
    path.write_text(text.replace(ANCHOR, ANCHOR + cmds))
    return path


def test_a_drive_slower_than_the_move_lags_and_faults_past_its_window(tmp_path: Path) -> None:
    move = ("1:20000:100000:1e6:2e7",)
    free = _sim(SINGLE, duration="1s", moves=move)["moves"][0]
    slow = _sim(_limited_drive(tmp_path, 40_000, None), duration="1s", moves=move)
    (lag,) = slow["moves"]
    assert slow["verdict"] == "pass"
    assert lag["end_position"] == lag["start_position"] + 20000  # it gets there, later
    assert lag["following_error_max"] > 10 * free["following_error_max"]
    assert lag["duration_s"] == free["duration_s"]  # the profile is the same
    faulted = _sim(_limited_drive(tmp_path, 40_000, 1000), duration="1s", moves=move)
    assert faulted["verdict"] == "fail"
    (fault,) = faulted["drive_faults"]
    assert fault["error_code"] == 0x8611


@pytest.mark.parametrize("at", [[3], [2, 10, 18, 26], [0, 5, 30], [20, 4, 12]])
def test_int32_views_write_and_read_in_place(at: list[int]) -> None:
    import numpy as np

    from lolacli.simulate.moves import _int32s

    buffer = bytearray(range(40))
    untouched = [i for i in range(40) if not any(a <= i < a + 4 for a in at)]
    view = _int32s(buffer, at)
    values = [(-1) ** i * (i + 1) * 123_456_789 for i in range(len(at))]
    view[:] = np.asarray(values, dtype="<i4")
    assert [int.from_bytes(buffer[a:a + 4], "little", signed=True) for a in at] == values
    assert [buffer[i] for i in untouched] == untouched
    row = np.zeros(len(at), dtype="<i4")
    buffer[at[0]:at[0] + 4] = (-7).to_bytes(4, "little", signed=True)
    row[:] = view
    assert list(row) == [-7, *values[1:]]


@pytest.mark.parametrize(
    ("path", "says"),
    [
        ("/dev/zero", "file too large for a trajectory file"),
        ("/", "is a directory, not a trajectory file"),
        ("/nonexistent/goals.csv", "no such file"),
    ],
)
def test_unreadable_trajectory_is_exit_3_without_reading_forever(path: str, says: str) -> None:
    """/dev/zero has no size to stat: the read is bounded (it used to read on and on)."""
    done = run("--duration", "100ms", "-q", "--trajectory", path)
    assert done.returncode == 3, done.stderr
    assert done.stderr.count("\n") == 1 and says in done.stderr and path in done.stderr
