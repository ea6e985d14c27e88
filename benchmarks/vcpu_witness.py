"""When this VM's CPUs were not run: stretches in which a vCPU did nothing the guest kernel
can see, measured while something else runs (``emulate_latency.py`` uses it per master run).

A witness thread per CPU (C, SCHED_FIFO 98, pinned) sleeps to an absolute deadline every
500 µs, so every CPU takes a timer interrupt at least that often, and the kernel's trace
(tracefs, an instance of its own, ``mono`` clock) records the interrupts, softirqs, IPIs
and task switches of each CPU. A CPU whose trace has no event at all for a stretch
while its witness timer was armed and an idle loop, the witness or a user task was on it
(a user task is preempted at the interrupt) did not run in the guest for that stretch:
the hypervisor was running something else. A kernel thread on the CPU (``kworker``,
``kdamond``...) may instead hold it in a long section the kernel does not preempt
(this kernel is PREEMPT_NONE); such stretches are told apart. A reply later than 1 ms
whose time on the wire is covered by such a stretch but for the time the reply itself
takes (``EXPLAINED_SLACK_NS``) is "explained by a vCPU stall".

    sudo python benchmarks/vcpu_witness.py                 # 60 s, nothing else running
    sudo python benchmarks/vcpu_witness.py --seconds 20 --min-us 500

Needs root, tracefs and a C compiler (``cc``); elsewhere :func:`available` says why not.
The witness costs each CPU 2,000 wake-ups a second, about 4% of it on this VM.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

TRACEFS = Path("/sys/kernel/tracing")
PERIOD_US = 500  # 200 µs costs ~10% of a CPU here (timer and halt exits); 500 µs ~4%
PRIORITY = 98
EXPLAINED_SLACK_NS = 500_000  # what a late reply's own work may take beyond the stall
EVENTS = (
    "sched/sched_switch",
    "sched/sched_waking",
    "irq_vectors/local_timer_entry",
    "irq_vectors/reschedule_entry",
    "irq_vectors/call_function_entry",
    "irq_vectors/call_function_single_entry",
    "irq/irq_handler_entry",
    "irq/softirq_entry",
)
KERNEL_THREAD = re.compile(
    r"^(kworker|kdamond|ksoftirqd|rcu|migration|kcompactd|khugepaged|kswapd|ksmd|"
    r"watchdog|cpuhp|irq/|kthreadd|oom_reaper|khungtaskd|kauditd|kblockd|writeback)"
)

WITNESS_C = r"""
#define _GNU_SOURCE
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>
static long period; static int prio; static volatile sig_atomic_t stop;
static void on_term(int s) { (void)s; stop = 1; }
static void *run(void *arg) {
    long cpu = (long)arg; cpu_set_t set; CPU_ZERO(&set); CPU_SET(cpu, &set);
    pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    struct sched_param p = { .sched_priority = prio };
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &p);
    struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t);
    while (!stop) {
        t.tv_nsec += period;
        while (t.tv_nsec >= 1000000000L) { t.tv_nsec -= 1000000000L; t.tv_sec++; }
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &t, 0);
    }
    return 0;
}
int main(int argc, char **argv) {
    period = atol(argv[1]) * 1000; prio = atoi(argv[2]);
    long n = sysconf(_SC_NPROCESSORS_ONLN); if (n > 64) n = 64;
    signal(SIGTERM, on_term); signal(SIGINT, on_term);
    mlockall(MCL_CURRENT | MCL_FUTURE);
    pthread_t th[64];
    for (long c = 0; c < n; c++) pthread_create(&th[c], 0, run, (void *)c);
    puts("ready"); fflush(stdout);
    for (long c = 0; c < n; c++) pthread_join(th[c], 0);
    return 0;
}
"""


@dataclass(frozen=True, slots=True)
class Stall:
    """``cpu`` had no trace event from ``start_ns`` to ``end_ns`` (CLOCK_MONOTONIC) while
    ``running`` was on it."""

    cpu: int
    start_ns: int
    end_ns: int
    running: str

    @property
    def us(self) -> float:
        return (self.end_ns - self.start_ns) / 1000

    @property
    def host(self) -> bool:
        """Whether the vCPU was not run (idle, the witness or a user task on it): the
        hypervisor's; else a kernel thread's section the kernel may not preempt."""
        return not KERNEL_THREAD.match(self.running)


@dataclass
class Trace:
    seconds: float = 0.0
    stalls: list[Stall] = field(default_factory=list)  # all of at least the asked length

    def host_stalls(self, min_us: float = 1000) -> list[Stall]:
        return [s for s in self.stalls if s.host and s.us >= min_us]

    def explain(self, start_ns: int, end_ns: int) -> Stall | None:
        """The longest stall on the CPU whose stalls cover most of ``[start_ns, end_ns]``
        (a late reply on the wire, CLOCK_MONOTONIC), when they cover all of it but for
        :data:`EXPLAINED_SLACK_NS` (a reply may wait for several); else None."""
        covered: dict[int, int] = {}
        longest: dict[int, tuple[int, Stall]] = {}
        for s in self.stalls:
            overlap = min(end_ns, s.end_ns) - max(start_ns, s.start_ns)
            if overlap <= 0:
                continue
            covered[s.cpu] = covered.get(s.cpu, 0) + overlap
            if s.cpu not in longest or overlap > longest[s.cpu][0]:
                longest[s.cpu] = (overlap, s)
        if not covered:
            return None
        cpu = max(covered, key=lambda c: covered[c])
        if covered[cpu] < (end_ns - start_ns) - EXPLAINED_SLACK_NS:
            return None
        return longest[cpu][1]

    def summary(self, min_us: float = 1000) -> str:
        host = self.host_stalls(min_us)
        kernel = [s for s in self.stalls if not s.host and s.us >= min_us]
        per_min = 60 * len(host) / self.seconds if self.seconds else 0.0
        longest = max((s.us for s in host), default=0.0)
        out = (
            f"vCPUs not run for {min_us / 1000:g} ms or more (no guest event while the "
            f"witness timer was armed): {len(host)} in {self.seconds:.0f} s "
            f"({per_min:.0f}/min), longest {longest / 1000:.1f} ms"
        )
        if kernel:
            names = sorted({s.running for s in kernel})
            out += f"; a kernel thread on the CPU ({', '.join(names)}): {len(kernel)}"
        return out


def available() -> str | None:
    """None when the witness can run here, else why not."""
    if os.geteuid() != 0:
        return "needs root"
    if shutil.which("cc") is None:
        return "needs a C compiler (cc)"
    if not (TRACEFS / "instances").is_dir():
        subprocess.run(["mount", "-t", "tracefs", "nodev", str(TRACEFS)], capture_output=True)
        if not (TRACEFS / "instances").is_dir():
            return f"needs tracefs at {TRACEFS}"
    return None


_LINE = re.compile(rb"\[(\d+)\]\s+\S+\s+(\d+)\.(\d+): (\w+):(.*)")
_NEXT = re.compile(rb"next_comm=(.*?) next_pid=")


class VcpuWitness:
    """``with VcpuWitness() as w: ...``; then ``w.trace`` (a :class:`Trace`)."""

    def __init__(self, min_us: float = 700, period_us: int = PERIOD_US) -> None:
        self.min_ns = int(min_us * 1000)
        self.period_us = period_us
        self.trace = Trace()
        self._dir = Path(tempfile.mkdtemp(prefix="vcpu_witness_"))
        self._instance = TRACEFS / "instances" / f"lolacli_witness_{os.getpid()}"
        self._proc: subprocess.Popen[str] | None = None
        self._t0 = 0.0

    def __enter__(self) -> VcpuWitness:
        why = available()
        if why:
            raise RuntimeError(why)
        binary = self._dir / "witness"
        source = self._dir / "witness.c"
        source.write_text(WITNESS_C)
        subprocess.run(["cc", "-O2", "-o", str(binary), str(source), "-lpthread"], check=True)
        if self._instance.exists():
            self._instance.rmdir()
        self._instance.mkdir()
        (self._instance / "trace_clock").write_text("mono")
        (self._instance / "buffer_size_kb").write_text("65536")
        for event in EVENTS:
            (self._instance / "events" / event / "enable").write_text("1")
        (self._instance / "tracing_on").write_text("1")
        self._proc = subprocess.Popen(
            [str(binary), str(self.period_us), str(PRIORITY)], stdout=subprocess.PIPE, text=True
        )
        assert self._proc.stdout is not None
        self._proc.stdout.readline()  # "ready"
        self._t0 = time.monotonic()
        return self

    def __exit__(self, *exc: object) -> None:
        self.trace.seconds = time.monotonic() - self._t0
        if self._proc is not None:
            self._proc.terminate()
            self._proc.wait(timeout=10)
        try:
            (self._instance / "tracing_on").write_text("0")
            raw = (self._instance / "trace").read_bytes()
            self.trace.stalls = self._stalls(raw)
        finally:
            self._instance.rmdir()
            shutil.rmtree(self._dir, ignore_errors=True)

    def _stalls(self, raw: bytes) -> list[Stall]:
        last: dict[int, int] = {}
        running: dict[int, str] = {}
        stalls: list[Stall] = []
        for line in raw.splitlines():
            m = _LINE.search(line)
            if m is None:
                continue
            cpu = int(m.group(1))
            t = int(m.group(2)) * 1_000_000_000 + int(m.group(3).ljust(9, b"0")[:9])
            before = last.get(cpu)
            if before is not None and t - before >= self.min_ns:
                stalls.append(Stall(cpu, before, t, running.get(cpu, "?")))
            last[cpu] = t
            if m.group(4) == b"sched_switch":
                n = _NEXT.search(m.group(5))
                if n is not None:
                    running[cpu] = n.group(1).decode(errors="replace")
        stalls.sort(key=lambda s: s.start_ns)
        return stalls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--min-us", type=float, default=1000.0)
    args = parser.parse_args()
    why = available()
    if why:
        raise SystemExit(f"vcpu_witness: {why}")
    with VcpuWitness(min_us=min(700.0, args.min_us)) as witness:
        time.sleep(args.seconds)
    trace = witness.trace
    print(trace.summary(args.min_us))
    for s in trace.stalls:
        if s.us >= args.min_us:
            kind = "not run" if s.host else "kernel thread"
            print(f"  cpu {s.cpu} at {s.start_ns / 1e9:.6f}: {s.us:7.0f} µs ({kind}: {s.running})")


if __name__ == "__main__":
    sys.exit(main())
