"""CPU time of the emulated chain per cyclic frame, in process (no sockets).

Brings the chain of an ENI (default: the embedded LOLA chain) to OP through its own
InitCmds, then runs the ENI's cyclic frame N times through ``Chain.process`` (answer) and
``Chain.run_deferred_cycles`` (device updates), the two halves ``bus emulate`` runs per
frame, and prints µs per frame for each and the share of the real-time budget and of the
frame's wire time (DESIGN.md frame bytes at 100 Mbit/s).

    python benchmarks/emulate_chain_cpu.py                          # LOLA, 20 000 frames
    python benchmarks/emulate_chain_cpu.py --eni lolacli/eni_examples/single_drive.xml
"""

from __future__ import annotations

import argparse
import gc
import json
import struct
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lolacli.emulator.slave import build_chain  # noqa: E402
from lolacli.files import load_eni  # noqa: E402
from lolacli.timing.model import frame_bytes, wire_time_ns  # noqa: E402
from lolacli.wire.frame import Datagram, encode_frame, make_frame  # noqa: E402
from tests.emulator.bus import Bus  # noqa: E402

DEFAULT_ENI = ROOT / "lolacli" / "eni_examples" / "lola.xml"


def cyclic_frame(eni, outputs: bytes) -> bytes:  # type: ignore[no-untyped-def]
    datagrams = []
    for c in eni.cyclic_frames[0].commands:
        if c.logical_address is not None:
            data = outputs[: c.data_length_bytes].ljust(c.data_length_bytes, b"\0")
            datagrams.append(Datagram.logical(c.cmd, c.logical_address, data))
        else:
            datagrams.append(Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes))
    return encode_frame(make_frame(datagrams), pad=True)


def images(eni, size: int, still: bool) -> list[bytes]:  # type: ignore[no-untyped-def]
    """Output images: every drive enabled in CSP (controlword 0x0F, mode 8), its target
    moving every cycle (a different one in each of 64 frames) unless ``still``."""

    def offsets(suffix: str) -> list[int]:
        return [
            v.bit_offset // 8
            for v in eni.process_image.variables
            if v.direction.value == "output" and v.name.endswith(suffix)
        ]

    out = []
    for k in range(1 if still else 64):
        image = bytearray(size)
        for at in offsets(".Controlword"):
            struct.pack_into("<H", image, at, 0x0F)
        for at in offsets(".Modes of operation"):
            image[at] = 8
        for j, at in enumerate(offsets(".Target position")):
            struct.pack_into("<i", image, at, 1000 * j + 37 * k)
        out.append(bytes(image))
    return out


def pct(values: list[int], q: float) -> int:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eni", type=Path, default=DEFAULT_ENI)
    parser.add_argument("--frames", type=int, default=20_000)
    parser.add_argument("--rate", type=float, default=2000.0, help="cycles per second (budget)")
    parser.add_argument(
        "--still", action="store_true", help="drives enabled but standing (same outputs)"
    )
    args = parser.parse_args()
    eni = load_eni(args.eni)
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.bring_up(eni)
    lengths = [c.data_length_bytes for c in eni.cyclic_frames[0].commands]
    frames = [cyclic_frame(eni, image) for image in images(eni, lengths[0], args.still)]
    gc.collect()
    gc.freeze()  # as the raw-socket server does
    period_ns = int(1e9 / args.rate)
    t_ns = bus.t_ns
    answer_ns = cycles_ns = 0
    worst_ns = 0
    per_frame: list[int] = []
    for i in range(args.frames):
        t_ns += period_ns
        t0 = time.perf_counter_ns()
        reply, _ = chain.process(frames[i % len(frames)], t_ns, defer_cycles=True)
        t1 = time.perf_counter_ns()
        chain.run_deferred_cycles()
        t2 = time.perf_counter_ns()
        assert reply is not None
        answer_ns += t1 - t0
        per_frame.append(t1 - t0)
        cycles_ns += t2 - t1
        worst_ns = max(worst_ns, t2 - t0)
    n = args.frames
    wire = wire_time_ns(frame_bytes(lengths))
    total = (answer_ns + cycles_ns) / n
    print(
        json.dumps(
            {
                "eni": args.eni.name,
                "slaves": len(chain.slaves),
                "frames": n,
                "process_us_per_frame": round(answer_ns / n / 1000, 1),
                "process_us_p50_p99": [round(pct(per_frame, q) / 1000, 1) for q in (0.5, 0.99)],
                "device_cycles_us_per_frame": round(cycles_ns / n / 1000, 1),
                "total_us_per_frame": round(total / 1000, 1),
                "worst_total_us": round(worst_ns / 1000, 1),
                "wire_time_us": wire / 1000,
                "process_over_wire_time": round(answer_ns / n / wire, 2),
                "total_over_budget": round(total / period_ns, 3),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
