"""Command-line options that several commands share, each defined once here: the same
flag, type, bounds and help text wherever it appears. A command's own options stay in its
module.

Checks a range cannot express go in ``callback=``: :func:`not_nan` for bounded numbers
(typer's range types let ``nan`` through, as every comparison with it is false).
"""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer


def not_nan(value: float | None) -> float | None:
    """A bounded float option's value, refused when it is not a number (``nan``)."""
    if value is not None and value != value:
        raise typer.BadParameter(f"{value} is not a number")
    return value


class OutputFormat(StrEnum):
    human = "human"
    json = "json"


FormatOption = Annotated[
    OutputFormat,
    typer.Option("--format", "-f", help="Output format: human (tables) or json (stdout)."),
]

# ---------------------------------------------------------------- the bus and its ENI

_IFACE = typer.Option(
    "--iface", "-i", metavar="IF", help="EtherCAT: the network interface (NIC, veth, TAP)."
)
#: the interface a command needs (``bus emulate``, ``bus scan``)
IfaceArgument = Annotated[str, _IFACE]
#: the interface of a command that runs in process without one (``sdo``)
IfaceOption = Annotated[str | None, _IFACE]
#: how long the bench verbs (``bus reg/sii/alias/state``) wait for a frame
FrameTimeoutOption = Annotated[
    str, typer.Option("--frame-timeout", help="Wait this long for each frame (e.g. 20ms).")
]
#: one slave of a live bus, as the bench verbs name it
SlaveArgument = Annotated[
    str,
    typer.Argument(
        metavar="SLAVE",
        help="A position (3), @station address (@0x1003) or slave name (from its SII).",
        show_default=False,
    ),
]

#: an ENI that stands for the chain (emulated, or the live bus's configuration)
EniOption = Annotated[
    Path | None,
    typer.Option(
        "--eni",
        help="ENI of the chain: the one emulated, or the configuration of the --iface bus. "
        "Default: the embedded LOLA chain.",
    ),
]
#: an ENI that a bus or a capture is checked against
EniCheckOption = Annotated[
    Path | None,
    typer.Option(
        "--eni",
        help="ENI to check against (its slaves, WKCs and FMMU layout).",
    ),
]
EsiOption = Annotated[
    list[Path] | None,
    typer.Option(
        "--esi",
        help="ESI file; slaves whose identity it describes take their SII and value types "
        "from it. Repeatable.",
    ),
]
CaptureArgument = Annotated[
    Path, typer.Argument(help="Capture file (pcap or pcapng).", show_default=False)
]

# ---------------------------------------------------------------- faults of an emulated chain

DropOption = Annotated[
    float, typer.Option("--drop-p", help="Probability to lose a frame.")
]
StuckSafeopOption = Annotated[
    list[int] | None,
    typer.Option("--stuck-safeop", help="Slave position (1-based) that refuses OP; repeatable."),
]
DriftOption = Annotated[
    int, typer.Option("--drift-ppb", help="Clock drift step along the line (ppb).")
]
SeedOption = Annotated[int, typer.Option("--seed", help="Seed of the fault generator.")]

# ---------------------------------------------------------------- the CAN gateway's sensors

InterfaceOption = Annotated[
    str | None,
    typer.Option(
        "--interface",
        help="python-can interface: socketcan, pcan, kvaser, virtual, udp_multicast… "
        "Default: python-can's configuration.",
    ),
]

ImuRateOption = Annotated[
    float,
    typer.Option(
        "--imu-rate",
        metavar="HZ",
        help="The emulated CAN gateway's IMU rate (Hz; the LOLA seed's 200).",
    ),
]
FtsRateOption = Annotated[
    float,
    typer.Option(
        "--fts-rate",
        metavar="HZ",
        help="Its foot force/torque sensors' rate (Hz; default 1000).",
    ),
]
CanBitrateOption = Annotated[
    int,
    typer.Option(
        "--can-bitrate",
        metavar="BIT/S",
        help="Its CAN bus's bitrate (10000 to 1000000 bit/s; the seed's 1000000).",
    ),
]

# ---------------------------------------------------------------- the joints behind the drives

JointModelFlag = Annotated[
    bool,
    typer.Option(
        "--joint-model",
        help="A joint behind each drive the joints file names (motor, gear, link, the "
        "drive's P-PI-PI cascade) instead of a kinematic follower: moves show the joint's "
        "following error.",
    ),
]
KeOption = Annotated[
    float | None,
    typer.Option(
        "--ke",
        metavar="K",
        help="k_e of every joint's velocity feed-forward, k_vel,ff = 1 + k_e (-1 to 5, "
        "default 0); implies --joint-model.",
    ),
]
JointsOption = Annotated[
    Path | None,
    typer.Option(
        "--joints",
        metavar="FILE",
        help="Joint parameters (TOML, the form of the packaged lolacli/motion/joints.toml). "
        "Default: the packaged LOLA joints. bus simulate: implies --joint-model.",
    ),
]

# ---------------------------------------------------------------- verdict thresholds

MaxLostOption = Annotated[
    int, typer.Option("--max-lost", min=0, help="Lost frames allowed before exit 1.")
]
MaxWkcOption = Annotated[
    int,
    typer.Option("--max-wkc-mismatches", min=0, help="WKC mismatches allowed before exit 1."),
]

# ---------------------------------------------------------------- servers

def seconds(text: str | float) -> float:
    """A server's --duration in seconds: ``30s``, ``500ms`` as ``bus simulate`` spells a
    time, or a bare number of seconds."""
    from lolacli.errors import UsageError
    from lolacli.timing.model import parse_duration_ns

    try:
        return parse_duration_ns(str(text), "s") / 1e9
    except UsageError:
        raise typer.BadParameter(f"{str(text)[:20]!r} is not a time >= 0") from None


DurationOption = Annotated[
    float,
    typer.Option(
        "--duration",
        parser=seconds,
        metavar="TIME",
        help="Stop after this long: 30s, 500ms, or seconds (0: until Ctrl-C).",
    ),
]

SetValueOption = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        metavar="VARIABLE=VALUE",
        help="Write this output variable (typed as the ENI says) every cycle; repeatable.",
    ),
]
