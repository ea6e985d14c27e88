"""Virtual time against wall time for `bus simulate` (LOLA at 2 kHz by default).

Runs the master against the emulated chain for N cycles (10 s at 2 kHz by default: the
command's defaults) in these configurations and prints, for each, µs of wall time per
cycle of the cyclic run, the part spent inside the emulated chain (the bus itself) and
the rest (the master), and the ratio of simulated time to wall time:

    frames-only  no middleware: the process image copied, drives left disabled
    defaults     what `bus simulate` runs: Bus Variables, CiA 402 state machines, joints
                 moving, per-cycle sections timed (the acceptance asks >= 20x)
    pcap         the defaults + every frame written to a pcapng (>= 10x)
    master-only  frames-only against a loopback that answers each frame with the WKCs the
                 ENI expects (no chain): the master's own cost
    engines      the defaults with the chain's C core and with its Python reference
                 (``c_over_python``: what the C twin is worth on this figure)
    cli          ``lolacli bus simulate`` in a new process, as a user runs it: the factor
                 it prints, and over the whole process's wall time (start-up included);
                 also with ``--move all:20000`` (a move on every joint), with and without
                 ``--joint-model``

The real-time factor is the report's (simulated time over the wall time of bring-up, run
and report, as ``bus simulate`` prints it), and the same over CPU time. Since the host is
shared, each configuration runs ``--repeat`` times, interleaved, the best run counts, and
the figures that compare are the ratios to frames-only from the same run
(``vs_frames_only``).

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
from lolacli.master import Master, MasterOptions  # noqa: E402
from lolacli.simulate import SimulateOptions, Simulation, VirtualBus  # noqa: E402

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
    bus = VirtualBus(eni)
    master = Master(eni, bus.transport, options=MasterOptions(dc_drift_frames=10))
    master.bring_up()
    bus.transport.processor = Loopback(eni)
    gc.collect()
    t = time.perf_counter()
    master.run(cycles)
    return (time.perf_counter() - t) / cycles * 1e6


def run(eni, options: SimulateOptions) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """One simulation: µs per cycle of its cyclic run (the bring-up left out), in the chain
    and in the rest, and the real-time factors: as the report gives it (simulated time
    over the wall time of bring-up, run and report) and the same over the process's CPU
    time (what the other sessions on a shared host do not change)."""
    gc.collect()
    simulation = Simulation(eni, options)
    transport = simulation.bus.transport
    marks: list[tuple[float, int]] = []
    simulation_progress = lambda done, total: marks.append(  # noqa: E731
        (time.perf_counter(), transport.processing_ns)
    )
    t0, c0 = time.perf_counter(), time.process_time()
    doc = simulation.run(progress=simulation_progress).doc
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    cycles = max(1, doc["cycles"])
    # the cyclic run from the first progress report on (the bring-up is before it)
    (first_t, first_busy), (last_t, last_busy) = marks[0], marks[-1]
    step = max(1, min(256, round(options.rate_hz / 20)))
    per_cycle = (last_t - first_t) / max(1, cycles - step) * 1e6
    chain_us = (last_busy - first_busy) / 1000 / max(1, cycles - step)
    return {
        "us_per_cycle": round(per_cycle, 1),
        "chain_us_per_cycle": round(chain_us, 1),
        "master_us_per_cycle": round(per_cycle - chain_us, 1),
        "realtime_factor": doc["realtime_factor"],
        "cpu_realtime_factor": round(doc["simulated_s"] / cpu, 2),
        "total_wall_s": round(wall, 2),
    }


def best(runs: list[dict[str, float]]) -> dict[str, float]:
    """The run with the highest real-time factor (the one the host disturbed least)."""
    return max(runs, key=lambda r: r["realtime_factor"])


def engines(eni, args: argparse.Namespace) -> dict[str, object]:  # type: ignore[no-untyped-def]
    """The defaults on the chain's C core against its Python reference (the twin that
    must earn its place: at least 2x on this figure), ``--engine-cycles`` cycles each,
    interleaved, the best of ``--repeat``."""
    import os

    runs: dict[str, list[dict[str, float]]] = {"c": [], "python": []}
    before = os.environ.get("LOLACLI_CHAIN_ENGINE")
    try:
        for _ in range(args.repeat):
            for engine in runs:
                os.environ["LOLACLI_CHAIN_ENGINE"] = engine
                runs[engine].append(run(eni, SimulateOptions(args.rate, args.engine_cycles)))
    finally:
        if before is None:
            os.environ.pop("LOLACLI_CHAIN_ENGINE", None)
        else:
            os.environ["LOLACLI_CHAIN_ENGINE"] = before
    c, python = best(runs["c"]), best(runs["python"])
    return {
        "cycles": args.engine_cycles,
        "c": c,
        "python": python,
        "c_over_python": round(c["realtime_factor"] / python["realtime_factor"], 2),
        "c_over_python_cpu": round(c["cpu_realtime_factor"] / python["cpu_realtime_factor"], 2),
    }


def cli(args: argparse.Namespace, *extra: str) -> dict[str, float]:
    """``lolacli bus simulate`` as a user runs it (a new process, the defaults but for
    ``--eni``/``--rate``/``--cycles`` and ``extra``): the factor it prints, and simulated
    time over the whole process's wall time (interpreter start-up and imports too); best
    of ``--repeat``. Bytecode is cached, as an installed package has it (this
    environment may set PYTHONDONTWRITEBYTECODE: every run would compile every module)."""
    import os
    import subprocess

    command = [sys.executable, "-m", "lolacli", "bus", "simulate", "--eni", str(args.eni),
               "--rate", str(args.rate), "--cycles", str(args.cycles), "--quiet",
               "--format", "json", *extra]
    env = dict(os.environ, PYTHONPYCACHEPREFIX=os.path.join(tempfile.gettempdir(),
                                                             "lolacli-bench-pycache"))
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    subprocess.run(command, capture_output=True, cwd=ROOT, env=env)  # (compiles once)
    runs = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, check=True,
                              env=env)
        wall = time.perf_counter() - t0
        doc = json.loads(done.stdout)
        runs.append({"realtime_factor": doc["realtime_factor"],
                     "process_wall_s": round(wall, 3),
                     "end_to_end_factor": round(doc["simulated_s"] / wall, 2)})
    return best(runs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eni", type=Path, default=DEFAULT_ENI)
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--rate", type=float, default=2000.0)
    parser.add_argument("--repeat", type=int, default=3, help="runs of each; the best counts")
    parser.add_argument("--engine-cycles", type=int, default=2000)
    args = parser.parse_args()
    eni = load_eni(args.eni)
    budget_us = 1e6 / args.rate
    out: dict[str, object] = {"eni": args.eni.name, "cycles": args.cycles, "rate_hz": args.rate}
    with tempfile.TemporaryDirectory() as tmp:
        configs = {
            "frames-only": SimulateOptions(
                args.rate, args.cycles, middleware=False, time_sections=False
            ),
            "defaults": SimulateOptions(args.rate, args.cycles),
            "pcap": SimulateOptions(args.rate, args.cycles, pcap=Path(tmp) / "b.pcapng"),
        }
        runs: dict[str, list[dict[str, float]]] = {name: [] for name in configs}
        for _ in range(args.repeat):  # interleaved: a busy spell of the host hits all alike
            for name, options in configs.items():
                runs[name].append(run(eni, options))
        for name in configs:
            out[name] = best(runs[name])
    out["cli"] = cli(args)
    # issue 26: a move on every joint, with the kinematic drives and with the joint model
    out["cli moves"] = cli(args, "--move", "all:20000")
    out["cli moves joint-model"] = cli(args, "--move", "all:20000", "--joint-model")
    out["engines"] = engines(eni, args)
    alone = master_only(eni, args.cycles)
    out["master-only"] = {
        "us_per_cycle": round(alone, 1),
        "realtime_factor": round(budget_us / alone, 1),
    }
    out["vs_frames_only"] = {
        f"{name} {figure}": round(
            out[name][figure] / out["frames-only"][figure],  # type: ignore[index]
            3,
        )
        for name in ("defaults", "pcap")
        for figure in ("realtime_factor", "cpu_realtime_factor")
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
