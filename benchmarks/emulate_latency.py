"""Reply latency of `lolacli bus emulate` under a real master (SOEM via pysoem) over veth.

Creates a veth pair, serves the chain (default: the embedded LOLA chain) on one end, drives
it to OP with pysoem on the other, then runs N process-data cycles at the given rate and
reports the round trip send_processdata -> receive_processdata: p50/p99/max, lost cycles
(timeout or WKC mismatch) and cycles over the real-time budget (the cycle period). With
``--moving`` every drive is enabled in CSP and gets a new target every cycle, so every
device model steps every cycle (the default leaves the outputs at zero: drives at rest).

Needs root. Both processes are pinned to the same core with taskset by default, the worst
case for a host that runs master and emulator together. ``--emulator-priority N`` runs the
emulator SCHED_FIFO (chrt -f N), as the stand-in for slave hardware that does not wait for
the master's process to yield the core.

    sudo python benchmarks/emulate_latency.py                     # LOLA, 2 kHz, 20 000 cycles
    sudo python benchmarks/emulate_latency.py --eni lolacli/eni_examples/single_drive.xml \
        --rate 1000 --cycles 10000 --core -1                      # no pinning
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_ENI = ROOT / "lolacli" / "eni_examples" / "lola.xml"


def veth(tag: str) -> tuple[str, str]:
    master, emulator = f"lbm{tag}", f"lbe{tag}"
    subprocess.run(["ip", "link", "add", master, "type", "veth", "peer", "name", emulator],
                   check=True)
    for name in (master, emulator):
        subprocess.run(["sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"], check=False)
        subprocess.run(["ip", "link", "set", name, "up"], check=True)
    return master, emulator


def start_emulator(iface: str, eni: Path, core: int, priority: int = 0) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", iface,
           "--eni", str(eni), "--quiet"]
    if core >= 0:
        cmd = ["taskset", "-c", str(core), *cmd]
    if priority > 0:
        cmd = ["chrt", "-f", str(priority), *cmd]  # the emulator stands in for hardware
    proc = subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    line = proc.stderr.readline()
    if "emulating" not in line:
        raise SystemExit(f"emulator did not start: {line}{proc.stderr.read()}")
    time.sleep(0.3)
    return proc


def to_op(master, pysoem, timeout_us: int) -> None:
    if master.config_init() <= 0:
        raise SystemExit("no slaves found")
    master.config_map()
    master.config_dc()
    if master.state_check(pysoem.SAFEOP_STATE, 10_000_000) != pysoem.SAFEOP_STATE:
        raise SystemExit("SAFEOP not reached")
    master.state = pysoem.OP_STATE
    master.write_state()
    for _ in range(1000):
        master.send_processdata()
        master.receive_processdata(timeout_us)
        if master.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
            return
    raise SystemExit("OP not reached")


DRIVE_OUTPUT_BYTES = 11  # controlword, mode of operation, target position, target velocity
CSP = 8


def drives_of(master) -> list:
    """The CiA 402 drives, by the size of their outputs."""
    return [s for s in master.slaves if len(s.output) == DRIVE_OUTPUT_BYTES]


def enable(master, timeout_us: int) -> None:
    """Shutdown, switch on, enable operation in CSP on every drive (a few cycles each)."""
    for cw in (0x06, 0x07, 0x0F):
        for drive in drives_of(master):
            drive.output = struct.pack("<Hbi", cw, CSP, 0) + bytes(DRIVE_OUTPUT_BYTES - 7)
        for _ in range(20):
            master.send_processdata()
            master.receive_processdata(timeout_us)
            time.sleep(0.001)


def set_targets(drives: list, k: int) -> None:
    for j, drive in enumerate(drives):
        target = 1000 * j + 37 * k
        drive.output = struct.pack("<Hbi", 0x0F, CSP, target) + bytes(DRIVE_OUTPUT_BYTES - 7)


SLEEP_MARGIN_NS = 150_000  # a sleeping master wakes this long before its next cycle


def run(master, cycles: int, period_ns: int, timeout_us: int,
        moving: bool = False, sleeps: bool = False) -> dict[str, object]:
    latencies: list[int] = []
    lost = 0
    drives = drives_of(master) if moving else []
    next_t = time.perf_counter_ns()
    for k in range(cycles):
        if drives:
            set_targets(drives, k)  # every drive gets a new target every cycle
        t0 = time.perf_counter_ns()
        master.send_processdata()
        wkc = master.receive_processdata(timeout_us)
        t1 = time.perf_counter_ns()
        if wkc != master.expected_wkc:
            lost += 1
        else:
            latencies.append(t1 - t0)
        next_t += period_ns
        if sleeps and next_t - time.perf_counter_ns() > SLEEP_MARGIN_NS:
            time.sleep((next_t - time.perf_counter_ns() - SLEEP_MARGIN_NS) / 1e9)
        while time.perf_counter_ns() < next_t:
            pass  # busy-wait: sleep() granularity would dominate at 2 kHz
    latencies.sort()

    def pct(p: float) -> float:
        return latencies[min(len(latencies) - 1, int(p * len(latencies)))] / 1000

    return {
        "cycles": cycles,
        "lost_cycles": lost,
        "over_budget_cycles": sum(1 for x in latencies if x > period_ns),
        "budget_us": period_ns / 1000,
        "latency_us": {
            "p50": pct(0.50), "p90": pct(0.90), "p99": pct(0.99), "p99.9": pct(0.999),
            "max": latencies[-1] / 1000,
            "mean": statistics.fmean(latencies) / 1000,
        } if latencies else None,
        "expected_wkc": master.expected_wkc,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eni", type=Path, default=DEFAULT_ENI)
    parser.add_argument("--rate", type=float, default=2000.0, help="cycles per second")
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--core", type=int, default=0, help="CPU for both processes; -1: none")
    parser.add_argument("--timeout-us", type=int, default=5000,
                        help="receive timeout; later replies count as lost")
    parser.add_argument("--emulator-priority", type=int, default=0,
                        help="run the emulator SCHED_FIFO at this priority (chrt -f); 0: normal")
    parser.add_argument("--master-sleeps", action="store_true",
                        help="the master sleeps between cycles (busy-waits only the last "
                        "150 µs), as a real-time master does; default: busy-waits throughout")
    parser.add_argument("--moving", action="store_true",
                        help="enable every drive (CSP) and give each a new target every cycle")
    args = parser.parse_args()
    if os.geteuid() != 0:
        raise SystemExit("needs root (veth pair, raw sockets)")
    import pysoem

    if args.core >= 0:
        os.sched_setaffinity(0, {args.core})
    master_if, emulator_if = veth(f"{os.getpid() % 100000:05d}")
    proc = start_emulator(emulator_if, args.eni, args.core, args.emulator_priority)
    master = pysoem.Master()
    try:
        master.open(master_if)
        to_op(master, pysoem, args.timeout_us)
        if args.moving:
            enable(master, args.timeout_us)
        result = run(master, args.cycles, int(1e9 / args.rate), args.timeout_us, args.moving,
                     args.master_sleeps)
        result.update(eni=str(args.eni.name), slaves=len(master.slaves), rate_hz=args.rate,
                      pinned_core=args.core, emulator_priority=args.emulator_priority,
                      master_sleeps=args.master_sleeps,
                      drives_moving=len(drives_of(master))
                      if args.moving else 0)
        print(json.dumps(result, indent=2))
    finally:
        master.close()
        proc.send_signal(2)
        proc.wait(timeout=20)
        subprocess.run(["ip", "link", "del", master_if], check=False)


if __name__ == "__main__":
    main()
