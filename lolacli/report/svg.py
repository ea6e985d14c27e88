"""The HTML report's figures as inline SVG, drawn here rather than by matplotlib.

Why, measured on the 2-core development host under the load of a shared machine: `bus
simulate` (10 s at 2 kHz) took 1.7 s; importing matplotlib took 0.5-0.9 s and its five
PNG figures 1.6 s more, so `report --simulate` took 2.5× the simulation, against a budget
of 2×. These figures cost a few tens of milliseconds, need no import, scale with the page
(viewBox, width 100%) and keep the HTML small. The Markdown report's PNG files still come
from matplotlib (:mod:`lolacli.report.plots`).
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

W, H = 720, 300
LEFT, RIGHT, TOP, BOTTOM = 70, 16, 30, 46
COLOURS = ("#2e86de", "#e67e22", "#27ae60", "#8e44ad", "#c0392b", "#16a085")
#: points per drawn line at most (a longer series: the min and max of equal slices)
MAX_POINTS = 2000


@dataclass(frozen=True, slots=True)
class Series:
    label: str
    x: Any  # numpy arrays
    y: Any
    kind: str = "line"  # "line" | "bars" (x: left edges, one more than y)


def ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About ``n`` round values (1, 2, 5 × 10^k) covering [lo, hi]."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return []
    if hi <= lo:
        hi = lo + (abs(lo) or 1.0)
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    first = math.ceil(lo / step) * step
    return [first + i * step for i in range(int((hi - first) / step + 1e-9) + 1)]


def log_ticks(lo: float, hi: float) -> list[float]:
    """Round values (1, 2, 5 × 10^k; only the decades over a wide range) in [lo, hi] > 0."""
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo <= 0 or hi <= lo:
        return []
    out: list[float] = []
    for steps in ((1, 2, 5), (1,)):
        out = [m * 10.0**k for k in range(math.floor(math.log10(lo)),
                                          math.ceil(math.log10(hi)) + 1)
               for m in steps if lo * (1 - 1e-9) <= m * 10.0**k <= hi * (1 + 1e-9)]
        if len(out) <= 10:
            break
    return out


def fmt_tick(v: float) -> str:
    """A tick's label: a short number."""
    if v == 0:
        return "0"
    if abs(v) >= 1e7 or abs(v) < 0.01:
        return f"{v:.3g}"
    return f"{v:,.6g}"


def thin(x: Any, y: Any) -> tuple[Any, Any]:
    """At most :data:`MAX_POINTS` points: the min and max of equal slices (spikes stay)."""
    import numpy as np

    if y.size <= MAX_POINTS:
        return x, y
    edges = np.linspace(0, y.size, MAX_POINTS // 2 + 1).astype(np.int64)[:-1]
    lo, hi = np.minimum.reduceat(y, edges), np.maximum.reduceat(y, edges)
    return np.repeat(x[edges], 2), np.column_stack([lo, hi]).ravel()


def chart(title: str, xlabel: str, ylabel: str, series: Sequence[Series],
          vline: float | None = None, *, hline: float | None = None,
          logx: bool = False) -> str:
    """One x/y chart: lines or histogram bars, axes with round ticks, a legend when there
    is more than one series; dashed lines at x = ``vline`` and y = ``hline``; ``logx``: a
    logarithmic x axis (x > 0)."""
    import numpy as np

    if logx:  # draw log10(x), label the ticks with x
        series = [Series(s.label, np.log10(np.asarray(s.x, dtype=np.float64)), s.y, s.kind)
                  for s in series]
        vline = math.log10(vline) if vline is not None and vline > 0 else None
    xs = np.concatenate([np.asarray(s.x, dtype=np.float64) for s in series])
    ys = np.concatenate([np.asarray(s.y, dtype=np.float64) for s in series])
    x0, x1 = float(xs.min()), float(xs.max())
    y0 = min(0.0, float(ys.min())) if any(s.kind == "bars" for s in series) else float(ys.min())
    y1 = float(ys.max())
    if x1 <= x0:
        x0, x1 = x0 - 1.0, x1 + 1.0
    if hline is not None:
        y0, y1 = min(y0, hline), max(y1, hline)
    if y1 <= y0:
        y0, y1 = y0 - 1.0, y1 + 1.0
    pad = (y1 - y0) * 0.05
    y0, y1 = (y0 if y0 == 0 else y0 - pad), y1 + pad
    pw, ph = W - LEFT - RIGHT, H - TOP - BOTTOM

    def px(v: Any) -> Any:
        return LEFT + (v - x0) / (x1 - x0) * pw

    def py(v: Any) -> Any:
        return TOP + ph - (v - y0) / (y1 - y0) * ph

    e = html.escape
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {H}" role="img" '
           f'aria-label="{e(title)}" class="chart">',
           f'<text x="{W / 2}" y="18" text-anchor="middle" class="t">{e(title)}</text>']
    xticks = [(math.log10(t), t) for t in log_ticks(10**x0, 10**x1)] if logx else [
        (t, t) for t in ticks(x0, x1)]
    for t, shown in xticks:
        x = px(t)
        out.append(f'<line x1="{x:.1f}" y1="{TOP}" x2="{x:.1f}" y2="{TOP + ph}" class="g"/>'
                   f'<text x="{x:.1f}" y="{TOP + ph + 16}" text-anchor="middle">'
                   f"{fmt_tick(shown)}</text>")
    for t in ticks(y0, y1):
        y = py(t)
        out.append(f'<line x1="{LEFT}" y1="{y:.1f}" x2="{LEFT + pw}" y2="{y:.1f}" class="g"/>'
                   f'<text x="{LEFT - 6}" y="{y + 4:.1f}" text-anchor="end">{fmt_tick(t)}</text>')
    out.append(f'<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" class="frame"/>')
    out.append(f'<text x="{LEFT + pw / 2}" y="{H - 8}" text-anchor="middle">{e(xlabel)}</text>')
    out.append(f'<text transform="translate(16 {TOP + ph / 2}) rotate(-90)" '
               f'text-anchor="middle">{e(ylabel)}</text>')
    many = len(series) > 1
    for i, s in enumerate(series):
        colour = COLOURS[i % len(COLOURS)]
        if s.kind == "bars":
            left, right, top = px(s.x[:-1]), px(s.x[1:]), py(s.y)
            base = py(max(y0, 0.0))
            opacity = ' fill-opacity="0.55"' if many else ""
            out.append(f'<g fill="{colour}"{opacity}>' + "".join(
                f'<rect x="{a:.1f}" y="{t:.1f}" width="{max(b - a, 0.5):.1f}" '
                f'height="{base - t:.1f}"/>'
                for a, b, t, n in zip(left, right, top, s.y, strict=True) if n > 0) + "</g>")
        else:
            x, y = thin(np.asarray(s.x, dtype=np.float64), np.asarray(s.y, dtype=np.float64))
            points = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(px(x), py(y), strict=True))
            out.append(f'<polyline fill="none" stroke="{colour}" stroke-width="1.2" '
                       f'points="{points}"/>')
    if vline is not None and x0 <= vline <= x1:
        x = px(vline)
        out.append(f'<line x1="{x:.1f}" y1="{TOP}" x2="{x:.1f}" y2="{TOP + ph}" '
                   'stroke="#555" stroke-dasharray="4 3" class="vline"/>')
    if hline is not None:
        y = py(hline)
        out.append(f'<line x1="{LEFT}" y1="{y:.1f}" x2="{LEFT + pw}" y2="{y:.1f}" '
                   'stroke="#555" stroke-dasharray="4 3" class="hline"/>')
    if many:
        for i, s in enumerate(series):
            y = TOP + 14 + 16 * i
            out.append(f'<rect x="{LEFT + pw - 215}" y="{y - 9}" width="10" height="10" '
                       f'fill="{COLOURS[i % len(COLOURS)]}"/><text x="{LEFT + pw - 200}" '
                       f'y="{y}">{e(s.label[:28])}</text>')
    out.append("</svg>")
    return "".join(out)


def hbars(title: str, xlabel: str, names: Sequence[str],
          bars: Sequence[tuple[str, Sequence[float]]]) -> str:
    """Horizontal bars, one row per name; ``bars``: (label, values) drawn over each
    other, the first behind (e.g. p99 behind mean)."""
    e = html.escape
    rows = len(names)
    row_h = 24
    height = TOP + rows * row_h + BOTTOM
    hi = max((v for _, values in bars for v in values), default=1.0) or 1.0
    ts = ticks(0.0, hi)
    x1 = max(hi, ts[-1] if ts else hi)
    left = 90
    pw = W - left - RIGHT

    def px(v: float) -> float:
        return left + v / x1 * pw

    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {height}" role="img" '
           f'aria-label="{e(title)}" class="chart">',
           f'<text x="{W / 2}" y="18" text-anchor="middle" class="t">{e(title)}</text>']
    bottom = TOP + rows * row_h
    for t in ts:
        out.append(f'<line x1="{px(t):.1f}" y1="{TOP}" x2="{px(t):.1f}" y2="{bottom}" '
                   f'class="g"/><text x="{px(t):.1f}" y="{bottom + 16}" '
                   f'text-anchor="middle">{fmt_tick(t)}</text>')
    for i, name in enumerate(names):
        y = TOP + i * row_h
        out.append(f'<text x="{left - 6}" y="{y + 16}" text-anchor="end">{e(name)}</text>')
        for j, (_label, values) in enumerate(bars):
            colour = ("#c8d6e5", "#2e86de")[j % 2]
            out.append(f'<rect x="{left}" y="{y + 4}" width="{max(px(values[i]) - left, 0.5):.1f}"'
                       f' height="{row_h - 8}" fill="{colour}"/>')
    out.append(f'<text x="{left + pw / 2}" y="{height - 8}" text-anchor="middle">'
               f"{e(xlabel)}</text>")
    for j, (label, _values) in enumerate(bars):
        x = W - RIGHT - 130 + 65 * j
        out.append(f'<rect x="{x}" y="{height - 18}" width="10" height="10" '
                   f'fill="{("#c8d6e5", "#2e86de")[j % 2]}"/>'
                   f'<text x="{x + 14}" y="{height - 9}">{e(label)}</text>')
    out.append("</svg>")
    return "".join(out)
