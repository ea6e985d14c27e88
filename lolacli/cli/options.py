"""Command-line options that several commands share, each defined once here: the same
flag, type, bounds and help text wherever it appears. A command's own options stay in its
module.

Checks a range cannot express go in ``callback=``: :func:`not_nan` for bounded numbers
(typer's range types let ``nan`` through, as every comparison with it is false).
"""

from __future__ import annotations

import typer


def not_nan(value: float | None) -> float | None:
    """A bounded float option's value, refused when it is not a number (``nan``)."""
    if value is not None and value != value:
        raise typer.BadParameter(f"{value} is not a number")
    return value
