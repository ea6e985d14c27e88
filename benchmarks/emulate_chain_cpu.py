"""CPU time of the emulated chain per cyclic frame, in process (no sockets).

Brings the chain of an ENI (default: the embedded LOLA chain) to OP through its own
InitCmds, enables every CiA 402 drive (shutdown, switch on, enable operation) and then
runs the ENI's cyclic frame N times through ``Chain.process`` (the answer) and
``Chain.run_deferred_cycles`` (device cycles, DC loops, the writes a plan defers): the two
halves ``bus emulate`` runs per frame and ``bus simulate`` per cycle. The drives follow a
target that moves every cycle (CSP), unless ``--still``.

Both engines run in the same process on the same frames, one after the other: ``python``
(the reference code, the path without the C core) and ``c`` (lolacli/emulator/_ccore.c);
their replies are compared frame by frame. Printed per engine: µs per frame (median, p99,
mean) of each half and of both, and the ratios: C against Python, each against the cycle
period (``--rate``) and against the per-cycle budget of a simulation at
``--realtime-factor`` times real time (``bus simulate``: 20× at 2 kHz is 25 µs per cycle
for chain and master together).

    python benchmarks/emulate_chain_cpu.py                          # LOLA, 20 000 frames
    python benchmarks/emulate_chain_cpu.py --eni lolacli/eni_examples/single_drive.xml
"""

from __future__ import annotations

import argparse
import gc
import hashlib
import json
import struct
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lolacli.emulator.core import core_available  # noqa: E402
from lolacli.emulator.slave import build_chain  # noqa: E402
from lolacli.files import load_eni  # noqa: E402
from lolacli.timing.model import frame_bytes, wire_time_ns  # noqa: E402
from lolacli.wire.frame import Datagram, encode_frame, make_frame  # noqa: E402
from tests.emulator.bus import Bus  # noqa: E402

DEFAULT_ENI = ROOT / "lolacli" / "eni_examples" / "lola.xml"
ENABLE = (0x06, 0x07, 0x0F)  # shutdown, switch on, enable operation (CiA 402-2 Table 4)


def cyclic_frame(eni, outputs: bytes) -> bytes:  # type: ignore[no-untyped-def]
    datagrams = []
    for c in eni.cyclic_frames[0].commands:
        if c.logical_address is not None:
            data = outputs[: c.data_length_bytes].ljust(c.data_length_bytes, b"\0")
            datagrams.append(Datagram.logical(c.cmd, c.logical_address, data))
        else:
            datagrams.append(Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes))
    return encode_frame(make_frame(datagrams), pad=True)


def image(eni, size: int, controlword: int, k: int) -> bytes:  # type: ignore[no-untyped-def]
    """Output image: every drive's controlword, mode 8 (CSP) and a target that moves
    with ``k`` (a different one for each drive)."""

    def offsets(suffix: str) -> list[int]:
        return [
            v.bit_offset // 8
            for v in eni.process_image.variables
            if v.direction.value == "output" and v.name.endswith(suffix)
        ]

    out = bytearray(size)
    for at in offsets(".Controlword"):
        struct.pack_into("<H", out, at, controlword)
    for at in offsets(".Modes of operation"):
        out[at] = 8
    for j, at in enumerate(offsets(".Target position")):
        struct.pack_into("<i", out, at, 1000 * j + 37 * k)
    return bytes(out)


def stats(values: list[int]) -> dict[str, float]:
    ordered = sorted(values)
    n = len(ordered)
    return {
        "median": round(ordered[n // 2] / 1000, 2),
        "p99": round(ordered[min(n - 1, int(0.99 * n))] / 1000, 2),
        "mean": round(sum(ordered) / n / 1000, 2),
    }


def run(eni, engine: str, frames: int, period_ns: int, still: bool) -> dict[str, Any]:  # type: ignore[no-untyped-def]
    chain = build_chain(eni, engine=engine)
    bus = Bus(chain)
    bus.bring_up(eni)
    size = eni.cyclic_frames[0].commands[0].data_length_bytes
    for cw in ENABLE:
        bus.cycle(eni, image(eni, size, cw, 0))
    cyclic = [cyclic_frame(eni, image(eni, size, 0x0F, k)) for k in range(1 if still else 64)]
    gc.collect()
    gc.freeze()  # as the raw-socket server does
    t_ns = bus.t_ns
    answer: list[int] = []
    cycles: list[int] = []
    total: list[int] = []
    digest = hashlib.blake2b(digest_size=16)
    for i in range(frames):
        t_ns += period_ns
        t0 = time.perf_counter_ns()
        reply, _ = chain.process(cyclic[i % len(cyclic)], t_ns, defer_cycles=True)
        t1 = time.perf_counter_ns()
        chain.run_deferred_cycles()
        t2 = time.perf_counter_ns()
        assert reply is not None
        digest.update(reply)
        answer.append(t1 - t0)
        cycles.append(t2 - t1)
        total.append(t2 - t0)
    gc.unfreeze()
    return {
        "process_us": stats(answer),
        "deferred_cycles_us": stats(cycles),
        "total_us": stats(total),
        "planned_frames": chain.stats.planned_frames,
        "replies_blake2b": digest.hexdigest(),
        "slaves": len(chain.slaves),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eni", type=Path, default=DEFAULT_ENI)
    parser.add_argument("--frames", type=int, default=20_000)
    parser.add_argument("--rate", type=float, default=2000.0, help="cycles per second")
    parser.add_argument(
        "--realtime-factor", type=float, default=20.0, help="simulation speed the budget is for"
    )
    parser.add_argument("--still", action="store_true", help="drives enabled but standing")
    args = parser.parse_args()
    eni = load_eni(args.eni)
    period_ns = int(1e9 / args.rate)
    budget_ns = period_ns / args.realtime_factor
    engines = ["python", "c"] if core_available() else ["python"]
    results = {engine: run(eni, engine, args.frames, period_ns, args.still) for engine in engines}
    lengths = [c.data_length_bytes for c in eni.cyclic_frames[0].commands]
    report: dict[str, Any] = {
        "eni": args.eni.name,
        "slaves": results["python"]["slaves"],
        "frames": args.frames,
        "wire_time_us": wire_time_ns(frame_bytes(lengths)) / 1000,
        "period_us": period_ns / 1000,
        "simulate_budget_us": round(budget_ns / 1000, 2),
        "engines": results,
    }
    for result in results.values():
        median_ns = result["total_us"]["median"] * 1000
        result["total_over_period"] = round(median_ns / period_ns, 4)
        result["total_over_simulate_budget"] = round(median_ns / budget_ns, 3)
    if "c" in results:
        c, py = results["c"], results["python"]
        report["same_replies"] = c["replies_blake2b"] == py["replies_blake2b"]
        report["python_over_c"] = {
            part: round(py[part]["median"] / c[part]["median"], 1)
            for part in ("process_us", "deferred_cycles_us", "total_us")
        }
    else:
        report["c"] = "not built (python3 setup.py build_ext --inplace)"
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
