"""SDO read latency: in process, and `lolacli sdo read` as a whole process.

1. In process (no sockets): expedited uploads of 0x1000 from a canopen LocalNode (the
   gateway's IMU node, served by ``lolacli.sdo.node``) over python-can's ``virtual`` bus,
   through ``lolacli.sdo.read`` (typed, over ``CanopenClient``), against two baselines
   measured in the same run: canopen's own ``RemoteNode.sdo.upload`` on the same bus (what
   canopen costs without lolacli on top) and a bare python-can request/answer round trip
   through the same notifier threads (an echo, no SDO). The three are measured in
   alternating batches, so a load change on the shared machine hits them alike.
2. Whole process (needs root: both ends join a udp_multicast group inside a private network
   namespace): wall time of ``python -m lolacli sdo read 16 0x1000 --can … --interface
   udp_multicast`` against ``python -c pass`` and ``python -m lolacli --version``.

    python benchmarks/sdo_read.py                 # 5000 reads, 20 processes
    python benchmarks/sdo_read.py --reads 20000 --processes 0 --json
"""

from __future__ import annotations

import argparse
import json
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
                    "lolacli": lambda: read(client, 0x1000, 0),
                    "canopen": lambda: client.node.sdo.upload(0x1000, 0),
                    "echo": round_trip,
                },
                n,
            )
    echo_notifier.stop()
    server_bus.shutdown()
    return {
        "lolacli_median_us": r["lolacli"][0],
        "lolacli_p99_us": r["lolacli"][1],
        "canopen_median_us": r["canopen"][0],
        "python_can_echo_median_us": r["echo"][0],
    }


def _wall_ms(cmds: dict[str, list[str]], n: int) -> dict[str, float]:
    """Median wall time of each command, run in turn n times (interleaved)."""
    times: dict[str, list[float]] = {name: [] for name in cmds}
    for _ in range(n):
        for name, cmd in cmds.items():
            t = time.perf_counter()
            subprocess.run(cmd, cwd=ROOT, capture_output=True, check=True)
            times[name].append(time.perf_counter() - t)
    return {name: statistics.median(t) * 1000 for name, t in times.items()}


def whole_process(n: int) -> dict[str, float] | None:
    from tests.sdo.multicast import namespace

    try:
        ctx = namespace()
        ns = ctx.__enter__()
    except BaseException as exc:  # pytest.skip outside pytest: not root
        print(f"whole-process timing skipped: {exc}", file=sys.stderr)
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
        return _wall_ms(
            {
                "python_pass_ms": [*inside, "-c", "pass"],
                "lolacli_version_ms": [*inside, "-m", "lolacli", "--version"],
                "sdo_read_ms": [*inside, "-m", "lolacli", "sdo", "read", "16", "0x1000", *can_args],
            },
            n,
        )
    finally:
        if server is not None:
            server.send_signal(2)
            server.wait(20)
        ctx.__exit__(None, None, None)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--reads", type=int, default=5000)
    parser.add_argument("--processes", type=int, default=20)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    result: dict[str, object] = {"in_process": in_process(args.reads)}
    if args.processes:
        result["whole_process"] = whole_process(args.processes)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    r = result["in_process"]
    assert isinstance(r, dict)
    print(f"in process, {args.reads} expedited reads of 0x1000 over python-can virtual:")
    print(
        f"  lolacli.sdo.read      median {r['lolacli_median_us']:7.1f} us  "
        f"p99 {r['lolacli_p99_us']:.1f} us"
    )
    print(
        f"  canopen sdo.upload    median {r['canopen_median_us']:7.1f} us  "
        f"(lolacli / canopen = {r['lolacli_median_us'] / r['canopen_median_us']:.2f})"
    )
    print(
        f"  python-can echo       median {r['python_can_echo_median_us']:7.1f} us  "
        f"(lolacli / echo = {r['lolacli_median_us'] / r['python_can_echo_median_us']:.2f})"
    )
    w = result.get("whole_process")
    if isinstance(w, dict):
        print(f"whole process, median of {args.processes} (udp_multicast, other process serves):")
        print(f"  python -c pass            {w['python_pass_ms']:6.0f} ms")
        print(f"  lolacli --version         {w['lolacli_version_ms']:6.0f} ms")
        print(
            f"  lolacli sdo read 16 0x1000 {w['sdo_read_ms']:5.0f} ms  "
            f"(sdo read - --version = {w['sdo_read_ms'] - w['lolacli_version_ms']:.0f} ms)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
