"""SDO read latency: in process, and `lolacli sdo read` as a whole process.

1. In process (no sockets), expedited uploads of 0x1000, measured in alternating batches
   so that a load change on the shared machine hits all alike:

   * ``ethercat``: ``lolacli.sdo.read`` through lolacli's own master against the embedded
     LOLA chain emulated in this process (slave 5, brought to PREOP once), the default
     transport of ``lolacli sdo``. The emulated chain's share (the time inside its
     ``process``, the bus itself) is reported apart;
   * ``can``: ``lolacli.sdo.read`` over ``CanopenClient`` from a canopen LocalNode (the
     gateway's IMU node, ``lolacli.sdo.node``) over python-can's ``virtual`` bus;
   * baselines in the same run: canopen's own ``RemoteNode.sdo.upload`` on the same bus
     (what canopen costs without lolacli on top) and a bare python-can request/answer
     round trip through the same notifier threads (an echo, no SDO).

2. Whole process, wall time (median, commands interleaved): ``lolacli sdo read 5 0x1000``
   on the default transport against ``python -c pass`` and ``lolacli --version`` (the
   interpreter's and the CLI's own start-up). Python's bytecode cache is written for the
   worktree first and used (the default; this sandbox sets PYTHONDONTWRITEBYTECODE, which
   the benchmark lifts for its processes). With root, also the CANopen read over
   ``udp_multicast`` in a private network namespace. ``--callgrind`` adds instruction
   counts of the same commands (valgrind): independent of the machine's load.

    python benchmarks/sdo_read.py                 # 5000 reads, 20 processes
    python benchmarks/sdo_read.py --reads 20000 --processes 0 --json
    python benchmarks/sdo_read.py --reads 2000 --processes 10 --callgrind
    python benchmarks/sdo_read.py --processes 20 --fifo   # processes ahead of other load
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lolacli.sdo import read  # noqa: E402
from lolacli.sdo.canopen_client import UDP_MULTICAST_IPV4, CanopenNetwork  # noqa: E402
from lolacli.sdo.node import IMU_NODE, NodeServer, gateway_nodes  # noqa: E402
from lolacli.sdo.session import LolaSession, TransportOptions, open_session  # noqa: E402


def _interleaved_us(
    fns: dict[str, Any], n: int, rounds: int = 10
) -> dict[str, tuple[float, float]]:
    """Median and p99 per function, measured in alternating batches so that a load change
    on the shared machine hits all of them alike."""
    samples: dict[str, list[int]] = {name: [] for name in fns}
    for fn in fns.values():
        for _ in range(min(200, n)):
            fn()
    for _ in range(rounds):
        for name, fn in fns.items():
            for _ in range(max(1, n // rounds)):
                t = time.perf_counter_ns()
                fn()
                samples[name].append(time.perf_counter_ns() - t)
    out = {}
    for name, times in samples.items():
        times.sort()
        out[name] = (times[len(times) // 2] / 1000, times[int(len(times) * 0.99)] / 1000)
    return out


def in_process(n: int) -> dict[str, float]:
    import can

    session = open_session(TransportOptions())
    assert isinstance(session, LolaSession)
    drive = session.target("5").client
    transport = session.bus.transport
    chain_ns: list[int] = []  # per read: inside the emulated chain
    own_ns: list[int] = []  # per read: the rest (master, SDO, types)
    clock = time.perf_counter_ns

    def ethercat() -> None:
        busy = transport.processing_ns  # type: ignore[attr-defined]
        t0 = clock()
        read(drive, 0x1000, 0)
        total = clock() - t0
        chain = transport.processing_ns - busy  # type: ignore[attr-defined]
        chain_ns.append(chain)
        own_ns.append(total - chain)

    # an echo on the same kind of bus, through the same notifier threads, without SDO
    server_bus = can.Bus(interface="virtual", channel="bench-sdo")
    answer = can.Message(arbitration_id=0x7E8, data=bytes(8), is_extended_id=False)
    got = threading.Event()

    def echo(msg: can.Message) -> None:
        if msg.arbitration_id == 0x7E0:
            server_bus.send(answer)

    def back(msg: can.Message) -> None:
        if msg.arbitration_id == 0x7E8:
            got.set()

    request = can.Message(arbitration_id=0x7E0, data=bytes(8), is_extended_id=False)
    echo_notifier = can.Notifier(server_bus, [echo], 0.02)
    with NodeServer("bench-sdo", gateway_nodes(), interface="virtual"):
        with CanopenNetwork("bench-sdo", interface="virtual", timeout_s=1.0) as net:
            client = net.client(IMU_NODE)
            net.network.notifier.add_listener(back)

            def round_trip() -> None:
                got.clear()
                net.bus.send(request)
                got.wait(1.0)

            r = _interleaved_us(
                {
                    "ethercat": ethercat,
                    "can": lambda: read(client, 0x1000, 0),
                    "canopen": lambda: client.node.sdo.upload(0x1000, 0),
                    "echo": round_trip,
                },
                n,
            )
    echo_notifier.stop()
    server_bus.shutdown()
    session.close()
    return {
        "ethercat_median_us": r["ethercat"][0],
        "ethercat_p99_us": r["ethercat"][1],
        "ethercat_chain_median_us": statistics.median(chain_ns) / 1000,
        "ethercat_master_median_us": statistics.median(own_ns) / 1000,
        "can_median_us": r["can"][0],
        "can_p99_us": r["can"][1],
        "canopen_median_us": r["canopen"][0],
        "python_can_echo_median_us": r["echo"][0],
    }


def _environment() -> dict[str, str]:
    """Python's default: bytecode cached (this sandbox turns that off for everything)."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


#: run the timed processes under SCHED_FIFO (``--fifo``): ahead of the other users of a
#: shared machine, as on an idle one
FIFO: list[str] = []


def _wall_ms(cmds: dict[str, list[str]], n: int) -> dict[str, float]:
    """Median wall time of each command, run in turn n times (interleaved)."""
    env = _environment()
    times: dict[str, list[float]] = {name: [] for name in cmds}
    for cmd in cmds.values():  # bytecode written, ENI cache filled
        subprocess.run(cmd, cwd=ROOT, capture_output=True, check=True, env=env)
    for _ in range(n):
        for name, cmd in cmds.items():
            t = time.perf_counter()
            subprocess.run(FIFO + cmd, cwd=ROOT, capture_output=True, check=True, env=env)
            times[name].append(time.perf_counter() - t)
    return {name: statistics.median(t) * 1000 for name, t in times.items()}


PROCESSES = {
    "python_pass_ms": ["-c", "pass"],
    "lolacli_version_ms": ["-m", "lolacli", "--version"],
    "sdo_read_ms": ["-m", "lolacli", "sdo", "read", "5", "0x1000"],
}


def whole_process(n: int) -> dict[str, float]:
    return _wall_ms({k: [sys.executable, *v] for k, v in PROCESSES.items()}, n)


def instructions() -> dict[str, float] | None:
    """Instructions (millions) each command runs, from valgrind's callgrind."""
    if shutil.which("valgrind") is None:
        print("instruction counts skipped: no valgrind", file=sys.stderr)
        return None
    out = {}
    env = _environment()
    for name, args in PROCESSES.items():
        done = subprocess.run(
            ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null"]
            + [sys.executable, *args],
            cwd=ROOT,
            capture_output=True,
            text=True,
            env=env,
        )
        found = re.search(r"Collected : (\d+)", done.stderr)
        out[name.replace("_ms", "_minstr")] = int(found.group(1)) / 1e6 if found else float("nan")
    return out


def can_process(n: int) -> dict[str, float] | None:
    from tests.sdo.multicast import namespace

    try:
        ctx = namespace()
        ns = ctx.__enter__()
    except BaseException as exc:  # pytest.skip outside pytest: not root
        print(f"CANopen whole-process timing skipped: {exc}", file=sys.stderr)
        return None
    server = None
    try:
        inside = ["ip", "netns", "exec", ns, sys.executable]
        can_args = ["--can", UDP_MULTICAST_IPV4, "--interface", "udp_multicast"]
        server = subprocess.Popen(
            [*inside, "-m", "lolacli", "sdo", "serve", *can_args, "--gateway"],
            cwd=ROOT,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert server.stderr is not None
        server.stderr.readline()
        cmd = [*inside, "-m", "lolacli", "sdo", "read", "16", "0x1000", *can_args]
        return _wall_ms({"can_sdo_read_ms": cmd}, n)
    finally:
        if server is not None:
            server.send_signal(2)
            server.wait(20)
        ctx.__exit__(None, None, None)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reads", type=int, default=5000)
    parser.add_argument("--processes", type=int, default=20)
    parser.add_argument("--callgrind", action="store_true", help="instruction counts too")
    parser.add_argument(
        "--fifo", action="store_true", help="time the processes under SCHED_FIFO (root)"
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.fifo:
        FIFO[:] = ["chrt", "-f", "50"]
    load = os.getloadavg()
    result: dict[str, object] = {"load_average": load, "in_process": in_process(args.reads)}
    if args.processes:
        result["whole_process"] = whole_process(args.processes)
        result["can_process"] = can_process(args.processes)
    if args.callgrind:
        result["instructions"] = instructions()
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    _print(result, args)
    return 0


def _print(result: dict[str, Any], args: argparse.Namespace) -> None:
    r = result["in_process"]
    print(f"load average {' '.join(f'{x:.1f}' for x in result['load_average'])} (2 cores)")
    print(f"in process, {args.reads} expedited reads of 0x1000 each:")
    print(
        f"  EtherCAT, our master, emulated LOLA chain  median {r['ethercat_median_us']:7.1f} us"
        f"  p99 {r['ethercat_p99_us']:.1f} us"
    )
    print(
        f"    of a read: inside the emulated chain {r['ethercat_chain_median_us']:.1f} us, "
        f"master + SDO + types {r['ethercat_master_median_us']:.1f} us (medians)"
    )
    print(
        f"  CANopen, lolacli.sdo.read, virtual bus     median {r['can_median_us']:7.1f} us"
        f"  p99 {r['can_p99_us']:.1f} us"
    )
    print(f"  canopen sdo.upload (baseline)             median {r['canopen_median_us']:7.1f} us")
    print(
        f"  python-can echo (floor of the CAN bus)    median "
        f"{r['python_can_echo_median_us']:7.1f} us"
    )
    base = r["canopen_median_us"]
    print(
        f"  EtherCAT / canopen = {r['ethercat_median_us'] / base:.2f}; "
        f"our master's part / canopen = {r['ethercat_master_median_us'] / base:.2f}"
    )
    w = result.get("whole_process")
    if isinstance(w, dict):
        how = "SCHED_FIFO, " if args.fifo else ""
        print(f"whole process, median of {args.processes} ({how}bytecode cached):")
        print(f"  python -c pass                      {w['python_pass_ms']:6.0f} ms")
        print(f"  lolacli --version                   {w['lolacli_version_ms']:6.0f} ms")
        print(
            f"  lolacli sdo read 5 0x1000           {w['sdo_read_ms']:6.0f} ms  "
            f"(/ --version = {w['sdo_read_ms'] / w['lolacli_version_ms']:.2f}, "
            f"- --version = {w['sdo_read_ms'] - w['lolacli_version_ms']:.0f} ms)"
        )
    c = result.get("can_process")
    if isinstance(c, dict):
        print(f"  lolacli sdo read 16 0x1000 --can …  {c['can_sdo_read_ms']:6.0f} ms")
    i = result.get("instructions")
    if isinstance(i, dict):
        print("instructions (callgrind, millions):")
        for name, value in i.items():
            print(f"  {name:24s} {value:8.1f}")
        print(
            f"  sdo read / --version = "
            f"{i['sdo_read_minstr'] / i['lolacli_version_minstr']:.2f}, "
            f"/ python -c pass = {i['sdo_read_minstr'] / i['python_pass_minstr']:.2f}"
        )


if __name__ == "__main__":
    sys.exit(main())
