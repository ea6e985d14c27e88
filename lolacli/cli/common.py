"""Options and output helpers shared by every command group.

Data goes to stdout (JSON, tables); hints, warnings and progress go to stderr. Commands
raise :class:`~lolacli.errors.LolaError`; :func:`lolacli.cli.main.main` maps them to one line
on stderr and the exit code of DESIGN.md.
"""

from __future__ import annotations

import json
import os
import sys
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer


class OutputFormat(StrEnum):
    human = "human"
    json = "json"


FormatOption = Annotated[
    OutputFormat,
    typer.Option("--format", "-f", help="Output format: human (tables) or json (stdout)."),
]

EniArgument = Annotated[
    Path,
    typer.Argument(help="ENI file (EtherCATConfig XML).", show_default=False),
]


def default_eni() -> Path:
    """The embedded LOLA chain, used wherever an ENI is optional."""
    from lolacli.files import lola_path

    return lola_path()


def silence_stdout() -> None:
    """The reader of stdout went away (``lolacli … | head``): send the rest of the output
    to /dev/null and let the command finish, so that its exit code still says what it
    found (rich's default would exit 1, "checks found failures", at once)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def emit_json(data: Any) -> None:
    """Write one JSON document to stdout."""
    try:
        sys.stdout.write(json.dumps(data, indent=2, ensure_ascii=False) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        silence_stdout()


def stdout_console() -> Any:
    """The console every command group prints data with, and its width rule: the
    terminal's width, ``$COLUMNS``, or 80 columns when piped. Tables fit it by wrapping
    names and headers, never by cutting numbers; a table that cannot fit is printed whole,
    wider than that, rather than cropped (:func:`fit_table`). Lines of text are not broken
    (they stay one line for grep; a terminal wraps them)."""
    from rich.console import Console
    from rich.measure import Measurement
    from rich.table import Table

    class _Console(Console):
        def on_broken_pipe(self) -> None:
            silence_stdout()

        def print(self, *objects: Any, **kwargs: Any) -> None:
            tables = [o for o in objects if isinstance(o, Table)]
            if not tables:
                kwargs.setdefault("soft_wrap", True)  # a line of text is never broken
            for table in tables:
                fit_table(table)
            if len(objects) == 1 and tables and "width" not in kwargs:
                wide = self.options.update(width=1 << 16)
                need = Measurement.get(self, wide, tables[0]).minimum
                if need > self.width:
                    kwargs.update(width=need, crop=False)
            super().print(*objects, **kwargs)

    return _Console(highlight=False, soft_wrap=False)


def fit_table(table: Any) -> None:
    """The width rule for a rich table: names and headers wrap between words (a word is
    never split, nor cut with an ellipsis), and right-aligned (number) columns are never
    narrower than their widest cell."""
    from rich.cells import cell_len

    for column in table.columns:
        column.overflow = "fold"
        texts = [c for c in column.cells if isinstance(c, str)]
        words = [w for t in [*texts, str(column.header)] for w in t.split()]
        widest = max((cell_len(w) for w in words), default=0)
        if column.justify == "right":
            widest = max([widest, *(cell_len(t) for t in texts)])
        column.min_width = max(column.min_width or 0, widest)


def stderr_console() -> Any:
    from rich.console import Console

    return Console(stderr=True, highlight=False)


def warn(message: str) -> None:
    sys.stderr.write(f"lolacli: {message}\n")


def debug_enabled() -> bool:
    return os.environ.get("LOLACLI_DEBUG", "") not in ("", "0")
