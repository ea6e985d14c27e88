"""The plain-text layout (lolacli.cli.plain) that ``capture analyze`` prints with: prose
filled between words, tables fitted to the width without cutting a number or a word."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.cli.plain import Table, cells, fill, keep

WORDS = st.lists(st.text("abcdefghij(µ×—", min_size=1, max_size=14), min_size=1, max_size=40)


@given(WORDS, st.integers(8, 100), st.integers(0, 6))
@settings(max_examples=300, deadline=None)
def test_fill_keeps_every_word_whole_and_in_order(words, width, hang):
    lines = fill(" ".join(words), width, hang)
    assert " ".join(" ".join(lines).split()) == " ".join(words)
    for k, line in enumerate(lines):
        if k:
            assert line.startswith(" " * hang)
        # a line is over the width only when it holds one word wider than that
        if cells(line) > width:
            assert len(line.split()) == 1


def test_fill_hangs_and_takes_a_word_down_to_a_lonely_last_one():
    text = "one two three four five six seven eight nine ten eleven"
    assert fill(text, 20, 2) == [
        "one two three four", "  five six seven", "  eight nine", "  ten eleven"]
    assert fill("a b c d e f g h i j k l m n o p q r s t u v w x y z", 10) == [
        "a b c d e", "f g h i j", "k l m n o", "p q r s t", "u v w x", "y z"]


def test_a_kept_unit_is_never_broken_and_prints_with_spaces():
    text = f"AL status: PREOP {keep('0x03E9 (1001)')} and {keep('0x03EA (1002)')}"
    for width in range(10, 50):
        lines = fill(text, width)
        assert "\xa0" not in "".join(lines)
        assert any("0x03E9 (1001)" in line for line in lines)
        assert any("0x03EA (1002)" in line for line in lines)


def test_wide_characters_take_two_columns():
    assert cells("ab") == 2 and cells("µs") == 2 and cells("日本") == 4 and cells("e\u0301") == 1


def _table() -> Table:
    t = Table("Timing (µs), cyclic stream: signature of a long name")
    t.add_column("")
    for col in ("count", "min", "mean", "median", "std", "p99", "max"):
        t.add_column(col, right=True)
    t.add_row("cyclic round trip (unusable)", "276", "0.00", "12.5", "12.50", "1571.1",
              "27392", "28006")
    t.add_row("cycle period", "62", "19997", "24161", "24020", "1571.1", "27392", "280060")
    return t


def test_a_table_fits_by_wrapping_names_never_numbers():
    for width in (70, 80, 120):
        lines = _table().lines(width)
        assert max(cells(line) for line in lines) <= width, (width, lines)
        body = "\n".join(lines)
        for number in ("19997", "24161", "1571.1", "280060", "27392"):
            assert number in body  # never cut
        assert lines[2] == "─" * cells(lines[2]) and cells(lines[2]) <= width
    narrow = _table().lines(70)
    # (a last line of one word takes one more)
    assert narrow[3].startswith(" cyclic round ") and narrow[4].strip() == "trip (unusable)"


def test_a_table_that_cannot_fit_is_printed_whole_wider():
    t = _table()
    t.title = None
    t.add_row("x", "1", "2", "3", "4", "5", "6", "1234567890" * 9)  # no 80 columns hold it
    lines = t.lines(80)
    assert max(cells(line) for line in lines) > 80
    assert "cyclic round trip (unusable)" in "\n".join(lines)  # natural widths
    assert all(line == line.rstrip() for line in lines)  # no trailing spaces


def test_rows_must_match_the_columns():
    t = Table(None)
    t.add_column("a")
    try:
        t.add_row("1", "2")
    except ValueError as e:
        assert "2 cells" in str(e)
    else:
        raise AssertionError("a row of the wrong size was taken")


def test_headers_bold_and_titles_italic_only_on_a_terminal(monkeypatch):
    import io
    import sys

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.delenv("NO_COLOR", raising=False)
    monkeypatch.setenv("TERM", "xterm")
    monkeypatch.setattr(sys, "stdout", Tty())
    styled = _table().lines(80)
    assert styled[0].startswith("\x1b[3m") and styled[1].startswith("\x1b[1m")
    monkeypatch.setenv("NO_COLOR", "1")
    assert "\x1b" not in "".join(_table().lines(80))
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    monkeypatch.delenv("NO_COLOR")
    assert "\x1b" not in "".join(_table().lines(80))


def test_a_table_too_wide_for_a_narrow_terminal_is_laid_out_as_at_80_columns():
    t = _table()
    t.add_row("a name of many words that wraps " * 3, "1", "2", "3", "4", "5", "6", "7")
    natural = max(cells(line) for line in t.lines(400))
    assert natural > 80
    for width in (30, 40, 60):
        lines = t.lines(width)
        assert max(cells(line) for line in lines) <= 80, width  # not its natural width
        t.title = None
        assert t.lines(width) == t.lines(80)
        t.title = "Timing"
