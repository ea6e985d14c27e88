"""Virtual time against wall time for `bus simulate` (LOLA at 2 kHz by default).

Runs the master against the emulated chain for N cycles in four configurations and prints,
for each, µs of wall time per cycle, the part spent inside the emulated chain
(``Chain.process``, the bus itself) and the rest (the master: frame build, transport,
WKC check, Bus Variables copy, device abstractions, recording), and the ratio of
simulated time to wall time (the acceptance asks ≥ 20×, i.e. ≤ 25 µs per cycle, with
middleware and recording off):

    bare         frames only: process image copied, drives left disabled
    middleware   Bus Variables, CiA 402 state machines, joints moving
    pcap         middleware + every frame written to a pcapng
    master-only  bare, but against a loopback that answers each frame with the WKCs
                 the ENI expects (no chain): the master's own cost, the baseline

    python benchmarks/simulate_speed.py                  # 20 000 cycles
    python benchmarks/simulate_speed.py --cycles 5000 --eni lolacli/eni_examples/single_drive.xml
"""

from __future__ import annotations

import argparse
import gc
import json
import struct
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lolacli.files import load_eni  # noqa: E402
from lolacli.master import ChainTransport, Master, MasterOptions  # noqa: E402
from lolacli.master.simulate import SimulateOptions, simulate  # noqa: E402

DEFAULT_ENI = ROOT / "lolacli" / "eni_examples" / "lola.xml"


class Loopback:
    """Answers a frame at once: every datagram's WKC set to what the ENI expects."""

    def __init__(self, eni) -> None:  # type: ignore[no-untyped-def]
        self.expected = {
            (c.cmd, c.data_length_bytes): c.expected_wkc or 0
            for f in eni.cyclic_frames
            for c in f.commands
        }

    def process(self, frame: bytes, t_ns: int) -> tuple[bytes, int]:
        buf = bytearray(frame)
        buf[6] |= 0x02
        pos = 16
        while pos + 10 <= len(buf):
            cmd, length = buf[pos], struct.unpack_from("<H", buf, pos + 6)[0]
            n = length & 0x7FF
            struct.pack_into("<H", buf, pos + 10 + n, self.expected.get((cmd, n), 1))
            pos += 12 + n
            if not length & 0x8000:
                break
        return bytes(buf), 90_000


def master_only(eni, cycles: int) -> float:  # type: ignore[no-untyped-def]
    from lolacli.emulator.slave import build_chain

    chain = build_chain(eni)
    transport = ChainTransport(chain)
    master = Master(eni, transport, options=MasterOptions(dc_drift_frames=10))
    master.bring_up()
    transport.processor = Loopback(eni)
    gc.collect()
    t = time.perf_counter()
    master.run(cycles)
    return (time.perf_counter() - t) / cycles * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eni", type=Path, default=DEFAULT_ENI)
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--rate", type=float, default=2000.0)
    args = parser.parse_args()
    eni = load_eni(args.eni)
    budget_us = 1e6 / args.rate
    out: dict[str, object] = {"eni": args.eni.name, "cycles": args.cycles, "rate_hz": args.rate}
    with tempfile.TemporaryDirectory() as tmp:
        configs = {
            "bare": SimulateOptions(args.rate, args.cycles, middleware=False, time_sections=False),
            "middleware": SimulateOptions(args.rate, args.cycles, time_sections=False),
            "pcap": SimulateOptions(
                args.rate, args.cycles, pcap=Path(tmp) / "b.pcapng", time_sections=False
            ),
        }
        for name, options in configs.items():
            gc.collect()
            t0 = time.perf_counter()
            seen: list[object] = []
            import lolacli.master.transport as tr

            original = tr.ChainTransport.__init__

            def spy(self, *a, _orig=original, _seen=seen, **k):  # type: ignore[no-untyped-def]
                _orig(self, *a, **k)
                _seen.append(self)

            tr.ChainTransport.__init__ = spy  # type: ignore[method-assign]
            try:
                result = simulate(eni, options)
            finally:
                tr.ChainTransport.__init__ = original  # type: ignore[method-assign]
            wall = time.perf_counter() - t0
            doc = result.doc
            per_cycle = doc["wall_s"] / max(1, doc["cycles"]) * 1e6
            chain_us = seen[0].processing_ns / 1000 / max(1, doc["cycles"])  # type: ignore[attr-defined]
            out[name] = {
                "us_per_cycle": round(per_cycle, 1),
                "chain_us_per_cycle": round(chain_us, 1),
                "master_us_per_cycle": round(per_cycle - chain_us, 1),
                "realtime_factor": round(budget_us / per_cycle, 2),
                "total_wall_s": round(wall, 2),
            }
    alone = master_only(eni, args.cycles)
    out["master-only"] = {
        "us_per_cycle": round(alone, 1),
        "realtime_factor": round(budget_us / alone, 1),
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
