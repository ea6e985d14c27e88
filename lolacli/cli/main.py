"""Entry point: ``lolacli``. Sub-apps are registered here; each imports its library lazily.

The command modules are imported when the app is built, and only those the command line
names: ``lolacli capture analyze F`` imports the ``capture`` group alone (the others cost
a short command ~60 ms of start-up), anything else (``--help``, ``--version``, an
unknown name) every group. :data:`app` is the whole app, built on first use.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Any

import typer
from typer.core import TyperGroup

from lolacli import __version__
from lolacli.cli.common import debug_enabled

#: top-level names, in the order of the root's help, and the command modules each needs
#: (in the order they register their commands: the order of the group's help)
GROUPS: dict[str, tuple[str, ...]] = {
    "eni": ("eni",),
    "bus": ("bus", "bus_data", "bus_diag", "bus_emulate", "bus_graph", "bus_reg", "bus_scan",
            "bus_sii", "bus_simulate", "bus_state", "bus_timing"),
    "capture": ("capture",),
    "sdo": ("sdo",),
    "foe": ("foe",),
    "traj": ("traj",),
    "joint": ("joint",),
    "report": ("report",),
}


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


def _build(names: tuple[str, ...] = tuple(GROUPS)) -> typer.Typer:
    """The root app with the top-level commands ``names`` (importing their modules)."""
    root = typer.Typer(
        cls=_LolaGroup,
        name="lolacli",
        help="EtherCAT bus commissioning and diagnostics: ENI, timing, captures, emulation, "
        "SDO, FoE.",
        rich_markup_mode=None,
        pretty_exceptions_enable=False,
        no_args_is_help=True,
        add_completion=False,
    )
    for name in names:
        modules = [importlib.import_module(f"lolacli.cli.{m}") for m in GROUPS[name]]
        if name == "report":
            root.command("report")(modules[0].report_cmd)
        else:
            root.add_typer(modules[0].app, name=name)
    root.callback()(_root)
    return root


def _version(value: bool) -> None:
    if value:
        sys.stdout.write(f"lolacli {__version__}\n")
        raise typer.Exit(0)


def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Show the version and exit."
    ),
) -> None:
    """EtherCAT bus commissioning and diagnostics."""


def __getattr__(name: str) -> Any:
    """:data:`app`, the whole app, built on first use (tests, docs generation)."""
    if name == "app":
        whole = globals()["app"] = _build()
        return whole
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def main(argv: list[str] | None = None) -> None:
    """Run the CLI (the ``lolacli`` console script).

    numpy's OpenBLAS starts a thread per core when numpy is imported, and those threads
    spin after each call: no command multiplies matrices large enough to gain from them,
    and ``capture analyze`` of a 2 M-frame capture lost ~0.1 s of wall time (and 0.2 s
    of CPU) to them on two cores. One thread, unless the caller says otherwise."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    args = sys.argv[1:] if argv is None else argv
    first = args[0] if args else None
    if first in GROUPS:
        _build((first,))(args=argv)
    else:
        __getattr__("app")(args=argv)
