"""``lolacli capture analyze A B C …`` (or a folder): many captures in one process.

CI scripts analyse many small captures; one process per file pays the start-up (imports,
0.2-0.3 s) each time for a few milliseconds of work (issue 28). Here each file is
analysed once, in one process, ``--jobs`` at a time (threads: the C scanner releases
the GIL while it walks a file), and the results come out in the order of the arguments.

Output, one of:

* ``--format json``: JSON lines, one document per file, ``lolacli.capture-batch/1``::

      {"schema": "lolacli.capture-batch/1", "file": "a.pcapng", "exit_code": 0,
       "error": null, "report": { …the lolacli.capture/1 document of the file… }}

  ``exit_code`` is what ``capture analyze`` of that file alone exits with (0 pass, 1 a
  failure finding, 3 unreadable: then ``error`` is the one-line message and ``report``
  null). The single-file command keeps its ``lolacli.capture/1`` document unchanged.
* human: one table, a row per file (frames, verdict, round trip and cycle period
  medians, lost frames, WKC mismatches; verdict "error" for a file that cannot be
  read, its message on stderr).

The command exits with the worst file's code (3 over 1 over 0); a stop (Ctrl-C,
SIGTERM) prints the files done so far, the file being analysed with its partial report
(``interrupted``), and exits 130/143.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from lolacli.errors import LolaError, UsageError

SCHEMA = "lolacli.capture-batch/1"
#: the files a folder argument stands for (not recursive)
SUFFIXES = (".pcap", ".pcapng", ".cap")
#: the file column's width in the human table (80 columns in all)
NAME_WIDTH = 16


def expand(args: list[Path]) -> list[Path]:
    """The files of the arguments: a folder stands for its captures, by name."""
    out: list[Path] = []
    for arg in args:
        if arg.is_dir():
            found = sorted(p for p in arg.iterdir()
                           if p.suffix.lower() in SUFFIXES and not p.is_dir())
            if not found:
                raise UsageError(f"{arg}: no {', '.join(SUFFIXES)} files in this folder")
            out.extend(found)
        else:
            out.append(arg)
    return out


def analyze_batch(files: list[Path], *, json_lines: bool, eni: Any, engine: str,
                  timeout_ns: int | None, max_lost: int, max_wkc: int,
                  jobs: int | None) -> int:
    """Analyse every file; print a JSON line per file or one table; return the exit
    code (the worst file's, or 130/143 when stopped)."""
    from concurrent.futures import ThreadPoolExecutor

    from lolacli.capture.analyze import analyze_file
    from lolacli.capture.fast import choose_engine, fallback_note
    from lolacli.interrupt import stop_signals

    paths = expand(files)
    choose_engine(engine)  # a usage error before any file; loads the C scanner here
    workers = max(1, min(jobs or os.cpu_count() or 1, len(paths)))
    rows: list[dict[str, Any]] = []
    worst = 0

    with stop_signals() as stop, stop.polled():
        def one(path: Path) -> dict[str, Any]:
            if stop():
                return {"file": str(path), "exit_code": None, "error": "not analysed: stopped",
                        "report": None}
            try:
                rep = analyze_file(path, eni=eni, engine=engine, timeout_ns=timeout_ns,
                                   max_lost=max_lost, max_wkc_mismatches=max_wkc,
                                   should_stop=stop)
            except LolaError as exc:
                return {"file": str(path), "exit_code": exc.exit_code, "error": str(exc),
                        "report": None}
            return {"file": str(path), "exit_code": 1 if rep.failed else 0, "error": None,
                    "report": rep.to_dict()}

        with ThreadPoolExecutor(max_workers=workers) as pool:
            for row in pool.map(one, paths):  # in the order of the arguments
                if row["exit_code"] is None:
                    continue  # not started before the stop
                worst = max(worst, row["exit_code"])
                if json_lines:
                    _line(row)
                else:
                    rows.append(row)
                    if row["error"] is not None:
                        sys.stderr.write(f"lolacli: error: {row['error']}\n")
    if (note := fallback_note()) is not None:
        sys.stderr.write(note + "\n")
    if not json_lines:
        _table(rows)
    if stop():
        done = sum(1 for r in rows) if not json_lines else None
        what = f" after {done} of {len(paths)} files" if done is not None else ""
        sys.stderr.write(f"lolacli: stopped{what}; the files not analysed are left out\n")
        return stop.exit_code
    return worst


def _line(row: dict[str, Any]) -> None:
    from lolacli.cli.common import json_text, silence_stdout

    try:
        sys.stdout.write(json_text({"schema": SCHEMA, **row}, indent=False) + "\n")
        sys.stdout.flush()
    except BrokenPipeError:
        silence_stdout()


def _median(doc: dict[str, Any], key: str) -> str:
    """The median, or "unusable" where the report says so (quantised or backward
    timestamps: the single-file report marks the same figure)."""
    from lolacli.text import number

    stats = doc.get(key)
    if not stats:
        return "–"
    if key in doc.get("unusable_stats", ()):
        return "unusable"
    return number(stats["median"], "µs", 1)


def _breakable(name: str, width: int = NAME_WIDTH) -> str:
    """A file name in lines of at most ``width`` characters, broken after ``-``, ``_`` or
    ``.`` where it can (the table wraps between words only, and names have no spaces)."""
    import re

    lines, line = [], ""
    for part in re.findall(r"[^-_.]*[-_.]?", name):
        while len(part) > width:  # no break in sight: cut
            if line:
                lines.append(line)
                line = ""
            lines.append(part[:width])
            part = part[width:]
        if len(line) + len(part) > width:
            lines.append(line)
            line = ""
        line += part
    return "\n".join([*lines, line] if line else lines)


def _table(rows: list[dict[str, Any]]) -> None:
    from lolacli.cli.common import text_width
    from lolacli.cli.plain import Table, fill, write
    from lolacli.text import plural

    table = Table(None)
    table.add_column("File")
    for name in ("Frames", "Verdict", "Round trip", "Cycle", "Lost",
                 "WKC errors"):
        table.add_column(name, right=name != "Verdict")
    for row in rows:
        doc = row["report"]
        name = _breakable(Path(row["file"]).name)
        if doc is None:
            table.add_row(name, "–", "error", "–", "–", "–", "–")
            continue
        verdict = doc["verdict"] + (" (stopped)" if doc["interrupted"] else "")
        table.add_row(name, f"{doc['frames_total']:,}", verdict,
                      _median(doc, "round_trip_us"), _median(doc, "cycle_period_us"),
                      f"{doc['lost_frames']:,}", f"{doc['wkc_mismatches']:,}")
    failed = sum(1 for r in rows if r["exit_code"])
    width = text_width()
    write([*table.lines(width), *fill(
        f"{plural(len(rows), 'capture')}, {failed} not passing; round trip and cycle "
        "period: medians", width)])
