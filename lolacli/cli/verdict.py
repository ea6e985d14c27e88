"""Human form of a verdict and its findings (the one Finding model), for every command
that gives one: a ``Verdict: FAIL (1 failure, 2 warnings)`` line, then one entry per
finding — its severity, kind and message wrapped to the console's width, and where it
shows (frames of a capture, cycles of a simulation, the slave)."""

from __future__ import annotations

from typing import Any

from lolacli.text import plural

_LABEL = {"failure": "FAIL", "warning": "WARN", "info": "info"}
_NOUN = {"failure": "failure", "warning": "warning", "info": "note"}


def render_verdict(
    console: Any, verdict: str, findings: list[dict[str, Any]], note: str = ""
) -> None:
    """``findings`` as :meth:`lolacli.findings.Finding.to_dict` gives them; ``note`` ends
    the verdict's line (", of the part read before the stop")."""
    from rich.table import Table
    from rich.text import Text

    from lolacli.cli.common import say

    counts = {s: sum(1 for f in findings if f["severity"] == s) for s in _LABEL}
    parts = [plural(n, _NOUN[s]) for s, n in counts.items() if n]
    say(console, f"Verdict: {verdict.upper()}" + (f" ({', '.join(parts)})" if parts else "")
        + note)
    if not findings:
        return
    grid = Table.grid(padding=(0, 1))
    grid.add_column(no_wrap=True)
    grid.add_column(overflow="fold")
    for f in findings:
        grid.add_row(_LABEL.get(f["severity"], f["severity"]),
                     Text(f"{f['kind']}: {f['message']}" + _where(f)))
    console.print(grid, width=min(console.width, 80) if console.width else 80)


def _where(f: dict[str, Any]) -> str:
    out = ""
    for key, noun in (("frames", "frame"), ("cycles", "cycle")):
        numbers = f.get(key) or []
        if not numbers:
            continue
        listed = ", ".join(str(n) for n in numbers)
        if f.get("count", 0) > len(numbers):
            out += f"\nfirst {noun}s {listed} (of {f['count']})"
        else:
            out += f"\n{noun}{'s' if len(numbers) > 1 else ''} {listed}"
    return out


__all__ = ["render_verdict"]
