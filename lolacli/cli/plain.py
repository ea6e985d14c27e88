"""Human output as plain lines of text: prose filled between words and tables in the look
of :func:`lolacli.cli.common.data_table` (a title, a header, a rule, columns two spaces
apart, names wrapped between words, numbers never cut), without rich.

``capture analyze`` renders its report with these: importing and running rich's layout
cost about 50 ms of a 180 ms run on a small capture, for output with no colour. The
width rule is the one of :mod:`lolacli.cli.common` (the terminal, ``$COLUMNS``, else 80
columns); a table that cannot fit is laid out as at 80 columns, or printed whole,
wider, when it cannot fit those either, never cropped. On a terminal
titles are italic and headers bold, as rich prints them (``NO_COLOR`` turns that off).
"""

from __future__ import annotations

import os
import sys
import unicodedata
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable


def cells(text: str) -> int:
    """Columns ``text`` takes on a terminal: wide East Asian characters two, combining
    marks none."""
    if text.isascii():
        return len(text)
    n = 0
    for ch in text:
        if unicodedata.combining(ch):
            continue
        n += 2 if unicodedata.east_asian_width(ch) in "WF" else 1
    return n


KEEP = "\xa0"  # a space a line never breaks at, printed as a space


def keep(text: str) -> str:
    """``text`` as one unit a line never breaks (``0x03E9 (1001)``)."""
    return text.replace(" ", KEEP)


def _words(text: str) -> list[str]:
    return text.replace(KEEP, "\0").split()


def breaks(plain: str, width: int, hang: int, measure: Callable[[str], int] = cells) -> list[int]:
    """Offsets of the words that start a new line when ``plain`` (one paragraph) is filled
    greedily at ``width``, continuation lines indented by ``hang``. A word is never split;
    a last line of one word takes one more from the line above when that fits."""
    out: list[int] = []
    starts: list[int] = []  # where each word starts
    start, room, i, n = 0, width, 0, len(plain)
    while i < n:
        while i < n and plain[i].isspace() and plain[i] != KEEP:
            i += 1
        if i >= n:
            break
        j = i
        while j < n and not (plain[j].isspace() and plain[j] != KEEP):
            j += 1
        if i > start and measure(plain[start:j]) > room:
            out.append(i)
            start, room = i, width - hang
        starts.append(i)
        i = j
    if out and starts[-1] == out[-1]:  # a last line of one word: take one more
        before = [w for w in starts if w < out[-1]]
        earlier = out[-2] if len(out) > 1 else 0
        if len(before) > 1 and before[-1] > earlier:
            tail = plain[before[-1] :].rstrip()
            if measure(tail) <= width - hang:
                out[-1] = before[-1]
    return out


def fill(text: str, width: int, hang: int = 0) -> list[str]:
    """``text`` as lines of at most ``width`` columns (a word wider than that alone on its
    line), continuation lines indented by ``hang``; each ``\\n`` starts a new line."""
    lines: list[str] = []
    for paragraph in text.split("\n"):
        cuts = [0, *breaks(paragraph, width, hang), len(paragraph)]
        for k in range(len(cuts) - 1):
            line = paragraph[cuts[k] : cuts[k + 1]].rstrip()
            lines.append(" " * hang + line if k else line)
    return [line.replace(KEEP, " ") for line in lines] if KEEP in text else lines


def styled() -> bool:
    """Whether stdout takes bold and italic (a terminal, no ``NO_COLOR``, not dumb)."""
    return (sys.stdout.isatty() and "NO_COLOR" not in os.environ
            and os.environ.get("TERM") != "dumb")


#: a table that cannot fit a narrower width is laid out at this one, as it would be on
#: an 80-column terminal, rather than at its natural width (which may be wider)
NARROWEST_FALLBACK = 80


class Table:
    """Rows of text cells; :meth:`lines` lays them out at a width.

    Right-aligned (number) columns are never narrower than their widest cell; the others
    wrap between words, a word never split. A table wider than the width gets each
    column its narrowest, then the room left shared out, the columns that need least
    first. One that cannot fit even so is laid out as at 80 columns, or, when it cannot
    fit those either, at its natural width."""

    GAP = "  "

    def __init__(self, title: str | None = None, *, header: bool = True) -> None:
        self.title = title
        self.header = header
        self.heads: list[str] = []
        self.right: list[bool] = []
        self.rows: list[tuple[str, ...]] = []

    def add_column(self, head: str = "", *, right: bool = False) -> None:
        self.heads.append(head)
        self.right.append(right)

    def add_row(self, *row: str) -> None:
        if len(row) != len(self.heads):
            raise ValueError(f"a row of {len(row)} cells in a table of {len(self.heads)}")
        self.rows.append(row)

    def _widths(self, width: int) -> list[int]:
        body = [*self.rows, tuple(self.heads)] if self.header else self.rows
        most = [max((cells(p) for r in body for p in r[c].split("\n")), default=0)
                for c in range(len(self.heads))]
        least = [most[c] if right else max((cells(w) for r in body for w in _words(r[c])),
                                           default=0)
                 for c, right in enumerate(self.right)]
        room = width - 1 - len(self.GAP) * (len(most) - 1)
        if sum(most) <= room or sum(least) > room:
            return most  # fits as it is, or cannot fit at all: printed whole
        given, room = list(least), room - sum(least)
        wanting = sorted(range(len(most)), key=lambda i: most[i] - least[i])
        for k, i in enumerate(wanting):
            share = min(most[i] - least[i], room // (len(wanting) - k))
            given[i] += share
            room -= share
        return given

    def lines(self, width: int) -> list[str]:
        widths = self._widths(width)
        if width < NARROWEST_FALLBACK and self._span(widths) > NARROWEST_FALLBACK:
            widths = self._widths(NARROWEST_FALLBACK)  # never wider than at 80 columns
        span = self._span(widths)
        bold, italic, plain = ("\x1b[1m", "\x1b[3m", "\x1b[0m") if styled() else ("",) * 3
        out = [f"{italic}{t}{plain}" for t in fill(self.title, width)] if self.title else []
        if self.header:
            out += [f"{bold}{line}{plain}" if line.strip() else line
                    for line in self._row(self.heads, widths)]
            out.append("─" * span)
        for row in self.rows:
            out += self._row(row, widths)
        return out

    def _span(self, widths: list[int]) -> int:
        return 1 + sum(widths) + len(self.GAP) * (len(widths) - 1)

    def _row(self, row: tuple[str, ...] | list[str], widths: list[int]) -> list[str]:
        cols = [fill(cell, w) if cells(cell) > w or "\n" in cell else [cell.replace(KEEP, " ")]
                for cell, w in zip(row, widths, strict=True)]
        out = []
        for k in range(max(len(c) for c in cols)):
            parts = []
            for c, w, right in zip(cols, widths, self.right, strict=True):
                text = c[k] if k < len(c) else ""
                pad = " " * (w - cells(text))
                parts.append(pad + text if right else text + pad)
            out.append((" " + self.GAP.join(parts)).rstrip())
        return out


def write(lines: list[str]) -> None:
    """Print ``lines`` to stdout; a reader that went away (``| head``) silences the rest."""
    try:
        sys.stdout.write("".join(f"{line}\n" for line in lines))
        sys.stdout.flush()
    except BrokenPipeError:
        from lolacli.cli.common import silence_stdout

        silence_stdout()
