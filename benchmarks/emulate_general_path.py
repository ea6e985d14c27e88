"""CPU time of the emulated chain per frame and command type, a real master's frames replayed.

The frames a master sent (taken from a capture of its side, e.g. one kept by
``emulate_latency.py --keep``; without one, the start-up of tests/emulator/bus.py's small
master through the ENI's InitCmds followed by cyclic frames) go through
``Chain.process(frame, t, defer_cycles=True)`` at their capture times, as ``bus emulate``
runs them; the work after the answer (firmware, device cycles) runs after each frame and is
timed apart. Both engines run the same frames in the same process, one after the other
(``python``: the reference; ``c``: the C core), and their replies are compared. Printed
per engine and command type (the frame's commands, e.g. ``FPRD`` or ``BRD+LRW``): count,
median/p99/max µs of the answer, and ``python_over_c`` per type. Timings vary with the load
on the machine (printed); the ratios in one run much less.

    python benchmarks/emulate_general_path.py --capture /tmp/cap/pysoem-idle.pcapng
    python benchmarks/emulate_general_path.py            # the test master's start-up, LOLA
"""

from __future__ import annotations

import argparse
import gc
import hashlib
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
DEFAULT_ENI = ROOT / "lolacli" / "eni_examples" / "lola.xml"


def master_frames(path: Path) -> list[tuple[int, bytes]]:
    """(time ns from the first, frame) of every frame the master sent: a frame that is
    not the answer to the pending one of the same command/index/length sequence (its
    source MAC's local bit, a WKC or an ADP changed on the way) is the master's."""
    from lolacli.capture.reader import iter_frames
    from lolacli.errors import WireError
    from lolacli.wire.frame import decode_frame

    pending: dict[tuple[tuple[int, int, int], ...], tuple[bytes, tuple[int, ...]]] = {}
    out: list[tuple[int, bytes]] = []
    t0: int | None = None
    for frame in iter_frames(path):
        try:
            datagrams = decode_frame(frame.data).datagrams
        except WireError:
            continue
        key = tuple((d.cmd, d.index, len(d.data)) for d in datagrams)
        fields = tuple(v for d in datagrams for v in (d.wkc, d.adp))
        first = pending.get(key)
        if first is not None and ((frame.data[6] ^ first[0][6]) & 0x02 or fields != first[1]):
            del pending[key]
            continue
        pending[key] = (frame.data[:12], fields)
        t0 = frame.timestamp_ns if t0 is None else t0
        out.append((frame.timestamp_ns - t0, bytes(frame.data)))
    return out


def test_master_frames(eni_path: Path, cycles: int) -> list[tuple[int, bytes]]:
    """The frames tests/emulator/bus.py's master sends for a start-up and ``cycles``."""
    from lolacli.emulator.slave import build_chain
    from lolacli.files import load_eni
    from tests.emulator.bus import Bus

    eni = load_eni(eni_path)
    chain = build_chain(eni, engine="python")
    sent: list[tuple[int, bytes]] = []
    process = chain.process

    def recording(frame: bytes, t_ns: int, *, defer_cycles: bool = False):  # type: ignore[no-untyped-def]
        sent.append((t_ns, bytes(frame)))
        return process(frame, t_ns, defer_cycles=defer_cycles)

    chain.process = recording  # type: ignore[method-assign]
    bus = Bus(chain)
    bus.bring_up(eni)
    for _ in range(cycles):
        bus.cycle(eni)
    t0 = sent[0][0]
    return [(t - t0, f) for t, f in sent]


def kind_of(frame: bytes) -> str:
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import decode_frame

    names = []
    for d in decode_frame(frame).datagrams:
        try:
            name = Command(d.cmd).name
        except ValueError:
            name = f"0x{d.cmd:02X}"
        if name not in names:
            names.append(name)
    n = len(decode_frame(frame).datagrams)
    return "+".join(names) + (f" x{n}" if n > 1 and len(names) == 1 else "")


def line_frames(eni_path: Path, after_ns: int, count: int) -> list[tuple[int, bytes]]:
    """Register frames of one datagram per slave, as KickCAT and SOEM send at start-up
    (KickCAT's AL status polls and SM/FMMU writes): ``count`` FPRD frames of AL status and
    ``count`` FPWR frames of the DC cyclic unit control (0), 100 µs apart."""
    from lolacli.files import load_eni
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    slaves = load_eni(eni_path).slaves
    frames = []
    for cmd, ado, data in ((Command.FPRD, 0x0130, 2), (Command.FPWR, 0x0980, b"\0\0")):
        ds = [Datagram.physical(cmd, s.station_address, ado, data) for s in slaves]
        frames.append(encode_frame(make_frame(ds, src=b"\x02" * 6), pad=True))
    return [(after_ns + 100_000 * i, frames[i % 2]) for i in range(2 * count)]


def run(engine: str, eni_path: Path, frames: list[tuple[int, bytes]]) -> dict[str, object]:
    from lolacli.emulator.slave import build_chain
    from lolacli.files import load_eni

    chain = build_chain(load_eni(eni_path), engine=engine)
    kinds = [kind_of(f) for _, f in frames]
    answer: dict[str, list[int]] = defaultdict(list)
    after: list[int] = []
    digest = hashlib.blake2b(digest_size=16)
    clock = time.perf_counter_ns
    base = 1_000_000_000
    gc.collect()
    gc.disable()
    try:
        for (t_ns, frame), kind in zip(frames, kinds, strict=True):
            t = base + t_ns
            start = clock()
            reply, _delay = chain.process(frame, t, defer_cycles=True)
            answered = clock()
            chain.run_deferred_cycles()
            after.append(clock() - answered)
            answer[kind].append(answered - start)
            digest.update(reply or b"-")
    finally:
        gc.enable()
    return {
        "by_command": {
            k: summary(v) for k, v in sorted(answer.items(), key=lambda kv: -len(kv[1]))
        },
        "after_answer_us": summary(after),
        "replies_blake2b": digest.hexdigest(),
        "planned_frames": chain.stats.planned_frames,
    }


def summary(values: list[int]) -> dict[str, float]:
    ordered = sorted(values)
    n = len(ordered)
    return {
        "count": n,
        "median": round(ordered[n // 2] / 1000, 2),
        "p99": round(ordered[min(n - 1, int(0.99 * n))] / 1000, 2),
        "max": round(ordered[-1] / 1000, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eni", type=Path, default=DEFAULT_ENI)
    parser.add_argument("--capture", type=Path, help="a capture of the master's side")
    parser.add_argument("--cycles", type=int, default=2000, help="without --capture")
    parser.add_argument(
        "--line-frames",
        type=int,
        default=500,
        help="then this many FPRD and FPWR frames of one datagram per slave (0: none)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.capture:
        frames = master_frames(args.capture)
    else:
        frames = test_master_frames(args.eni, args.cycles)
    if args.line_frames:
        frames += line_frames(args.eni, frames[-1][0] + 1_000_000, args.line_frames)
    results = {engine: run(engine, args.eni, frames) for engine in ("python", "c")}
    same = results["python"]["replies_blake2b"] == results["c"]["replies_blake2b"]
    source = args.capture.name if args.capture else "tests/emulator/bus.py master"
    print(
        f"{len(frames)} frames of {source}, ENI {args.eni.name}; same replies: {same}; "
        f"load average {os.getloadavg()[0]:.2f} (2 cores)"
    )
    head = f"{'command':>18} {'n':>6} | {'python µs p50/p99/max':>24} | "
    print(head + f"{'c µs p50/p99/max':>22} | py/c")
    py, c = results["python"]["by_command"], results["c"]["by_command"]
    assert isinstance(py, dict) and isinstance(c, dict)
    for kind, a in py.items():
        b = c[kind]
        print(
            f"{kind:>18} {a['count']:6d} | {a['median']:7.1f} {a['p99']:7.1f} {a['max']:8.1f} | "
            f"{b['median']:6.1f} {b['p99']:6.1f} {b['max']:8.1f} | {a['median'] / b['median']:4.1f}"
        )
    for engine in ("python", "c"):
        s = results[engine]["after_answer_us"]
        assert isinstance(s, dict)
        print(f"after the answer ({engine}): p50 {s['median']} µs, p99 {s['p99']}, max {s['max']}")
    if args.json:
        print(json.dumps(results, indent=2))
    if not same:
        raise SystemExit("the engines' replies differ")


if __name__ == "__main__":
    main()
