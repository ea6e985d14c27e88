"""Output helpers shared by every command group (the shared options: :mod:`.options`).

Data goes to stdout (JSON, tables); hints, warnings and progress go to stderr. Commands
raise :class:`~lolacli.errors.LolaError`; :func:`lolacli.cli.main.main` maps them to one line
on stderr and the exit code of README.md.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

from lolacli.cli.options import FormatOption as FormatOption  # the shared options
from lolacli.cli.options import OutputFormat as OutputFormat


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


def json_text(data: Any, *, indent: bool = True) -> str:
    """``data`` as JSON, indented by two spaces, non-ASCII as it is (UTF-8), by orjson:
    json's own indenting encoder is pure Python, 15 times slower on a large report. An
    integer wider than 64 bits, which orjson does not take, goes through json, which
    writes the same text. NaN and infinities, which JSON does not have, are written null
    either way; a string that is not valid Unicode (a file name's undecodable bytes, as
    Python holds them) has U+FFFD in their place, so the output is valid UTF-8.
    ``indent=False``: the document on one line, compact (JSON lines)."""
    import orjson

    try:
        return orjson.dumps(data, default=_plain_number, option=orjson.OPT_NON_STR_KEYS
                            | orjson.OPT_SERIALIZE_NUMPY
                            | (orjson.OPT_INDENT_2 if indent else 0)).decode()
    except orjson.JSONEncodeError:
        return json.dumps(_valid(data), indent=2 if indent else None, ensure_ascii=False,
                          default=_plain_number)


def _plain_number(value: Any) -> Any:
    """A subclass of float or int, or a numpy scalar, as the number it is."""
    if isinstance(value, float):
        return float(value)
    if isinstance(value, int):
        return int(value)
    item = getattr(value, "item", None)  # a numpy scalar
    if callable(item):
        return item()
    raise TypeError(f"{type(value).__name__} is not JSON")


def _valid(data: Any) -> Any:
    """``data`` with NaN and infinities None and strings valid Unicode."""
    if isinstance(data, float):
        return data if data - data == 0 else None
    if isinstance(data, str):
        return data.encode("utf-8", "surrogateescape").decode("utf-8", "replace")
    if isinstance(data, dict):
        return {_valid(k): _valid(v) for k, v in data.items()}
    if isinstance(data, list | tuple):
        return [_valid(v) for v in data]
    return data


def emit_json(data: Any) -> None:
    """Write one JSON document to stdout."""
    try:
        sys.stdout.write(json_text(data) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        silence_stdout()


def stdout_console() -> Any:
    """The console every command group prints data with, and its width rule: the
    terminal's width, ``$COLUMNS``, or 80 columns when piped. Tables fit it by wrapping
    names and headers, never by cutting numbers; a table that cannot fit is printed whole,
    wider than that, rather than cropped (:func:`fit_table`). ``print`` does not break a
    line of text; prose goes through :func:`say`, which wraps it between words."""
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
                fit_table(table, self, kwargs.get("width") or self.width)
            if len(objects) == 1 and tables and "width" not in kwargs:
                wide = self.options.update(width=1 << 16)
                need = Measurement.get(self, wide, tables[0]).minimum
                if need > self.width:
                    kwargs.update(width=need, crop=False)
            super().print(*objects, **kwargs)

    # no emoji codes: a name such as "Drive:100:" in an ENI is printed as it is
    return _Console(highlight=False, soft_wrap=False, emoji=False)


def fit_table(table: Any, console: Any = None, width: int | None = None) -> None:
    """The width rule for a rich table: names and headers wrap between words (a word is
    never split, nor cut with an ellipsis), and right-aligned (number) columns are never
    narrower than their widest cell.

    Given the ``console`` and the ``width`` to fit, a table wider than that gets its column
    widths here: each column its narrowest, then the room left shared out, the columns
    that need least first (rich's own sharing narrows the widest column below the words
    it holds, and the table then overflows and is cropped)."""
    from rich.cells import cell_len
    from rich.text import Text

    for column in table.columns:
        column.overflow = "fold"
        texts = [c.plain if isinstance(c, Text) else c for c in column.cells
                 if isinstance(c, str | Text)]
        words = [w for t in [*texts, str(column.header)] for w in t.split()]
        widest = max((cell_len(w) for w in words), default=0)
        if column.justify == "right":
            widest = max([widest, *(cell_len(t) for t in texts)])
        column.min_width = max(column.min_width or 0, widest)
    if console is not None and width is not None:
        _share_width(table, console, width)


def _share_width(table: Any, console: Any, width: int) -> None:
    from rich.measure import Measurement

    wide = console.options.update(width=1 << 16)
    if any(c.width is not None for c in table.columns):
        return  # widths chosen by the command
    whole = Measurement.get(console, wide, table).maximum
    if whole <= width:
        return  # fits as it is (most tables: no cell measured one by one)
    most = [
        max(Measurement.get(console, wide, cell).maximum for cell in (c.header, *c.cells))
        for c in table.columns
    ]
    least = [min(c.min_width or 0, m) for c, m in zip(table.columns, most, strict=True)]
    extra = whole - sum(most)  # padding, rules
    room = width - extra - sum(least)
    if room < 0:
        return  # cannot fit, and is printed whole, wider
    given = list(least)
    wanting = sorted(range(len(most)), key=lambda i: most[i] - least[i])
    for n, i in enumerate(wanting):
        share = min(most[i] - least[i], room // (len(wanting) - n))
        given[i] += share
        room -= share
    for column, w in zip(table.columns, given, strict=True):
        column.width = w


def data_table(title: str | None = None) -> Any:
    """A table of data as every command prints it: a rule under the header, no frame, two
    spaces between columns (80 columns hold seven or eight of them); a title, if any, on
    the line above, left."""
    from rich import box
    from rich.table import Table

    return Table(
        title=title,
        title_justify="left",
        box=box.SIMPLE_HEAD,
        show_edge=False,
        pad_edge=False,
        collapse_padding=True,
    )


def say(console: Any, text: Any, *, hang: int = 2) -> None:
    """Print a paragraph (a ``str``, or a rich ``Text`` for colour) wrapped between words
    at the console's width, continuation lines indented by ``hang``. A word is never split:
    a word wider than the line (a long file path) gets a line of its own."""
    from rich.cells import cell_len
    from rich.text import Text

    from lolacli.cli.plain import breaks as fill_breaks

    text = text if isinstance(text, Text) else Text(str(text))
    for paragraph in text.split("\n"):
        breaks = fill_breaks(paragraph.plain, console.width, hang, cell_len)
        for i, line in enumerate(paragraph.divide(breaks)):
            line.rstrip()
            console.print(Text(" " * hang) + line if i else line, soft_wrap=True, crop=False)


def break_long_words(text: str, width: int, after: str = ".") -> str:
    """``text`` with each word wider than ``width`` broken into lines after an ``after``
    character (``SyncUnits.<default>.<unreferenced>.WcState.WcState`` into
    ``SyncUnits.<default>.`` and ``<unreferenced>.WcState.WcState``), so that a table cell
    can wrap it; a word with no such place stays whole."""
    import re

    from rich.cells import cell_len

    def pieces(word: str) -> str:
        if cell_len(word) <= width:
            return word
        lines, line = [], ""
        for part in re.findall(rf"[^{re.escape(after)}]*[{re.escape(after)}]?", word):
            if line and cell_len(line + part) > width:
                lines.append(line)
                line = ""
            line += part
        return "\n".join([*lines, line] if line else lines)

    return " ".join(pieces(w) for w in text.split(" "))


def stderr_console() -> Any:
    from rich.console import Console

    return Console(stderr=True, highlight=False, emoji=False)


def text_width() -> int:
    """The width human output fits: the terminal's, ``$COLUMNS``, else 80 (piped)."""
    import shutil

    return max(40, shutil.get_terminal_size((80, 24)).columns)


def wrapped(text: str, indent: str = "    ") -> list[str]:
    """A line of human output fitted to :func:`text_width`: broken between words,
    continuation lines indented; a word longer than a line (a path) is kept whole."""
    import textwrap

    return textwrap.wrap(
        text,
        text_width(),
        subsequent_indent=indent,
        break_on_hyphens=False,
        break_long_words=False,
    ) or [""]


def write_wrapped(stream: Any, text: str) -> None:
    stream.write("".join(f"{line}\n" for line in wrapped(text)))


def warn(message: str) -> None:
    write_wrapped(sys.stderr, f"lolacli: {message}")


def debug_enabled() -> bool:
    return os.environ.get("LOLACLI_DEBUG", "") not in ("", "0")
