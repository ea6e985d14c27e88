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
    """Print :func:`verdict_lines` with a rich ``console``, at its width (80 at most)."""
    width = min(console.width, 80) if console.width else 80
    for line in verdict_lines(verdict, findings, note, width):
        console.print(line, markup=False, soft_wrap=True, crop=False)


def verdict_lines(
    verdict: str, findings: list[dict[str, Any]], note: str = "", width: int = 80
) -> list[str]:
    """``findings`` as :meth:`lolacli.findings.Finding.to_dict` gives them; ``note`` ends
    the verdict's line (", of the part read before the stop"). Each finding's text wraps
    between words beside its severity."""
    from lolacli.cli.plain import fill

    counts = {s: sum(1 for f in findings if f["severity"] == s) for s in _LABEL}
    parts = [plural(n, _NOUN[s]) for s, n in counts.items() if n]
    lines = fill(f"Verdict: {verdict.upper()}" + (f" ({', '.join(parts)})" if parts else "")
                 + note, width, hang=2)
    labels = [_LABEL.get(f["severity"], f["severity"]) for f in findings]
    hang = max((len(label) for label in labels), default=0) + 1
    for label, f in zip(labels, findings, strict=True):
        text = fill(f"{f['kind']}: {f['message']}" + _where(f), width - hang)
        lines.append(f"{label:<{hang - 1}} {text[0]}")
        lines += [" " * hang + line for line in text[1:]]
    return lines


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


__all__ = ["render_verdict", "verdict_lines"]
