"""Writing a report: the page (HTML, or Markdown with its PNGs) and its JSON beside it,
each file whole or not at all (written under a temporary name in the same folder, then
renamed; a failure or a stop part way removes what was not renamed yet)."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from lolacli.errors import InputError, UsageError

if TYPE_CHECKING:
    from lolacli.report.model import Report

FORMATS = ("html", "md")


def check_output(path: Path) -> None:
    """InputError (exit 3) when ``path`` cannot be written, UsageError (exit 2) when it
    is its own JSON's path: before any work is done."""
    if json_path(path) == path:
        raise UsageError(f"{path}: the page and its JSON would be the same file; name "
                         "the page .html or .md")
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise InputError("is a directory; give the report's file name", path=str(path))
    if not folder.is_dir():
        raise InputError("no such folder for the report", path=str(path))
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError("cannot write here: permission denied", path=str(path))


def json_path(path: Path) -> Path:
    """``report.html`` -> ``report.json`` beside it."""
    return path.with_suffix(".json")


def write_report(report: Report, path: Path, fmt: str = "html", title: str | None = None
                 ) -> list[Path]:
    """Render and write ``report`` to ``path`` (and its JSON, and for ``md`` the PNGs
    ``<stem>-<figure>.png``) beside it; returns the paths written, the page first."""
    from lolacli.report.plots import png_figures, svg_figures
    from lolacli.report.render import to_html, to_markdown

    check_output(path)
    title = title or "lolacli timing report"
    files: list[tuple[Path, bytes]] = []
    if fmt == "md":
        figs = png_figures(report)
        names = {f.name: f"{path.stem}-{f.name}.png" for f in figs}
        files.append((path, to_markdown(report, figs, title, names).encode()))
        files += [(path.with_name(names[f.name]), f.png) for f in figs]
    else:
        files.append((path, to_html(report, svg_figures(report), title).encode()))
    doc = json.dumps(report.to_dict(), indent=2, ensure_ascii=False, allow_nan=False)
    files.append((json_path(path), (doc + "\n").encode()))
    _write_all(files)
    return [p for p, _ in files]


def _write_all(files: list[tuple[Path, bytes]]) -> None:
    temps: list[tuple[str, Path]] = []
    try:
        for target, data in files:
            fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part",
                                       dir=target.parent)
            temps.append((tmp, target))
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.chmod(tmp, 0o666 & ~_umask())
        for tmp, target in temps:
            os.replace(tmp, target)
        temps.clear()
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}",
                         path=str(files[0][0])) from None
    finally:
        for tmp, _ in temps:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
