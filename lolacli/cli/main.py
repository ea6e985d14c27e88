"""Entry point: ``lolacli``. Sub-apps are registered here; each imports its library lazily."""

from __future__ import annotations

import sys
from typing import Any

import typer
from typer.core import TyperGroup

from lolacli import __version__
from lolacli.cli import (  # noqa: F401
    bus,
    bus_data,
    bus_diag,
    bus_emulate,
    bus_graph,
    bus_reg,
    bus_scan,
    bus_sii,
    bus_simulate,
    bus_state,
    bus_timing,
    capture,
    eni,
    foe,
    joint,
    report,
    sdo,
    traj,
)
from lolacli.cli.common import debug_enabled


class _LolaGroup(TyperGroup):
    """Root group: maps library errors to one stderr line and the documented exit code."""

    def invoke(self, ctx: Any) -> Any:  # typer.Context; click is vendored in typer
        from lolacli.errors import LolaError
        from lolacli.interrupt import exit_code, stop_signals

        try:
            with stop_signals():  # SIGINT and SIGTERM raise Interrupted; restored after
                return super().invoke(ctx)
        except LolaError as exc:
            _traceback_if_debug()
            sys.stderr.write(f"lolacli: error: {exc}\n")
            raise typer.Exit(exc.exit_code) from None
        except KeyboardInterrupt as exc:
            sys.stderr.write(f"lolacli: {exc or 'stopped by SIGINT'}\n")
            raise typer.Exit(exit_code(exc)) from None
        except typer.TyperException as exc:
            if exc.exit_code != 2:  # click's UsageError and its kinds: wrong arguments
                raise
            _traceback_if_debug()
            usage_ctx = getattr(exc, "ctx", None)
            if usage_ctx is not None and exc.format_message() == usage_ctx.get_help():
                sys.stderr.write(exc.format_message() + "\n")  # a group without a command:
                raise typer.Exit(2) from None  # its help, as the root's (no_args_is_help)
            path = usage_ctx.command_path if usage_ctx is not None else "lolacli"
            message = " ".join(exc.format_message().split())
            sys.stderr.write(f"{path}: error: {message} (see --help)\n")
            raise typer.Exit(2) from None


def _traceback_if_debug() -> None:
    """With LOLACLI_DEBUG=1 the traceback of the error being handled goes to stderr (the
    exit code stays the documented one)."""
    if debug_enabled():
        import traceback

        traceback.print_exc()


app = typer.Typer(
    cls=_LolaGroup,
    name="lolacli",
    help="EtherCAT bus commissioning and diagnostics: ENI, timing, captures, emulation, SDO, FoE.",
    rich_markup_mode=None,
    pretty_exceptions_enable=False,
    no_args_is_help=True,
    add_completion=False,
)
app.add_typer(eni.app, name="eni")
app.add_typer(bus.app, name="bus")
app.add_typer(capture.app, name="capture")
app.add_typer(sdo.app, name="sdo")
app.add_typer(foe.app, name="foe")
app.add_typer(traj.app, name="traj")
app.add_typer(joint.app, name="joint")
app.command("report")(report.report_cmd)


def _version(value: bool) -> None:
    if value:
        sys.stdout.write(f"lolacli {__version__}\n")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Show the version and exit."
    ),
) -> None:
    """EtherCAT bus commissioning and diagnostics."""


def main(argv: list[str] | None = None) -> None:
    """Run the CLI (the ``lolacli`` console script)."""
    app(args=argv)
