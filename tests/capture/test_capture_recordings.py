"""The pcapng and MCAP files `bus simulate --pcap/--mcap` writes (lolacli.master.record)
open in tshark and in the mcap reader however the run was stopped, and carry the day of
the run, not 1970.

A stop (Ctrl-C, SIGTERM) raises a KeyboardInterrupt between two Python operations. The
in-process tests raise one at EVERY line the recorders' write and close run through
(theirs, the pcapng encoder's and the mcap library's), one point per run, by a trace
function; the subprocess test signals a real `bus simulate` at several moments.
"""

from __future__ import annotations

import gc
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from decimal import Decimal
from pathlib import Path

import mcap.reader
import mcap.writer  # (imported before any trace: a stop inside an import is another story)
import pytest
from capture_oracle import tshark_available

from lolacli.master.record import McapRecorder, PcapngRecorder, WallClock

ROOT = Path(__file__).resolve().parents[2]
needs_tshark = pytest.mark.skipif(not tshark_available(), reason="tshark not installed")
EARLIER = 5  # frames or messages written whole before the interrupted one


def _lrw() -> bytes:
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    d = Datagram.logical(Command.LRW, 0x10000, 8, index=1)
    return encode_frame(make_frame([d], src=b"\x00" * 6), pad=True)


FRAME = _lrw()


def _stop_at_line(n: int, action: Callable[[], None]) -> bool:
    """Run ``action`` with a KeyboardInterrupt raised at the n-th line any Python code
    under it starts (1-based); False when it completed in fewer lines."""
    count = 0

    def tracer(frame, event, arg):  # noqa: ANN001, ANN202
        nonlocal count
        if event == "line":
            count += 1
            if count == n:
                raise KeyboardInterrupt
        return tracer

    gc.disable()  # (a recorder of an earlier run, collected under the trace, would close)
    sys.settrace(tracer)
    try:
        action()
    except KeyboardInterrupt:
        return True
    finally:
        sys.settrace(None)
        gc.enable()
    return False


def _close(recorder: PcapngRecorder | McapRecorder) -> None:
    try:
        recorder.close()
    except KeyboardInterrupt:  # close finishes, then raises the stop it held
        pass


def _tshark(path: Path) -> list[str]:
    r = subprocess.run(["tshark", "-r", str(path), "-T", "fields", "-e", "frame.time_epoch",
                        "-e", "_ws.malformed"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "cut short" not in r.stderr and "appears to be damaged" not in r.stderr, r.stderr
    rows = r.stdout.splitlines()
    assert not any("\t" in row and row.split("\t")[1] for row in rows)  # nothing malformed
    return [row.split("\t")[0] for row in rows]


def _mcap_topics(path: Path) -> dict[str, int]:
    topics: dict[str, int] = {}
    with open(path, "rb") as f:
        reader = mcap.reader.make_reader(f, validate_crcs=True)
        for _schema, channel, message in reader.iter_messages():
            json.loads(message.data)
            topics[channel.topic] = topics.get(channel.topic, 0) + 1
    return topics


def _points(run: Callable[[int], bool]) -> int:
    """Call ``run(n)`` for n = 1, 2, ... until it completes without being stopped."""
    n = 1
    while run(n):
        n += 1
    assert n > 5, "the traced code ran through too few lines: the trace did not apply"
    return n - 1


@needs_tshark
def test_pcapng_stopped_at_every_line_of_a_write_or_close_opens_in_tshark(tmp_path):
    files: dict[str, tuple[Path, int]] = {}

    def run(n: int, in_close: bool) -> bool:
        path = tmp_path / f"{'c' if in_close else 'w'}{n}.pcapng"
        clock = WallClock()
        clock.offset_ns = 1_700_000_000 * 10**9  # the same bytes for the same frames
        rec = PcapngRecorder(path, clock)
        for i in range(EARLIER):
            rec(i * 1000, FRAME, False)
        if in_close:
            stopped = _stop_at_line(n, rec.close)
        else:
            stopped = _stop_at_line(n, lambda: rec(EARLIER * 1000, FRAME, True))
        _close(rec)
        assert rec.frames in (EARLIER, EARLIER + 1)
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        files.setdefault(digest, (path, rec.frames))
        return stopped

    writes = _points(lambda n: run(n, False))
    closes = _points(lambda n: run(n, True))
    assert writes > 5 and closes > 5
    assert len(files) <= 4  # every point leaves one of a few whole files
    for path, frames in files.values():  # tshark once per distinct file
        assert len(_tshark(path)) == frames


@pytest.mark.parametrize("chunk_bytes", [1, 1 << 20], ids=["chunk-per-message", "1-MiB"])
def test_mcap_stopped_at_every_line_of_a_write_or_close_opens(tmp_path, chunk_bytes):
    """With a chunk per message the interrupted write finishes a chunk (compression,
    indexes); with 1 MiB chunks it only adds to the open one, and a stop in close
    interrupts the summary."""
    def run(n: int, in_close: bool) -> bool:
        path = tmp_path / "m.mcap"
        rec = McapRecorder(path, chunk_bytes=chunk_bytes)
        for i in range(EARLIER):
            rec.write("/cycle", i * 1000, {"cycle": i, "t_ns": i * 1000})
        if in_close:
            stopped = _stop_at_line(n, rec.close)
        else:
            stopped = _stop_at_line(
                n, lambda: rec.write("/cycle", EARLIER * 1000, {"cycle": EARLIER}))
        _close(rec)
        got = _mcap_topics(path).get("/cycle", 0)
        if chunk_bytes == 1 or not stopped:
            assert got >= EARLIER, n  # the earlier chunks are whole
        if not stopped:
            assert got == rec.messages == EARLIER + (not in_close)
        return stopped

    writes, closes = _points(lambda n: run(n, False)), _points(lambda n: run(n, True))
    assert writes > 10 and closes > 10


def test_a_stop_while_opening_leaves_a_file_that_opens(tmp_path):
    path = tmp_path / "open.mcap"
    held: list[McapRecorder] = []  # (collected after the trace, not under it)

    def run(n: int) -> bool:
        stopped = _stop_at_line(n, lambda: held.append(McapRecorder(path)))
        for rec in held:
            _close(rec)
        held.clear()
        if path.exists():  # (not when stopped before it was created)
            assert _mcap_topics(path) == {}
            path.unlink()
        return stopped

    assert _points(run) > 10


@needs_tshark
def test_timestamps_are_the_day_of_the_run(tmp_path):
    """Transport time (virtual from 0, or monotonic) plus the wall clock at the first
    frame: tshark shows today, and the MCAP log times agree with the pcapng."""
    before = time.time_ns()
    clock = WallClock()
    frames = PcapngRecorder(tmp_path / "t.pcapng", clock)
    messages = McapRecorder(tmp_path / "t.mcap", clock)
    for i in range(3):
        frames(i * 500_000, FRAME, False)
        messages.write("/cycle", i * 500_000, {"cycle": i, "t_ns": i * 500_000})
    frames.close()
    messages.close()
    after = time.time_ns()
    # exact decimals (the pcapng is in nanoseconds): a float of today's epoch keeps only
    # ~16 digits, so the two could differ by one in the last place
    epochs_ns = [int(Decimal(t) * 1_000_000_000) for t in _tshark(tmp_path / "t.pcapng")]
    assert before <= epochs_ns[0] <= after
    assert [t - epochs_ns[0] for t in epochs_ns] == [0, 500_000, 1_000_000]
    with open(tmp_path / "t.mcap", "rb") as f:
        times = [m.log_time for _, _, m in mcap.reader.make_reader(f).iter_messages()]
    assert times == epochs_ns


def _simulate(tmp_path: Path, delay_s: float, k: int) -> tuple[int, Path, Path, str]:
    pcap, mcap = tmp_path / f"s{k}.pcapng", tmp_path / f"s{k}.mcap"
    proc = subprocess.Popen(
        [sys.executable, "-m", "lolacli", "bus", "simulate", "--duration", "3600s",
         "--pcap", str(pcap), "--mcap", str(mcap), "--format", "json", "--quiet"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    deadline = time.monotonic() + 60
    while not pcap.exists() and time.monotonic() < deadline:
        time.sleep(0.005)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=60)
    return proc.returncode, pcap, mcap, err


@needs_tshark
@pytest.mark.parametrize("delay_s", [0.0, 0.05, 0.3, 1.0])
def test_bus_simulate_stopped_by_sigint_leaves_files_that_open(tmp_path, delay_s):
    """From just after the files are created (bring-up) to the cyclic run. A stop in the
    bring-up ends it at once: its files may hold no frame yet, and still open."""
    start = time.time()
    code, pcap, mcap, err = _simulate(tmp_path, delay_s, 0)
    assert code == 130 and "Traceback" not in err, err
    epochs = [float(t) for t in _tshark(pcap)]  # opens in tshark, nothing malformed
    if not epochs:
        assert delay_s < 1.0, "a second into the run, frames must have been written"
        # stopped between opening the two files: the MCAP never was
        assert not mcap.exists() or _mcap_topics(mcap).get("/cycle", 0) == 0
        return
    assert start - 1 <= epochs[0] <= time.time()
    shown = subprocess.run(["tshark", "-r", str(pcap), "-c", "1", "-T", "fields", "-e",
                            "frame.time"], capture_output=True, text=True).stdout
    assert time.strftime("%Y", time.gmtime(epochs[0])) in shown and "1970" not in shown
    topics = _mcap_topics(mcap)
    assert delay_s < 1.0 or topics.get("/cycle", 0) > 0
