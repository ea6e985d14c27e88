"""Reply latency of `lolacli bus emulate` per command type, for real masters over veth.

For each master (SOEM through pysoem, KickCAT) and each load (other core idle, a CPU hog
pinned to core 1): a veth pair, `lolacli bus emulate` on one end, `dumpcap` on the
master's end, and the master in its own process: its whole start-up (INIT -> OP) then
N cycles at 1 kHz with its default timeouts (pysoem ``receive_processdata(2000)``;
KickCAT's 2 ms link timeout, 500 µs in the cyclic loop as its examples set it). The
capture is then analysed with lolacli's own capture library: ``analyze_file`` for the
totals (pairs, lost frames, round trip), and the reader + wire decoder for the reply
latency per command type (an echo is the next frame with the same command/index/length
sequence: KickCAT's own MAC has the locally administered bit set, so the MAC cannot tell).
The table shows p50/p99/max against the 2 ms budget real masters wait per frame (SOEM's
EC_TIMEOUTRET, KickCAT's link timeout) and the target p99 <= 150 µs, max <= 1 ms. After
each run, the baseline: the host's own wake-up latency measured cyclictest's way (a
SCHED_FIFO 10 process sleeping to a deadline every 1 ms, same load), and the ratio of the
emulator's worst reply to the host's worst wake-up. Per command type, the same frames on a
100 Mbit line (lolacli's timing model, each frame after those sent just before it, as a
real port sends them): "line p99", and the p99 of the emulator's reply minus the line's,
"over line". First of all (``--no-first-frames`` to skip), a probe of a session's first
frames against the emulator and against a plain echo server on the same kind of veth pair;
each master's table is followed by its session's first replies. A command type a start-up
sends fewer than 100 times (BWR, BRD) has its p99 at its maximum, which is then the
session's first frame: the table says so where such a type misses.
With ``--witness`` (root, tracefs and a C compiler), ``vcpu_witness.py`` traces during each
master's run when the VM's CPUs were not run at all, and each reply later than 1 ms is
printed with the stretch of a vCPU not run that covers it, if one does (the host's, which
no emulator can answer through). The witness costs each CPU about 4% and wakes every
500 µs above the emulator, which shows in the start-up's p99 (KickCAT's FPRD 47-49 ->
160-172 µs here): a run to attribute the maxima, not one for the table.

    sudo python benchmarks/emulate_latency.py                      # LOLA, both masters
    sudo python benchmarks/emulate_latency.py --masters pysoem --cycles 2000 --loads idle
    sudo python benchmarks/emulate_latency.py --eni lolacli/eni_examples/single_drive.xml
    sudo python benchmarks/emulate_latency.py --emulate-arg=--let-cpus-sleep  # no PM QoS hold

Needs root (veth, raw sockets), dumpcap, pysoem and/or kickcat. The masters run at
``--master-nice`` (default 0: normal; SOEM polls its socket without sleeping, and above
the kernel's softirq thread it holds back the very packets it waits for), on core
``--master-cpu`` (default 0, as a real-time master is deployed and as the tests run
them; -1 leaves it free; the emulator follows it there, ``bus emulate --cpu follow``). The
machine's load during the run is printed with the table: figures on a shared host are
upper bounds.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from vcpu_witness import VcpuWitness, available  # noqa: E402

DEFAULT_ENI = ROOT / "lolacli" / "eni_examples" / "lola.xml"
BUDGET_US = 2000.0  # SOEM EC_TIMEOUTRET, KickCAT default link timeout
TARGET_P99_US = 150.0
TARGET_MAX_US = 1000.0


# ---------------------------------------------------------------- the masters
def run_pysoem(iface: str, cycles: int) -> dict[str, object]:
    import pysoem

    master = pysoem.Master()
    master.open(iface)
    t0 = time.perf_counter()
    try:
        slaves = master.config_init()
        image = master.config_map()
        master.config_dc()
        if master.state_check(pysoem.SAFEOP_STATE, 5_000_000) != pysoem.SAFEOP_STATE:
            return {"error": "SAFEOP not reached"}
        master.send_processdata()
        master.receive_processdata(2000)
        master.state = pysoem.OP_STATE
        master.write_state()
        for _ in range(1000):
            master.send_processdata()
            master.receive_processdata(2000)
            if master.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
                break
        else:
            return {"error": "OP not reached"}
        startup_s = time.perf_counter() - t0
        bad = 0
        next_t = time.perf_counter()
        for _ in range(cycles):
            master.send_processdata()
            if master.receive_processdata(2000) != master.expected_wkc:
                bad += 1
            next_t += 0.001
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        master.state = pysoem.INIT_STATE
        master.write_state()
        return {"slaves": slaves, "image_bytes": image, "startup_s": startup_s, "errors": bad}
    finally:
        master.close()


KICKCAT_STARTS = 3


def run_kickcat(iface: str, cycles: int) -> dict[str, object]:
    """KickCAT's start-up (tried again when it raises: its 2 ms link timeout meets this
    VM's occasional 4-5 ms stalls, and its own 20 µs sleep-poll overruns; the capture has
    the failed tries' frames too) and ``cycles`` cycles with its examples' 500 µs."""
    import kickcat

    failed: list[str] = []
    for _ in range(KICKCAT_STARTS):
        link = kickcat.create_link(iface, "")  # default link timeout: 2 ms
        bus = kickcat.Bus(link)
        t0 = time.perf_counter()
        try:
            bus.init(0.1)
            slaves = bus.slaves()
            bus.create_mapping()
            bus.request_state(kickcat.State.SAFE_OP)
            bus.wait_for_state(kickcat.State.SAFE_OP, 5.0)
            for s in slaves:
                s.set_output_bytes(bytes(s.output_size))
            bus.process_data_no_check()
            bus.request_state(kickcat.State.OPERATIONAL)
            bus.wait_for_state(kickcat.State.OPERATIONAL, 5.0, bus.process_data_no_check)
        except RuntimeError as exc:
            failed.append(str(exc))
            continue
        break
    else:
        return {"error": f"start-up: {failed}", "failed_startups": failed}
    startup_s = time.perf_counter() - t0
    link.set_timeout(0.0005)  # as KickCAT's examples in their cyclic loops
    errors = 0
    next_t = time.perf_counter()
    for _ in range(cycles):
        try:
            bus.process_data()
        except RuntimeError:
            errors += 1
        next_t += 0.001
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return {
        "slaves": len(slaves),
        "startup_s": startup_s,
        "errors": errors,
        "failed_startups": failed,
    }


FIRST_REPLIES = 3  # the session's first replies, printed with each table
MASTERS = {"pysoem": run_pysoem, "kickcat": run_kickcat}


# ------------------------------------------------------------- the capture
def per_command_latency(
    path: Path,
    slaves: int = 0,
    late: list[tuple[str, int, int]] | None = None,
    firsts: list[tuple[str, int]] | None = None,
) -> tuple[dict[str, list[int]], int, dict[str, list[int]]]:
    """Reply latency (ns) per command type from a master-side capture; unanswered count;
    and per command type, what a 100 Mbit line of ``slaves`` slaves would take for the
    same frames sent at the same times: lolacli's timing model of the round trip (the
    frame's wire time, 1 µs per slave, the cables) after the frames the master sent just
    before it, which a real port sends one after the other (a start-up sends bursts).

    A frame is the echo of the pending one with the same command/index/length sequence
    when the source MAC's locally administered bit differs (DESIGN.md "Direction") or,
    where the master's own MAC has that bit set (KickCAT), when a working counter or an
    ADP changed on the way; otherwise it is the master sending the frame again.
    ``late`` gets (command type, request time in ns of the capture's clock, latency ns) of
    every reply later than :data:`TARGET_MAX_US`; ``firsts`` (command type, latency ns) of
    the session's first :data:`FIRST_REPLIES` replies."""
    from lolacli.capture.reader import iter_frames
    from lolacli.emulator.chain import ChainTiming
    from lolacli.errors import WireError
    from lolacli.timing.model import frame_bytes
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import decode_frame

    timing = ChainTiming()
    pending: dict[tuple[tuple[int, int, int], ...], tuple[int, str, bytes, tuple[int, ...]]] = {}
    out: dict[str, list[int]] = defaultdict(list)
    line: dict[str, list[int]] = defaultdict(list)
    sent: dict[tuple[tuple[int, int, int], ...], int] = {}  # the line's latency of each
    free_ns = 0  # when the master's port has sent what it was sending
    unanswered = 0
    for frame in iter_frames(path):
        try:
            decoded = decode_frame(frame.data)
        except WireError:
            continue
        datagrams = decoded.datagrams
        key = tuple((d.cmd, d.index, len(d.data)) for d in datagrams)
        fields = tuple(v for d in datagrams for v in (d.wkc, d.adp))
        first = pending.get(key)
        if first is not None:
            bit_differs = (frame.data[6] ^ first[2][6]) & 0x02
            if bit_differs or fields != first[3]:
                del pending[key]
                out[first[1]].append(frame.timestamp_ns - first[0])
                if firsts is not None and len(firsts) < FIRST_REPLIES:
                    firsts.append((first[1], frame.timestamp_ns - first[0]))
                if late is not None and frame.timestamp_ns - first[0] > TARGET_MAX_US * 1000:
                    late.append((first[1], first[0], frame.timestamp_ns - first[0]))
                line[first[1]].append(sent.pop(key))
                continue
            unanswered += 1  # sent again: the first copy had no answer
        names = sorted({_mnemonic(Command, d.cmd) for d in datagrams})
        pending[key] = (frame.timestamp_ns, "+".join(names), frame.data[:12], fields)
        lengths = [len(d.data) for d in datagrams]
        start = max(frame.timestamp_ns, free_ns)  # a frame waits for the one before it
        free_ns = start + timing.wire_time_ns(frame_bytes(lengths))
        sent[key] = start - frame.timestamp_ns + timing.round_trip_ns(lengths, slaves)
    unanswered += len(pending)
    return out, unanswered, line


def _mnemonic(command: type, cmd: int) -> str:
    try:
        return str(command(cmd).name)
    except ValueError:
        return f"0x{cmd:02X}"


def _pct(values: list[int], p: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(p * len(ordered)))] / 1000


# ------------------------------------------------------------------ the run
def steal_ms() -> float | None:
    """CPU time the hypervisor took from this VM's CPUs so far (the ``steal`` column of
    /proc/stat, all CPUs, in ms), or None where the kernel does not count it. A stall
    the emulator cannot help shows up here."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()
        return int(fields[8]) * 1000 / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True)


def one_run(args: argparse.Namespace, master: str, hog: bool, folder: Path) -> dict[str, object]:
    tag = f"{os.getpid() % 10000:04d}"
    m_if, e_if = f"{args.prefix}m{tag}", f"{args.prefix}e{tag}"
    _ip("link", "add", m_if, "type", "veth", "peer", "name", e_if)
    procs: list[subprocess.Popen[bytes]] = []
    try:
        for name in (m_if, e_if):
            subprocess.run(["sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"], check=False)
            _ip("link", "set", name, "up")
        pcap = folder / f"{master}-{'hog' if hog else 'idle'}.pcapng"
        emu_log = folder / f"{master}-{'hog' if hog else 'idle'}.emulate.txt"
        emulator = subprocess.Popen(
            [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", e_if,
             "--eni", str(args.eni), "--quiet", *args.emulate_arg],
            cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        procs.append(emulator)
        assert emulator.stderr is not None
        ready = emulator.stderr.readline()  # "emulating N slaves …": the socket is open
        if "emulating" not in ready:
            raise SystemExit(f"emulator did not start: {ready}{emulator.stderr.read()}")
        if hog:
            procs.append(_hog())
        dumpcap = subprocess.Popen(
            ["dumpcap", "-q", "-i", m_if, "-w", str(pcap)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        procs.append(dumpcap)
        time.sleep(1.0)  # dumpcap capturing
        cmd = [sys.executable, __file__, "--run-master", master, "--iface", m_if,
               "--cycles", str(args.cycles)]  # fmt: skip
        if args.master_nice:
            cmd = ["nice", "-n", str(args.master_nice), *cmd]
        if args.master_cpu >= 0 and shutil.which("taskset"):
            cmd = ["taskset", "-c", str(args.master_cpu), *cmd]
        stolen = steal_ms()
        realtime_minus_mono = time.time_ns() - time.monotonic_ns()  # the capture's clock
        with _witness(args) as witness:
            done = subprocess.run(
                cmd, capture_output=True, text=True, timeout=args.cycles / 100 + 300
            )
        stolen_after = steal_ms()
        lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
        result: dict[str, object] = (
            json.loads(lines[-1]) if lines else {"error": (done.stderr or done.stdout)[-300:]}
        )
        time.sleep(0.3)
    finally:
        for proc in reversed(procs):
            proc.terminate()
            proc.wait(timeout=20)
        if procs and procs[0].stderr is not None:
            emu_log.write_text(procs[0].stderr.read())
        subprocess.run(["ip", "link", "del", m_if], capture_output=True, check=False)
    from lolacli.capture import analyze_file
    from lolacli.files import load_eni

    report = analyze_file(pcap).to_dict()
    slaves = len(load_eni(args.eni).slaves)
    late: list[tuple[str, int, int]] = []
    firsts: list[tuple[str, int]] = []
    latency, unanswered, line = per_command_latency(pcap, slaves, late, firsts)
    result.update(witness_report(witness, late, realtime_minus_mono))
    result.update(
        master=master,
        hog=hog,
        capture=str(pcap),
        steal_ms=None if stolen is None or stolen_after is None else stolen_after - stolen,
        emulator="; ".join(
            " ".join(line.split()).partition(": ")[2] if line.startswith("reply time:") else line
            for line in emu_log.read_text().splitlines()
            if line.startswith(("reply time:", "placement:"))
        ),
        pairs=report["pairs"],
        lost_frames=report["lost_frames"],
        direction_rule=report.get("direction_rule", "mac"),
        round_trip_us=report["round_trip_us"],
        unanswered=unanswered,
        first_replies=[{"command": kind, "us": ns / 1000} for kind, ns in firsts],
        by_command={
            kind: {
                "count": len(v),
                "p50_us": _pct(v, 0.5),
                "p99_us": _pct(v, 0.99),
                "max_us": max(v) / 1000,
                "line_p99_us": _pct(line[kind], 0.99),
                "over_line_p99_us": _pct([a - b for a, b in zip(v, line[kind], strict=True)], 0.99),
            }
            for kind, v in sorted(latency.items(), key=lambda kv: -len(kv[1]))
        },
    )
    return result


@contextmanager
def _witness(args: argparse.Namespace) -> Iterator[VcpuWitness | None]:
    """The vCPU witness around a master's run (None: off or not possible here)."""
    if not args.witness or available() is not None:
        yield None
        return
    with VcpuWitness() as witness:
        yield witness


def witness_report(
    witness: VcpuWitness | None, late: list[tuple[str, int, int]], realtime_minus_mono: int
) -> dict[str, object]:
    """What the witness saw during the run, and each reply later than 1 ms with the vCPU
    stall that covers it (or none)."""
    if witness is None:
        why = available() or "off (--witness traces when the VM's CPUs were not run)"
        return {"witness": f"vCPU witness: {why}", "late": []}
    trace = witness.trace
    rows = []
    for kind, t_ns, latency_ns in late:
        start = t_ns - realtime_minus_mono
        stall = trace.explain(start, start + latency_ns)
        rows.append(
            {
                "command": kind,
                "latency_us": latency_ns / 1000,
                "stall": None
                if stall is None
                else {"cpu": stall.cpu, "us": stall.us, "running": stall.running,
                      "host": stall.host},
            }
        )  # fmt: skip
    return {"witness": trace.summary(), "late": rows}


def _hog() -> subprocess.Popen[bytes]:
    """A CPU hog on core 1 (a plain busy loop)."""
    cmd = [sys.executable, "-c", "while 1: pass"]
    if shutil.which("taskset"):
        cmd = ["taskset", "-c", "1", *cmd]
    return subprocess.Popen(cmd)


def host_baseline(seconds: float, hog: bool) -> dict[str, float]:
    """The host's own wake-up latency, cyclictest's way: a process at the emulator's
    scheduling (SCHED_FIFO 10 where permitted) sleeps to a deadline every 1 ms and
    records how late it wakes. Nothing can answer a frame faster than this host wakes
    the process that answers it, so the emulator's maxima are read against these."""
    code = (
        "import os, time, json\n"
        "try: os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))\n"
        "except OSError: pass\n"
        "late = []\n"
        "t = time.monotonic_ns()\n"
        f"end = t + {int(seconds * 1e9)}\n"
        "while t < end:\n"
        "    t += 1_000_000\n"
        "    time.sleep(max(0, t - time.monotonic_ns()) / 1e9)\n"
        "    late.append(time.monotonic_ns() - t)\n"
        "late.sort()\n"
        "print(json.dumps({'n': len(late), 'p50_us': late[len(late) // 2] / 1e3,\n"
        "    'p99_us': late[int(len(late) * 0.99)] / 1e3, 'max_us': late[-1] / 1e3}))\n"
    )
    procs = [_hog()] if hog else []
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    finally:
        for proc in procs:
            proc.terminate()
            proc.wait()
    return json.loads(done.stdout) if done.returncode == 0 else {}


def print_table(result: dict[str, object]) -> None:
    load = "CPU hog on core 1" if result["hog"] else "other core idle"
    failed = result.get("failed_startups") or []
    tries = f" (after {len(failed)} failed: {'; '.join(failed)})" if failed else ""
    print(f"\n== {result['master']}, {load}: start-up {result.get('startup_s', 0):.2f} s{tries}, "
          f"master errors {result.get('errors', result.get('error'))}, "
          f"unanswered {result['unanswered']}, capture analyze: {result['pairs']} pairs, "
          f"{result['lost_frames']} lost ({result['direction_rule']} direction)")  # fmt: skip
    print(
        f"{'command':>14} {'n':>7} {'p50 µs':>8} {'p99 µs':>8} {'max µs':>9} "
        f"{'p99/budget':>10} {'line p99':>9} {'over line':>9}  "
        f"target (p99 ≤ {TARGET_P99_US:.0f}, max ≤ {TARGET_MAX_US:.0f})"
    )
    by_command = result["by_command"]
    assert isinstance(by_command, dict)
    for kind, s in by_command.items():
        ok = s["p99_us"] <= TARGET_P99_US and s["max_us"] <= TARGET_MAX_US
        print(
            f"{kind:>14} {s['count']:7d} {s['p50_us']:8.1f} {s['p99_us']:8.1f} "
            f"{s['max_us']:9.1f} {s['p99_us'] / BUDGET_US:10.3f} {s['line_p99_us']:9.1f} "
            f"{s['over_line_p99_us']:9.1f}  {'ok' if ok else 'MISSED'}"
            f"{'' if ok or s['count'] >= 100 else ' (n < 100: its p99 is its maximum)'}"
        )
    firsts = result.get("first_replies") or []
    assert isinstance(firsts, list)
    if firsts:
        print("the session's first replies: " + ", ".join(
            f"{r['command']} {r['us']:.0f} µs" for r in firsts
        ) + " (the host's own first-frame cost: the probe of first frames above)")  # fmt: skip
    print(f"emulator's own reply time: {result['emulator']}")
    print(result["witness"])
    late = result.get("late") or []
    assert isinstance(late, list)
    if late:
        host = sum(1 for r in late if r["stall"] is not None and r["stall"]["host"])
        print(f"replies over {TARGET_MAX_US / 1000:g} ms: {len(late)}; covered by a stretch in "
              f"which a vCPU was not run: {host}")  # fmt: skip
        for r in late[:10]:
            st = r["stall"]
            why = (
                "no vCPU stall covers it"
                if st is None
                else f"cpu {st['cpu']} {'not run' if st['host'] else 'in a kernel thread'} "
                f"for {st['us']:.0f} µs ({st['running']} on it)"
            )
            print(f"  {r['command']} {r['latency_us']:.0f} µs: {why}")
    if result.get("steal_ms") is not None:
        print(f"time the hypervisor took from this VM's CPUs during the master's run "
              f"(steal, /proc/stat): {result['steal_ms']:.0f} ms")  # fmt: skip
    base = result.get("host_baseline")
    if isinstance(base, dict) and base:
        worst = max(s["max_us"] for s in by_command.values())
        print(
            f"host baseline (a SCHED_FIFO 10 sleeper woken every 1 ms for "
            f"{base['n'] / 1000:.0f} s, same load): late p50 {base['p50_us']:.0f} µs, "
            f"p99 {base['p99_us']:.0f} µs, max {base['max_us']:.0f} µs; the emulator's "
            f"worst reply / the host's worst wake-up = {worst / base['max_us']:.2f}"
        )


# A plain raw-socket echo server at the emulator's scheduling (SCHED_FIFO 10, CPU wake-up
# latency held at 0 where permitted): what answering a frame costs this host at the least.
ECHO_SERVER = """
import os, select, socket, struct, sys
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
except OSError:
    pass
try:
    fd = os.open("/dev/cpu_dma_latency", os.O_WRONLY)
    os.write(fd, struct.pack("=i", 0))
except OSError:
    pass
s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x88A4))
s.bind((sys.argv[1], 0))
p = select.poll()
p.register(s, select.POLLIN)
print("emulating: a plain echo server", file=sys.stderr, flush=True)
while True:
    p.poll(100)
    try:
        data, addr = s.recvfrom(2000, socket.MSG_DONTWAIT)
    except BlockingIOError:
        continue
    if addr[2] != 4:
        b = bytearray(data)
        b[6] |= 2
        s.send(b)
"""


def probe(iface: str, rounds: int = 3, idle_s: float = 1.0, frames: int = 10) -> list[list[float]]:
    """Round trips (µs, this process's clock) of ``frames`` BRDs sent one after the other,
    each on the answer to the one before, after ``idle_s`` of silence; ``rounds`` times."""
    import socket

    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    raw = bytearray(encode_frame(make_frame([Datagram.physical(Command.BRD, 0, 0, 2)]), pad=True))
    raw[0:6], raw[6:12] = b"\xff" * 6, b"\x00\x01\x01\x01\x01\x01"
    frame = bytes(raw)
    sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x88A4))
    sock.bind((iface, 0))
    sock.settimeout(0.5)
    out = []
    try:
        for _ in range(rounds):
            time.sleep(idle_s)
            times = []
            for _ in range(frames):
                t = time.perf_counter_ns()
                sock.send(frame)
                while True:
                    data, address = sock.recvfrom(2000)
                    if address[2] != 4 and data[6] & 0x02:
                        break
                times.append((time.perf_counter_ns() - t) / 1000)
            out.append(times)
    finally:
        sock.close()
    return out


def first_frames(args: argparse.Namespace) -> dict[str, list[list[float]]]:
    """The probe against a plain echo server and against ``lolacli bus emulate``, each on
    a fresh veth pair: a session's first frame after an idle second costs this host
    ~250 µs however little the answer takes; the emulator is read against that."""
    out = {}
    for name in ("echo", "emulate"):
        m_if, e_if = f"{args.prefix}fm", f"{args.prefix}fe"
        _ip("link", "add", m_if, "type", "veth", "peer", "name", e_if)
        server = None
        try:
            for iface in (m_if, e_if):
                subprocess.run(
                    ["sysctl", "-qw", f"net.ipv6.conf.{iface}.disable_ipv6=1"], check=False
                )
                _ip("link", "set", iface, "up")
            cmd = (
                [sys.executable, "-c", ECHO_SERVER, e_if]
                if name == "echo"
                else [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", e_if,
                      "--eni", str(args.eni), "--quiet", *args.emulate_arg]
            )  # fmt: skip
            server = subprocess.Popen(
                cmd, cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True
            )
            assert server.stderr is not None
            ready = server.stderr.readline()
            if "emulating" not in ready:
                raise SystemExit(f"{name} did not start: {ready}")
            out[name] = probe(m_if)
        finally:
            if server is not None:
                server.terminate()
                server.wait(timeout=20)
            subprocess.run(["ip", "link", "del", m_if], capture_output=True, check=False)
    return out


def print_first_frames(result: dict[str, list[list[float]]]) -> None:
    print("\n== a session's first frames (BRD, one on the answer to the other, after 1 s idle)")
    for name, rounds in result.items():
        label = "plain echo server" if name == "echo" else "lolacli bus emulate"
        firsts = ", ".join(f"{r[0]:.0f}" for r in rounds)
        rest = sorted(t for r in rounds for t in r[1:])
        print(f"{label:>20}: first frame {firsts} µs; the next {len(rest)}: "
              f"p50 {rest[len(rest) // 2]:.0f} µs, max {rest[-1]:.0f} µs")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--eni", type=Path, default=DEFAULT_ENI)
    parser.add_argument("--cycles", type=int, default=10_000)
    parser.add_argument("--masters", default="pysoem,kickcat")
    parser.add_argument("--loads", default="idle,hog", help="idle, hog or both")
    parser.add_argument("--master-nice", type=int, default=0)
    parser.add_argument(
        "--master-cpu",
        type=int,
        default=0,
        help="the core the master runs on, as the tests' masters (-1: free on every core)",
    )
    parser.add_argument("--prefix", default="lbl", help="veth name prefix")
    parser.add_argument("--keep", type=Path, help="keep the captures in this folder")
    parser.add_argument(
        "--baseline-s", type=float, default=10.0,
        help="seconds of the host's own wake-up latency measured after each run (0: none)",
    )  # fmt: skip
    parser.add_argument(
        "--emulate-arg", action="append", default=[],
        help="an extra argument for `lolacli bus emulate` (repeatable), e.g. --let-cpus-sleep",
    )  # fmt: skip
    parser.add_argument(
        "--first-frames", action=argparse.BooleanOptionalAction, default=True,
        help="first the probe of a session's first frames, emulator and plain echo server",
    )  # fmt: skip
    parser.add_argument(
        "--witness", action=argparse.BooleanOptionalAction, default=False,
        help="trace when the VM's CPUs were not run during each master's run "
        "(benchmarks/vcpu_witness.py; costs each CPU ~4%%)",
    )  # fmt: skip
    parser.add_argument("--json", action="store_true", help="also print the results as JSON")
    parser.add_argument("--run-master", choices=sorted(MASTERS), help=argparse.SUPPRESS)
    parser.add_argument("--iface", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.run_master:
        print(json.dumps(MASTERS[args.run_master](args.iface, args.cycles)))
        return
    if os.geteuid() != 0:
        raise SystemExit("needs root (veth pair, raw sockets)")
    if shutil.which("dumpcap") is None:
        raise SystemExit("needs dumpcap (Debian package wireshark-common / tshark)")
    folder = args.keep or Path(tempfile.mkdtemp(prefix="emulate_latency_"))
    folder.mkdir(parents=True, exist_ok=True)
    results = []
    if args.first_frames:
        print_first_frames(first_frames(args))
    for master in args.masters.split(","):
        for load in args.loads.split(","):
            results.append(one_run(args, master, load == "hog", folder))
            if args.baseline_s > 0:
                results[-1]["host_baseline"] = host_baseline(args.baseline_s, load == "hog")
            print_table(results[-1])
    print(f"\nENI {args.eni.name}, {args.cycles} cycles at 1 kHz after start-up; "
          f"load average during the run: {os.getloadavg()[0]:.2f} (2 cores); "
          f"captures in {folder}")  # fmt: skip
    if args.json:
        print(json.dumps(results, indent=2))
    if args.keep is None:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
