"""Entry point: ``lolacli``. Sub-apps are registered here; each imports its library lazily.

The command modules are imported when the app is built, and only those the command line
names: ``lolacli capture analyze F`` imports the ``capture`` group alone (the others cost
a short command ~60 ms of start-up), anything else (``--help``, ``--version``, an
unknown name) every group. Within the group, only the command named is built into a
click command (its siblings' options: ~1.5 ms more). :data:`app` is the whole app, built
on first use.
"""

from __future__ import annotations

import copy
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
            _usage_error(exc)
            raise

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        """The root's own options ("lolacli --bogus"): the same one line as a command's."""
        try:
            return list(super().parse_args(ctx, args))
        except typer.TyperException as exc:
            _usage_error(exc)
            raise


def _usage_error(exc: Any) -> None:
    """click's usage errors (wrong arguments, exit 2) as one line on stderr, then exit 2;
    any other click exception is left to click."""
    if exc.exit_code != 2:  # click's UsageError and its kinds: wrong arguments
        return
    _traceback_if_debug()
    usage_ctx = getattr(exc, "ctx", None)
    if usage_ctx is not None and exc.format_message() == usage_ctx.get_help():
        sys.stderr.write(exc.format_message() + "\n")  # a group without a command:
        raise typer.Exit(2) from None  # its help, as the root's (no_args_is_help)
    # one prefix for every error, "lolacli: error:", whatever the program was called by
    # (lolacli, python -m lolacli); the command is the one just typed
    message = " ".join(exc.format_message().split())
    # click's "Invalid value for '--ke': 'abc' is not…" as "--ke: 'abc' is not…": the
    # line fits 80 columns
    if message.startswith("Invalid value for '") and "': " in message:
        name, _, rest = message.removeprefix("Invalid value for '").partition("': ")
        name = name.replace("' / '", "/")  # "'-c' / '--count'": -c/--count
        message = f"{name}: {_short_range(rest)}"
    sys.stderr.write(f"lolacli: error: {message} (see --help)\n")
    raise typer.Exit(2) from None


def _short_range(message: str) -> str:
    """click's words for a bad value, shorter, so that the error line fits 80 columns:
    "-1 is not in the range x>=0." as "-1 is below 0", "100 is not in the range
    0<=x<=99." as "100 is not 0 to 99", "'x' is not a valid float range." as "'x' is
    not a number", "'a' is not one of 'b', 'c'." as "'a' is not b|c"."""
    import re

    message = message.rstrip(".")
    if m := re.fullmatch(r"(.*) is not a valid (float|integer|int)( range)?", message):
        return f"{m[1]} is not {'a number' if m[2] == 'float' else 'an integer'}"
    if m := re.fullmatch(r"(.*) is not one of (.*)", message):
        return f"{m[1]} is not {'|'.join(c.strip(chr(39)) for c in m[2].split(', '))}"
    value, found, bounds = message.partition(" is not in the range ")
    if not found:
        return message
    if m := re.fullmatch(r"(\S+?)<=?x<=?(\S+)", bounds):
        return f"{value} is not {m[1]} to {m[2]}"
    if m := re.fullmatch(r"x(>=?|<=?)(\S+)", bounds):
        return f"{value} is {'below' if m[1].startswith('>') else 'above'} {m[2]}"
    return f"{value} is not {bounds}"


def _traceback_if_debug() -> None:
    """With LOLACLI_DEBUG=1 the traceback of the error being handled goes to stderr (the
    exit code stays the documented one)."""
    if debug_enabled():
        import traceback

        traceback.print_exc()


def _build(names: tuple[str, ...] = tuple(GROUPS), command: str | None = None) -> typer.Typer:
    """The root app with the top-level commands ``names`` (importing their modules); a
    group that has a command named ``command`` gets that one alone (:func:`_only`)."""
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
            root.add_typer(_only(modules[0].app, command), name=name)
    root.callback()(_root)
    return root


def _only(group: typer.Typer, command: str | None) -> typer.Typer:
    """``group`` with its command ``command`` alone, when it has one by that name (typer
    builds the click command, options and all, of every command a group registers), else
    ``group``. A copy: the module's app keeps all its commands."""
    chosen = [c for c in group.registered_commands if command is not None and c.name == command]
    if len(chosen) != 1:
        return group
    alone = copy.copy(group)
    alone.registered_commands = chosen
    return alone


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
    if first in GROUPS:  # the group's command: the word after it (no group takes options)
        _build((first,), args[1] if len(args) > 1 else None)(args=argv)
    else:
        __getattr__("app")(args=argv)
