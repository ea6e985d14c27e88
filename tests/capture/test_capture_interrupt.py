"""Ctrl-C and SIGTERM on `capture analyze` and `capture list` of a large file: the command
stops within a second, prints what it found in the frames read so far (marked as partial)
and exits 130 (SIGINT) or 143 (SIGTERM). The scanner returns to Python, where the stop is
polled, at least every slice of the file, whatever the engine."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lolacli.capture.analyze import SLICE_BYTES, SLICE_BYTES_PYTHON, analyze_file

ROOT = Path(__file__).resolve().parents[2]
CYCLES = 120_000  # 30 MB: the Python engine reads it in several seconds


def _lrw_pair() -> tuple[bytes, bytes]:
    from lolacli.capture import writer as w
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    def frame(ret: bool) -> bytes:
        d = Datagram.logical(Command.LRW, 0x10000, 64, index=1, wkc=3 if ret else 0)
        return encode_frame(make_frame([d], src=b"\x02" * 6 if ret else b"\x00" * 6), pad=True)

    return w.epb(0, frame(False)), w.epb(0, frame(True))


@pytest.fixture(scope="module")
def large(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """CYCLES cycles of 1 ms, an LRW out and back 40..45 µs later, as nanosecond pcapng
    (the blocks of lolacli's writer, repeated; their timestamps set in place)."""
    from lolacli.capture import writer as w

    out, ret = _lrw_pair()
    pair = np.frombuffer(out + ret, np.uint8)
    rows = np.tile(pair, CYCLES).reshape(CYCLES, pair.size)
    words = rows.view("<u4")  # pcapng blocks are 4-byte aligned; EPB ts at words 3, 4
    t_out = 1_700_000_000 * 10**9 + np.arange(CYCLES, dtype=np.uint64) * 1_000_000
    t_ret = t_out + 40_000 + (np.arange(CYCLES, dtype=np.uint64) * 37) % 5000
    second = len(out) // 4
    for col, t in ((0, t_out), (second, t_ret)):
        words[:, col + 3] = (t >> np.uint64(32)).astype(np.uint32)
        words[:, col + 4] = (t & np.uint64(0xFFFFFFFF)).astype(np.uint32)
    path = tmp_path_factory.mktemp("large") / "large.pcapng"
    with open(path, "wb") as f:
        f.write(w.shb() + w.idb())
        f.write(rows.tobytes())
    return path


@pytest.mark.parametrize("engine", ["c", "python"])
def test_the_scanner_returns_to_python_every_slice(large: Path, engine: str) -> None:
    """Progress is reported, and the stop polled, after every slice at most: a stop asked
    once eight slices are read ends the analysis within the ninth, with a partial report
    of the frames read so far."""
    from lolacli.capture import writer as w

    slice_bytes = SLICE_BYTES_PYTHON if engine == "python" else SLICE_BYTES
    seen: list[int] = []
    report = analyze_file(large, engine=engine, keep_series=True,
                          progress=lambda done, _total: seen.append(done),
                          should_stop=lambda: seen[-1] >= 8 * slice_bytes)
    # (the first gap also holds the interface block, which Python reads between two calls)
    assert max(b - a for a, b in zip(seen, seen[1:], strict=False)) <= slice_bytes + len(w.idb())
    doc = report.to_dict()
    assert doc["interrupted"] is True and report.read_bytes is not None
    assert 8 * slice_bytes <= report.read_bytes <= 9 * slice_bytes
    assert 0 < doc["frames_total"] < 2 * CYCLES and doc["pairs"] == doc["frames_total"] // 2
    stopped = [f for f in doc["findings"] if f["kind"] == "interrupted"]
    assert len(stopped) == 1 and stopped[0]["severity"] == "warning"
    assert doc["lost_frames"] == 0 and report.round_trip_ns is not None
    assert report.round_trip_ns.size == doc["pairs"]
    if engine != "python":  # (the Python engine reads the whole file in several seconds)
        seen.clear()
        whole = analyze_file(large, engine=engine, progress=lambda d, _t: seen.append(d))
        assert whole.interrupted is False and whole.read_bytes is None
        assert whole.counts["frames_total"] == 2 * CYCLES and seen[-1] == large.stat().st_size
        assert max(b - a for a, b in zip(seen, seen[1:], strict=False)) <= slice_bytes + 32


def _started(proc: subprocess.Popen[str], path: Path, timeout: float = 60.0) -> None:
    """Wait until the process has ``path`` open (it is reading it)."""
    deadline = time.monotonic() + timeout
    fd_dir = Path(f"/proc/{proc.pid}/fd")
    while time.monotonic() < deadline:
        try:
            if any(os.readlink(fd_dir / fd) == str(path) for fd in os.listdir(fd_dir)):
                return
        except OSError:
            pass
        assert proc.poll() is None, "the command ended before reading the capture"
        time.sleep(0.01)
    raise AssertionError("the command never opened the capture")


def _interrupt(args: list[str], path: Path, sig: int, out: Path) -> tuple[int, float, str]:
    """Run ``python -m lolacli ARGS``, signal it 0.5 s into reading ``path``; returns the
    exit code, the seconds from the signal to the exit, and stderr."""
    with open(out, "w") as stdout:
        proc = subprocess.Popen(
            [sys.executable, "-m", "lolacli", *args], cwd=ROOT, stdout=stdout,
            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        try:
            _started(proc, path)
            time.sleep(0.5)
            assert proc.poll() is None, "the command ended before the signal"
            sent = time.monotonic()
            proc.send_signal(sig)
            code = proc.wait(timeout=30)
            took = time.monotonic() - sent
        finally:
            if proc.poll() is None:
                proc.kill()
        err = proc.stderr.read() if proc.stderr else ""
    return code, took, err


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["SIGINT", "SIGTERM"])
def test_analyze_stops_within_a_second_with_a_partial_report(large, tmp_path, sig, code):
    out = tmp_path / "out.json"
    got, took, err = _interrupt(
        ["capture", "analyze", str(large), "--engine", "python", "--format", "json"],
        large, sig, out)
    assert got == code, err
    assert took < 1.0, f"{took:.2f} s from the signal to the exit"
    doc = json.loads(out.read_text())
    assert doc["schema"] == "lolacli.capture/1" and doc["interrupted"] is True
    assert 0 < doc["frames_total"] < 2 * CYCLES
    kinds = {f["kind"]: f["severity"] for f in doc["findings"]}
    assert kinds["interrupted"] == "warning"
    assert f"stopped by {signal.Signals(sig).name}" in err and "Traceback" not in err


def test_analyze_human_output_says_it_is_partial(large, tmp_path):
    out = tmp_path / "out.txt"
    got, took, err = _interrupt(["capture", "analyze", str(large), "--engine", "python"],
                                large, signal.SIGINT, out)
    text = out.read_text()
    assert got == 130 and took < 1.0, (err, took)
    assert "interrupted: the analysis was stopped after" in text.replace("\n", " ")
    assert "Traceback" not in err


@pytest.mark.parametrize("fmt", ["human", "json"])
def test_list_stops_within_a_second_and_keeps_what_it_listed(large, tmp_path, fmt):
    out = tmp_path / "list.out"
    got, took, err = _interrupt(["capture", "list", str(large), "--format", fmt], large,
                                signal.SIGINT, out)
    assert got == 130 and took < 1.0, (err, took)
    text = out.read_text()
    if fmt == "json":
        doc = json.loads(text)
        assert doc["interrupted"] is True and 0 < len(doc["frames"]) < 2 * CYCLES
        numbers = [f["number"] for f in doc["frames"]]
    else:
        assert text.endswith("\n")
        numbers = [int(line.split()[0]) for line in text.splitlines()
                   if not line.startswith(" " * 24)]  # (not a datagram's continuation)
    assert numbers == list(range(1, len(numbers) + 1)) and len(numbers) > 10
    assert "stopped by SIGINT" in err and "Traceback" not in err
