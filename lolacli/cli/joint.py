"""`lolacli joint …`: a simulated joint behind its drive (seed 000 §V-VI): tracking with and
without the learned velocity feed-forward and target extrapolation (Table III, Fig. 9),
the k_e learning (Fig. 6), the closed loop's bandwidth (Fig. 10).

The library is :mod:`lolacli.motion` (numpy, imported inside the commands)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import JointsOption, not_nan

if TYPE_CHECKING:
    from lolacli.motion.joint import JointParams

app = typer.Typer(no_args_is_help=True,
                  help="A simulated joint behind its drive: tracking, k_e learning, bandwidth.")

TRACK_SCHEMA = "lolacli.joint/1"
TUNE_SCHEMA = "lolacli.joint-tune/1"
BODE_SCHEMA = "lolacli.joint-bode/1"

JointOption = Annotated[
    str,
    typer.Option("--joint", help="Joint: its ENI slave name, the name without its number "
                 "(\"L Knee\") or the number (\"Joint04\")."),
]
StepOption = Annotated[
    float,
    typer.Option("--step-s", min=0.2, max=5.0, callback=not_nan,
                 help="Duration of one walking step, s (a stride is two)."),
]
ControlHzOption = Annotated[
    int, typer.Option("--control-hz", min=100, max=10_000,
                      help="Rate of the central control (new targets), Hz.")
]
BusHzOption = Annotated[
    int,
    typer.Option("--bus-hz", min=100, max=10_000,
                 help="Bus rate, Hz: a whole multiple of the control rate (bode: the chirp "
                 "is computed each bus cycle); cycles between control updates extrapolate."),
]
PlotOption = Annotated[Path | None, typer.Option("--plot", metavar="FILE",
                                                  help="Write the figure to this PNG file.")]
SeriesFlag = Annotated[
    bool,
    typer.Option("--series", help="JSON: each case's error θd − θ every 0.1 ms as well "
                 "(error_series; for lolacli report --joint-track's figure)."),
]

_DEFAULT_JOINT = "Joint03 L Hip Pitch"  # lolacli.motion.joint.DEFAULT_JOINT (no numpy here)


def _joint(joints: Path | None, name: str) -> JointParams:
    from lolacli.errors import UsageError
    from lolacli.files import load_joints
    from lolacli.motion.joint import find_joint

    table = load_joints(joints)
    found = find_joint(table, name)
    if found is None:
        raise UsageError(f"--joint {name!r}: no such joint (there are {len(table)}; "
                         f"e.g. {next(iter(table))!r})")
    return found


def _period_ns(hz: int, option: str) -> int:
    from lolacli.errors import UsageError

    if 1_000_000_000 % hz or (1_000_000_000 // hz) % 100_000:
        raise UsageError(f"{option} {hz}: the period must be a whole multiple of the "
                         "drive's 0.1 ms (10000, 5000, 2000, 1000, 500 Hz, ...)")
    return 1_000_000_000 // hz


def _timing(control_hz: int, bus_hz: int, bus_option: str) -> Any:
    from lolacli.errors import UsageError
    from lolacli.motion.targets import BusTiming

    control, bus = _period_ns(control_hz, "--control-hz"), _period_ns(bus_hz, bus_option)
    if control % bus:
        raise UsageError(f"{bus_option} {bus_hz}: a whole multiple of --control-hz "
                         f"{control_hz} is needed")
    return BusTiming(control, bus, bus < control)


def _plot_path(plot: Path | None) -> None:
    """Refuse a --plot path that cannot be written before the simulation runs."""
    from lolacli.errors import UsageError

    if plot is None:
        return
    if plot.is_dir():
        raise UsageError(f"--plot {plot}: is a folder; give a PNG file name")
    if not plot.parent.is_dir():
        raise UsageError(f"--plot {plot}: no such folder {plot.parent}")


def _mrad(rad: float) -> str:
    from lolacli.text import number

    return number(rad * 1e3, "mrad", 4)


def _stopped(stop: Any) -> None:
    """A run stopped by a signal: raise it on to the root (one line, exit 130/143)."""
    stop.raise_if_stopped()


@app.command("track")
def track_cmd(
    joint: JointOption = _DEFAULT_JOINT,
    joints: JointsOption = None,
    step_s: StepOption = 0.6,
    steps: Annotated[int, typer.Option("--steps", min=1, max=50,
                                       help="Walking steps measured.")] = 4,
    control_hz: ControlHzOption = 1000,
    fast_bus_hz: Annotated[int, typer.Option(
        "--fast-bus-hz", min=100, max=10_000,
        help="Bus rate of the third case, Hz (a multiple of --control-hz).")] = 2000,
    plot: PlotOption = None,
    series: SeriesFlag = False,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Table III of seed 000: a walking hip trajectory tracked with the bus at the control
    rate and k_e = 0 (standard velocity feed-forward, "ref"), with the learned k_e
    ("w/ff"), and with a faster bus whose cycles between control updates extrapolate the
    target (learned again there). RMS and largest error of θd − θ over --steps steps,
    after 0.3 s settling; --plot draws the error over time (Fig. 9)."""
    from lolacli.interrupt import stop_signals
    from lolacli.motion.targets import HipWalk
    from lolacli.motion.tracking import Stopped, table_iii

    _plot_path(plot)
    params = _joint(joints, joint)
    slow = _timing(control_hz, control_hz, "--control-hz")
    fast = _timing(control_hz, fast_bus_hz, "--fast-bus-hz")
    walk = HipWalk(step_s=step_s)
    with stop_signals() as stop, stop.polled():
        try:
            cases, learnt = table_iii(params, walk, step_s=step_s, window_s=steps * step_s,
                                      control_period_ns=slow.control_period_ns,
                                      fast_bus_period_ns=fast.bus_period_ns,
                                      should_stop=stop)
        except Stopped:
            _stopped(stop)
            raise
    doc = {
        "schema": TRACK_SCHEMA,
        "joint": params.name,
        "trajectory": {"kind": "walking hip", "step_s": step_s, "steps": steps,
                       "amplitude_rad": walk.amplitude_rad},
        "cases": [c.to_dict() | (_series(c) if series else {}) for c in cases],
        "learning": {k: [{"k_e": ke, "rms_error_rad": e} for ke, e in v.steps]
                     for k, v in learnt.items()},
    }
    if plot is not None:
        _plot_track(plot, cases)
    if fmt is OutputFormat.json:
        emit_json(doc)
        return
    _render_track(doc)


def _series(case: Any) -> dict[str, Any]:
    """The case's error over its window: θd − θ (rad, to 1e-10) every ``sample_s`` from 0."""
    import numpy as np

    t = case.tracking.times_s
    return {"error_series": {
        "sample_s": round(float(t[1] - t[0]), 12) if len(t) > 1 else 1e-4,
        "error_rad": np.round(case.tracking.error_rad, 10).tolist()}}


def _render_track(doc: dict[str, Any]) -> None:
    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import number

    console = stdout_console()
    t = doc["trajectory"]
    say(console, f"Tracking of {doc['joint']}: walking hip, "
        f"{number(t['step_s'], 's')} steps, {t['steps']} measured")
    table = data_table()
    for name, right in (("case", False), ("control", True), ("bus", True),
                        ("extrapolated", False), ("k_e", True), ("RMS error", True),
                        ("max error", True)):
        table.add_column(name, justify="right" if right else "left")
    for c in doc["cases"]:
        table.add_row(c["name"], number(c["control_hz"], "Hz", 0), number(c["bus_hz"], "Hz", 0),
                      "yes" if c["extrapolation"] else "no", f"{c['k_e']:.1f}",
                      _mrad(c["rms_error_rad"]), _mrad(c["max_error_rad"]))
    console.print(table)
    ref, *rest = doc["cases"]
    for c in rest:
        cut = 100 * (1 - c["rms_error_rad"] / ref["rms_error_rad"])
        say(console, f"{c['name']}: RMS error {number(cut, '%', 1)} below {ref['name']}")


def _plot_track(path: Path, cases: list[Any]) -> None:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4))
    for c in cases:
        ax.plot(c.tracking.times_s, c.tracking.error_rad * 1e3, label=c.name, linewidth=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tracking error θd − θ (mrad)")
    ax.set_title("Closed-loop tracking error (seed 000 Fig. 9)")
    ax.legend()
    ax.grid(True, alpha=0.3)
    _save(fig, path)


@app.command("tune")
def tune_cmd(
    joint: JointOption = _DEFAULT_JOINT,
    joints: JointsOption = None,
    step_s: StepOption = 0.6,
    control_hz: ControlHzOption = 1000,
    bus_hz: BusHzOption = 1000,
    max_steps: Annotated[int, typer.Option("--max-steps", min=2, max=200,
                                           help="Most k_e values tried.")] = 50,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """The k_e learning of seed 000 §V: k_e from 0 in steps of 0.1 while the RMS tracking
    error over two walking steps falls; the last k_e before it rose is kept
    (k_vel,ff = 1 + k_e)."""
    from lolacli.interrupt import stop_signals
    from lolacli.motion.targets import HipWalk
    from lolacli.motion.tracking import KE_STEP, Stopped, learn_ke, learning_cost

    params = _joint(joints, joint)
    timing = _timing(control_hz, bus_hz, "--bus-hz")
    with stop_signals() as stop, stop.polled():
        try:
            learning = learn_ke(learning_cost(params, HipWalk(step_s=step_s), timing, step_s,
                                              stop), max_steps=max_steps)
        except Stopped:
            _stopped(stop)
            raise
    doc = {
        "schema": TUNE_SCHEMA,
        "joint": params.name,
        "control_hz": round(1e9 / timing.control_period_ns, 6),
        "bus_hz": round(1e9 / timing.bus_period_ns, 6),
        "extrapolation": timing.extrapolate,
        "step_s": step_s,
        "k_e_step": KE_STEP,
        "steps": [{"k_e": ke, "rms_error_rad": e} for ke, e in learning.steps],
        "k_e": learning.k_e,
        "k_vel_ff": 1.0 + learning.k_e,
    }
    if fmt is OutputFormat.json:
        emit_json(doc)
        return
    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import number

    console = stdout_console()
    say(console, f"k_e learning of {doc['joint']}: control "
        f"{number(doc['control_hz'], 'Hz', 0)}, bus {number(doc['bus_hz'], 'Hz', 0)}"
        f"{', extrapolated' if doc['extrapolation'] else ''}; cost: RMS error over two "
        f"steps of {number(step_s, 's')}")
    table = data_table()
    table.add_column("k_e", justify="right")
    table.add_column("RMS error", justify="right")
    table.add_column("")
    for s in doc["steps"]:
        kept = "kept" if s["k_e"] == doc["k_e"] else ""
        table.add_row(f"{s['k_e']:.1f}", _mrad(s["rms_error_rad"]), kept)
    console.print(table)
    say(console, f"learned k_e = {doc['k_e']:.1f} (k_vel,ff = {doc['k_vel_ff']:.1f})")


class Feedforward(StrEnum):
    full = "full"
    velocity = "velocity"
    none = "none"


@app.command("bode")
def bode_cmd(
    joint: JointOption = _DEFAULT_JOINT,
    joints: JointsOption = None,
    f_start: Annotated[float, typer.Option("--f-start", min=0.1, callback=not_nan,
                                           help="Chirp start frequency, Hz.")] = 10.0,
    f_stop: Annotated[float, typer.Option("--f-stop", min=1.0, max=5000.0, callback=not_nan,
                                          help="Chirp end frequency, Hz.")] = 500.0,
    amplitude: Annotated[float, typer.Option("--amplitude", min=1e-7, max=1.0,
                                             callback=not_nan,
                                             help="Chirp amplitude, rad.")] = 0.0002,
    duration: Annotated[float, typer.Option("--duration", min=0.5, max=60.0, callback=not_nan,
                                            help="Chirp duration, s.")] = 4.0,
    bus_hz: BusHzOption = 2000,
    k_e: Annotated[float, typer.Option("--ke", min=0.0, max=10.0, callback=not_nan,
                                       help="k_e of the velocity feed-forward.")] = 0.0,
    feedforward: Annotated[Feedforward, typer.Option(
        "--feedforward", help="Feed-forward sent with the target: full (velocity and "
        "current), velocity, or none.")] = Feedforward.full,
    plot: PlotOption = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """The closed loop's frequency response (seed 000 Fig. 10): a small-amplitude chirp
    target through the bus, the response from target to joint angle in 1/24-octave bands,
    and its -3 dB bandwidth."""
    from lolacli.errors import UsageError
    from lolacli.interrupt import stop_signals
    from lolacli.motion.bode import chirp_response
    from lolacli.motion.targets import Chirp
    from lolacli.motion.tracking import Stopped

    if f_stop < 2 * f_start:
        raise UsageError("--f-stop must be at least twice --f-start")
    if f_stop > bus_hz / 2:
        raise UsageError(f"--f-stop {f_stop:g} Hz: above half the bus rate ({bus_hz / 2:g} Hz)")
    _plot_path(plot)
    params = _joint(joints, joint)
    timing = _timing(bus_hz, bus_hz, "--bus-hz")
    chirp = Chirp(f_start, f_stop, duration, amplitude)
    with stop_signals() as stop, stop.polled():
        try:
            bode = chirp_response(params, chirp, timing, k_e=k_e,
                                  velocity_ff=feedforward is not Feedforward.none,
                                  current_ff=feedforward is Feedforward.full,
                                  should_stop=stop)
        except Stopped:
            _stopped(stop)
            raise
    doc = _bode_doc(params.name, bus_hz, chirp, feedforward.value, k_e, bode)
    if plot is not None:
        _plot_bode(plot, bode)
    if fmt is OutputFormat.json:
        emit_json(doc)
        return
    _render_bode(doc)


def _bode_doc(joint: str, bus_hz: int, chirp: Any, feedforward: str, k_e: float,
              bode: Any) -> dict[str, Any]:
    return {
        "schema": BODE_SCHEMA,
        "joint": joint,
        "bus_hz": bus_hz,
        "chirp": {"start_hz": chirp.start_hz, "stop_hz": chirp.stop_hz,
                  "amplitude_rad": chirp.amplitude_rad, "duration_s": chirp.duration_s},
        "feedforward": feedforward,
        "k_e": k_e,
        "bandwidth_hz": bode.bandwidth_hz,
        "points": [{"freq_hz": p.freq_hz, "gain_db": p.gain_db, "phase_deg": p.phase_deg}
                   for p in bode.points],
    }


def _render_bode(doc: dict[str, Any]) -> None:
    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import number

    console = stdout_console()
    c = doc["chirp"]
    say(console, f"Closed-loop response of {doc['joint']}: chirp "
        f"{number(c['start_hz'], 'Hz')} to {number(c['stop_hz'], 'Hz')}, "
        f"{number(c['amplitude_rad'] * 1e3, 'mrad', 4)}, {number(c['duration_s'], 's')}; "
        f"bus {number(doc['bus_hz'], 'Hz', 0)}, feed-forward {doc['feedforward']}, "
        f"k_e {doc['k_e']:g}")
    table = data_table()
    for name in ("frequency", "gain", "phase"):
        table.add_column(name, justify="right")
    points = doc["points"]
    for p in points[:: max(1, len(points) // 16)]:  # about two lines an octave
        table.add_row(number(p["freq_hz"], "Hz", 1), number(p["gain_db"], "dB", 2),
                      number(p["phase_deg"], "°", 1))
    console.print(table)
    bw = doc["bandwidth_hz"]
    say(console, f"-3 dB bandwidth: {number(bw, 'Hz', 1)}" if bw is not None else
        f"-3 dB bandwidth: above {number(points[-1]['freq_hz'], 'Hz', 1)} (not reached)")


def _plot_bode(path: Path, bode: Any) -> None:
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(8, 6))
    f = [p.freq_hz for p in bode.points]
    top.semilogx(f, [p.gain_db for p in bode.points])
    bottom.semilogx(f, [p.phase_deg for p in bode.points])
    top.axhline(-3.0103, color="grey", linestyle="--", linewidth=0.8)
    if bode.bandwidth_hz is not None:
        top.axvline(bode.bandwidth_hz, color="red", linewidth=0.8,
                    label=f"-3 dB at {bode.bandwidth_hz:.1f} Hz")
        top.legend()
    top.set_ylabel("gain (dB)")
    bottom.set_ylabel("phase (°)")
    bottom.set_xlabel("frequency (Hz)")
    top.set_title("Closed-loop response, target to joint angle (seed 000 Fig. 10)")
    for ax in (top, bottom):
        ax.grid(True, which="both", alpha=0.3)
    _save(fig, path)


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> None:
    from lolacli.errors import UsageError

    plt = _pyplot()
    try:
        fig.tight_layout()
        fig.savefig(path, dpi=100, format="png")
    except OSError as exc:
        raise UsageError(f"--plot {path}: cannot write: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)
