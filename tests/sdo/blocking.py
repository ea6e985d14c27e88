"""A process for the stop tests: CANopen nodes on python-can's virtual bus, served in
this process (nothing outside it can reach that bus), and ``lolacli ARGS`` on the same
bus, as ``python -m tests.sdo.blocking CHANNEL ARGS…``.

The gateway IMU's EDS is node 16; any other node ID does not answer, as a CANopen slave
that is off or miswired does not: an SDO request to it waits for its ``--timeout``.
"""

from __future__ import annotations

import sys

from lolacli.cli.main import main
from lolacli.sdo.node import IMU_NODE, NodeServer, NodeSpec, example_eds


def serve_and_run(channel: str, argv: list[str]) -> None:
    with NodeServer(
        channel, [NodeSpec(example_eds("lola_imu.eds"), IMU_NODE)], interface="virtual"
    ):
        main(argv)  # exits (SystemExit) with the command's code; the nodes close after


if __name__ == "__main__":
    serve_and_run(sys.argv[1], sys.argv[2:])
