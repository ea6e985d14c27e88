"""SDO read latency: in process, and `lolacli sdo read` as a whole process.

1. In process (no sockets): expedited uploads of 0x1000 from a canopen LocalNode (the
   gateway's IMU node, served by ``lolacli.sdo.node``) over python-can's ``virtual`` bus,
   through ``lolacli.sdo.read`` (typed, over ``CanopenClient``), against two baselines
   measured in the same run: canopen's own ``RemoteNode.sdo.upload`` on the same bus (what
   canopen costs without lolacli on top) and a bare python-can request/answer round trip
   through the same notifier threads (the floor of this transport).
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lolacli.sdo import read  # noqa: E402
from lolacli.sdo.canopen_client import UDP_MULTICAST_IPV4, CanopenNetwork  # noqa: E402
from lolacli.sdo.node import IMU_NODE, NodeServer, gateway_nodes  # noqa: E402


def _median_us(fn, n: int) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    for _ in range(min(200, n)):
        fn()
    times = []
    for _ in range(n):
        t = time.perf_counter_ns()
        fn()
        times.append(time.perf_counter_ns() - t)
    times.sort()
    return times[len(times) // 2] / 1000, times[int(len(times) * 0.99)] / 1000


def in_process(n: int) -> dict[str, float]:
    import can

    with NodeServer("bench-sdo", gateway_nodes(), interface="virtual"):
        with CanopenNetwork("bench-sdo", interface="virtual", timeout_s=1.0) as net:
            client = net.client(IMU_NODE)
            ours = _median_us(lambda: read(client, 0x1000, 0), n)
            canopen_only = _median_us(lambda: client.node.sdo.upload(0x1000, 0), n)
    # floor: one CAN frame out, one back, through python-can notifiers on a virtual bus
    server_bus = can.Bus(interface="virtual", channel="bench-echo")
    client_bus = can.Bus(interface="virtual", channel="bench-echo")
    answer = can.Message(arbitration_id=0x590, data=bytes(8), is_extended_id=False)
    got = threading.Event()

    def echo(msg: can.Message) -> None:
        server_bus.send(answer)

    def back(msg: can.Message) -> None:
        got.set()

    notifiers = [can.Notifier(server_bus, [echo], 0.02), can.Notifier(client_bus, [back], 0.02)]
    request = can.Message(arbitration_id=0x610, data=bytes(8), is_extended_id=False)

    def round_trip() -> None:
        got.clear()
        client_bus.send(request)
        got.wait(1.0)

    floor = _median_us(round_trip, n)
    for notifier in notifiers:
        notifier.stop()
    server_bus.shutdown()
    client_bus.shutdown()
    return {
        "lolacli_median_us": ours[0],
        "lolacli_p99_us": ours[1],
        "canopen_median_us": canopen_only[0],
        "python_can_round_trip_median_us": floor[0],
    }


def _wall_ms(cmd: list[str], n: int) -> float:
    times = []
    for _ in range(n):
        t = time.perf_counter()
        subprocess.run(cmd, cwd=ROOT, capture_output=True, check=True)
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1000


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
        return {
            "python_pass_ms": _wall_ms([*inside, "-c", "pass"], n),
            "lolacli_version_ms": _wall_ms([*inside, "-m", "lolacli", "--version"], n),
            "sdo_read_ms": _wall_ms(
                [*inside, "-m", "lolacli", "sdo", "read", "16", "0x1000", *can_args], n
            ),
        }
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
        f"  python-can round trip median {r['python_can_round_trip_median_us']:7.1f} us  "
        f"(lolacli / floor = {r['lolacli_median_us'] / r['python_can_round_trip_median_us']:.2f})"
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
