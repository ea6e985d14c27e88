"""`lolacli traj …`: trajectories. `traj plan` plans one jerk-limited S-curve move
(:func:`lolacli.motion.scurve.plan`, seed 003 eqs. 1-17) and prints its phases and peaks."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import not_nan

SCHEMA = "lolacli.traj/1"

app = typer.Typer(no_args_is_help=True, help="Jerk-limited S-curve trajectories (seed 003).")


def _number(name: str, help_text: str) -> Any:
    return typer.Option(name, callback=not_nan, help=help_text, show_default=False)


@app.command("plan")
def plan_cmd(
    distance: Annotated[float, _number("--distance", "Distance to move (signed), in UNIT.")],
    vmax: Annotated[float, _number("--vmax", "Maximum velocity, UNIT/s.")],
    amax: Annotated[float, _number("--amax", "Maximum acceleration, UNIT/s².")],
    jmax: Annotated[float, _number("--jmax", "Maximum jerk, UNIT/s³.")],
    dmax: Annotated[float | None, _number(
        "--dmax", "Maximum deceleration (the second ramp), UNIT/s². Default: --amax.")] = None,
    v_start: Annotated[float, typer.Option(
        "--v-start", min=0.0, callback=not_nan,
        help="Start speed in the direction of the move, UNIT/s.")] = 0.0,
    v_end: Annotated[float, typer.Option(
        "--v-end", min=0.0, callback=not_nan,
        help="End speed in the direction of the move, UNIT/s.")] = 0.0,
    cycle_text: Annotated[str | None, typer.Option(
        "--cycle", metavar="TIME", show_default=False,
        help="Cycle time (1ms, 500us, 0.001s): every phase lasts whole cycles. Default: "
        "continuous time.")] = None,
    unit: Annotated[str, typer.Option("--unit", help="Unit of position (for the output).")]
    = "m",
    plot: Annotated[Path | None, typer.Option(
        "--plot", metavar="FILE", help="Write a PNG file of position, velocity, acceleration "
        "and jerk.")]
    = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Plan a jerk-limited S-curve move: accelerate (T1-T3), cruise (T4), decelerate
    (T5-T7), from --v-start to --v-end, never above --vmax, --amax, --dmax, --jmax.

    When the distance is too short to cruise at --vmax the peak velocity is reduced (seed
    003 eq. 14). With --cycle every phase is a whole number of cycles, rounded up, and the
    accelerations and peak velocity are re-solved (eqs. 11-13) so that the end position
    and velocity are exact and every limit holds. A move that would have to reverse
    (the distance shorter than the change from --v-start to --v-end needs) is refused.
    """
    from lolacli.errors import UsageError
    from lolacli.motion.scurve import plan

    cycle = _cycle_s(cycle_text)

    if plot is not None and plot.is_dir():
        raise UsageError(f"--plot {plot} is a folder; give a PNG file name")
    direction = -1.0 if distance < 0 else 1.0
    profile = plan(distance, vmax, amax, jmax, direction * v_start, direction * v_end,
                   cycle, dmax, allow_reverse=False)
    doc = {"schema": SCHEMA, "unit": unit,
           "request": {"distance": distance, "vmax": vmax, "amax": amax,
                       "dmax": profile.dmax, "jmax": jmax, "v_start": v_start,
                       "v_end": v_end, "cycle_s": cycle},
           **profile.to_dict()}
    if plot is not None:
        write_plot(profile.sample(), plot, unit, f"S-curve over {distance:g} {unit}")
        doc["plot"] = str(plot)
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        _render(doc)


def _render(doc: dict[str, Any]) -> None:
    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import number, plural

    console = stdout_console()
    u, req = doc["unit"], doc["request"]
    cycles = f", {plural(doc['cycles'], 'cycle')} of {number(req['cycle_s'] * 1e3, 'ms')}" \
        if doc["cycles"] is not None else ""
    say(console, f"S-curve over {number(req['distance'], u)}: "
                 f"{number(doc['duration_s'], 's', 4)}{cycles}")
    phases = data_table()
    for name in ("T1", "T2", "T3", "T4", "T5", "T6", "T7"):
        phases.add_column(name, justify="right")
    phases.add_row(*(number(t * 1e3, "ms", 1) for t in doc["phases_s"]))
    console.print(phases)
    table = data_table()
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("limit", justify="right")
    table.add_row("peak velocity", number(doc["max_velocity"], f"{u}/s"),
                  number(req["vmax"], f"{u}/s"))
    table.add_row("peak acceleration", number(doc["max_acceleration"], f"{u}/s²"),
                  number(max(req["amax"], req["dmax"]), f"{u}/s²"))
    table.add_row("peak jerk", number(doc["max_jerk"], f"{u}/s³"),
                  number(req["jmax"], f"{u}/s³"))
    table.add_row("end position", number(doc["end_position"], u, 6),
                  number(req["distance"], u, 6))
    table.add_row("end velocity", number(doc["end_velocity"], f"{u}/s", 6),
                  number(req["v_end"], f"{u}/s", 6))
    console.print(table)
    cruise = "cruises at --vmax" if doc["cruise_at_vmax"] else \
        "no cruise at --vmax: peak reduced (eq. 14)"
    say(console, f"Profile {cruise}.")
    if "plot" in doc:
        say(console, f"Plot: {doc['plot']}")


def write_plot(series: dict[str, Any], path: Path, unit: str, title: str,
               goals: list[tuple[float, float]] | None = None) -> Path:
    """A PNG of position, velocity, acceleration and jerk over time (seed 003 Figs. 6-7);
    ``goals`` (time s, position) are marked on the position axis."""
    from lolacli.errors import UsageError

    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - a core dependency
        raise UsageError(f"--plot needs matplotlib ({exc})") from None
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(7.2, 7.2))
    try:
        rows = (("position", unit), ("velocity", f"{unit}/s"),
                ("acceleration", f"{unit}/s²"), ("jerk", f"{unit}/s³"))
        for ax, (name, u) in zip(axes, rows, strict=True):
            if name == "jerk":
                ax.step(series["t"], series[name], where="post", lw=0.8)
            else:
                ax.plot(series["t"], series[name], lw=0.9, label="command")
            ax.set_ylabel(f"{name}\n({u})", fontsize=8)
            ax.grid(True, alpha=0.3)
        if goals:
            axes[0].plot([g[0] for g in goals], [g[1] for g in goals], ".", ms=3,
                         label="goals")
            axes[0].legend(fontsize=8)
        axes[-1].set_xlabel("time (s)")
        axes[0].set_title(title, fontsize=10)
        fig.tight_layout()
        try:
            fig.savefig(path, format="png", dpi=110)
        except OSError as exc:
            raise UsageError(f"--plot {path}: cannot write ({exc.strerror})") from None
    finally:
        plt.close(fig)
    return path


def _cycle_s(text: str | None) -> float | None:
    """--cycle in seconds (None: continuous time)."""
    from lolacli.errors import UsageError
    from lolacli.timing.model import parse_duration_ns

    if text is None:
        return None
    cycle_ns = parse_duration_ns(text, None, what="--cycle")
    if cycle_ns <= 0:
        raise UsageError(f"--cycle {text}: a cycle lasts more than 0 s")
    return cycle_ns / 1e9
