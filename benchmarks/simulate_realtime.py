"""`lolacli bus simulate --iface`: our master in real time against `bus emulate` over veth.

Creates a veth pair, serves the LOLA chain on one end (`bus emulate`, its own process, with its own
scheduling: SCHED_FIFO 10 as root, the stand-in for slave hardware; ``--emulator-priority
N`` sets another, 0 normal scheduling), then
runs `bus simulate --iface` on the other for ``--cycles`` cycles at ``--rate`` in two
set-ups, in the same run:

* baseline: the master as a plain process (SCHED_OTHER, no busy-wait: a sleep to the
  cycle start);
* real time: SCHED_FIFO ``--priority`` and ``--busy-wait-us`` of busy-waiting at the end of
  every cycle;

and prints for each the cycle period (mean, std, max), the wake-up lateness, the round
trip, lost / late / never-returned frames, overruns and skipped cycles, the scheduling the
OS granted, the host's load and the CPU the master and the emulator used; then the ratio
baseline / real time of the period's std and of the p99 wake-up lateness. ``--hog N``
starts N busy Python processes (``while 1: pass``) for the whole run.

Needs root.

    python benchmarks/simulate_realtime.py                         # 20 000 cycles at 2 kHz
    python benchmarks/simulate_realtime.py --hog 1 --cycles 20000
    python benchmarks/simulate_realtime.py --cycles 4000 --json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOLA = ROOT / "lolacli" / "eni_examples" / "lola.xml"


def veth(prefix: str) -> tuple[str, str]:
    tag = f"{os.getpid() % 10000:04d}"
    master, emulator = f"{prefix}m{tag}", f"{prefix}e{tag}"
    subprocess.run(
        ["ip", "link", "add", master, "type", "veth", "peer", "name", emulator], check=True
    )
    for name in (master, emulator):
        subprocess.run(["sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"], check=False)
        subprocess.run(["ip", "link", "set", name, "up"], check=True)
    return master, emulator


def cpu_ticks(pid: int) -> int:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])  # utime + stime


def start_emulator(iface: str, priority: int | None) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", iface, "--quiet"]
    if priority is not None:
        cmd += ["--realtime-priority", str(priority)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stderr=subprocess.PIPE, text=True)
    assert proc.stderr is not None
    line = proc.stderr.readline()
    if "emulating" not in line:
        raise SystemExit(f"emulator did not start: {line}{proc.stderr.read()}")
    time.sleep(0.3)
    return proc


def run_master(iface: str, args: argparse.Namespace, *, realtime: bool) -> dict:
    cmd = [
        sys.executable, "-m", "lolacli", "bus", "simulate", "--iface", iface,
        "--rate", str(args.rate), "--cycles", str(args.cycles), "--format", "json",
        "--max-lost", str(10**9), "--max-wkc-mismatches", str(10**9),
        "--realtime-priority", str(args.priority if realtime else 0),
        "--busy-wait-us", str(args.busy_wait_us if realtime else 0),
    ]  # fmt: skip
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=3600)
    if done.returncode not in (0, 1):
        raise SystemExit(f"bus simulate failed ({done.returncode}): {done.stderr}")
    doc: dict = json.loads(done.stdout)
    return doc


def scenario(name: str, iface: str, emu: subprocess.Popen[str], args, realtime: bool) -> dict:
    hz = os.sysconf("SC_CLK_TCK")
    e0, t0 = cpu_ticks(emu.pid), time.monotonic()
    doc = run_master(iface, args, realtime=realtime)
    e1, t1 = cpu_ticks(emu.pid), time.monotonic()
    period, wake, rt = doc["cycle_period_us"], doc["wakeup_lateness_us"], doc["round_trip_us"]
    out = {
        "scenario": name,
        "cycles": doc["cycles"],
        "period_mean_us": period["mean"],
        "period_std_us": period["std"],
        "period_min_us": period["min"],
        "period_max_us": period["max"],
        "period_p99_us": period["p99"],
        "wakeup_lateness_p99_us": wake["p99"],
        "wakeup_lateness_max_us": wake["max"],
        "send_offset_median_us": doc["send_offset_us"]["median"],
        "round_trip_median_us": rt["median"] if rt else None,
        "round_trip_p99_us": rt["p99"] if rt else None,
        "lost_frames": doc["lost_frames"],
        "cyclic_lost_frames": doc["cyclic_lost_frames"],
        "late_frames": doc["late_frames"],
        "never_returned_frames": doc["never_returned_frames"],
        "wkc_mismatches": doc["wkc_mismatches"],
        "overruns": doc["overruns"],
        "skipped_cycles": doc["skipped_cycles"],
        "scheduling": doc["scheduling"],
        "load_before": doc["load"]["before"],
        "load_after": doc["load"]["after"],
        "master_cpu_percent": doc["master_cpu_percent"],
        "emulator_cpu_percent_of_process_run": round(100 * (e1 - e0) / hz / (t1 - t0), 1),
    }
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--cycles", type=int, default=20_000)
    p.add_argument("--rate", type=float, default=2000.0)
    p.add_argument("--priority", type=int, default=80, help="master SCHED_FIFO priority")
    p.add_argument("--busy-wait-us", type=float, default=200.0)
    p.add_argument("--emulator-priority", type=int, default=None)
    p.add_argument("--hog", type=int, default=0, help="busy processes to start")
    p.add_argument("--prefix", default="lrt", help="veth name prefix")
    p.add_argument("--only-realtime", action="store_true")
    p.add_argument("--json", action="store_true")
    args = p.parse_args()
    if os.geteuid() != 0:
        raise SystemExit("needs root (veth pair, raw sockets)")
    master, emulator = veth(args.prefix)
    hogs = [subprocess.Popen([sys.executable, "-c", "while 1: pass"]) for _ in range(args.hog)]
    emu = None
    try:
        emu = start_emulator(emulator, args.emulator_priority)
        results = []
        if not args.only_realtime:
            results.append(scenario("baseline", master, emu, args, realtime=False))
        results.append(scenario("realtime", master, emu, args, realtime=True))
    finally:
        if emu is not None:
            emu.send_signal(2)
            emu.wait(timeout=20)
        for h in hogs:
            h.kill()
            h.wait()
        subprocess.run(["ip", "link", "del", master], check=False)
    report = {"hogs": args.hog, "emulator_priority": args.emulator_priority, "runs": results}
    if len(results) == 2:
        base, rt = results
        report["std_ratio_baseline_over_realtime"] = round(
            base["period_std_us"] / max(rt["period_std_us"], 1e-9), 2
        )
        report["wakeup_p99_ratio_baseline_over_realtime"] = round(
            base["wakeup_lateness_p99_us"] / max(rt["wakeup_lateness_p99_us"], 1e-3), 1
        )
    if args.json:
        print(json.dumps(report, indent=2))
        return
    emu_sched = {None: "bus emulate's default", 0: "off"}.get(args.emulator_priority)
    print(f"hogs: {args.hog}, emulator SCHED_FIFO {emu_sched or args.emulator_priority}")
    for r in results:
        s = r["scheduling"]
        print(
            f"{r['scenario']:9s} {r['cycles']} cycles: period mean {r['period_mean_us']} us "
            f"std {r['period_std_us']} p99 {r['period_p99_us']} max {r['period_max_us']}; "
            f"wake-up late p99 {r['wakeup_lateness_p99_us']} max {r['wakeup_lateness_max_us']}; "
            f"round trip median {r['round_trip_median_us']} p99 {r['round_trip_p99_us']}; "
            f"lost {r['lost_frames']} (cyclic {r['cyclic_lost_frames']}, late "
            f"{r['late_frames']}, never {r['never_returned_frames']}), overruns "
            f"{r['overruns']}, skipped {r['skipped_cycles']}; {s['policy']} {s['priority']} "
            f"busy-wait {s['busy_wait_us']} us; load {r['load_before']['loadavg_1min']}->"
            f"{r['load_after']['loadavg_1min']}; CPU master {r['master_cpu_percent']} % "
            f"emulator {r['emulator_cpu_percent_of_process_run']} %"
        )
    if "std_ratio_baseline_over_realtime" in report:
        print(
            f"ratio baseline/realtime: period std {report['std_ratio_baseline_over_realtime']}x, "
            f"wake-up p99 {report['wakeup_p99_ratio_baseline_over_realtime']}x"
        )


if __name__ == "__main__":
    main()
