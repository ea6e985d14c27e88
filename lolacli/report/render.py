"""The report as one self-contained HTML page (figures as PNG data URIs, CSS inline, no
request leaves it; it reads on a 1280 px laptop and a 390 px phone) or as Markdown with
its PNGs beside it (CI artifacts, job summaries)."""

from __future__ import annotations

import base64
import html
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from lolacli.report.model import Report, Table
    from lolacli.report.plots import Figure

CSS = """
:root { color-scheme: light; --fg: #1d2733; --muted: #5b6878; --line: #d8dee6;
  --pass: #1e7d32; --fail: #b3261e; --warn: #a15c00; }
* { box-sizing: border-box; }
body { font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif;
  color: var(--fg); margin: 0 auto; padding: 16px; max-width: 1100px; }
h1 { font-size: 1.5em; margin: 0 0 .2em; }
h2 { font-size: 1.25em; margin: 1.6em 0 .4em; border-bottom: 1px solid var(--line); }
nav { display: flex; flex-wrap: wrap; gap: .3em 1em; margin: .6em 0 1em; }
nav a { color: #1a5fb4; }
p.meta { color: var(--muted); margin: 0; overflow-wrap: anywhere; }
.badge { display: inline-block; padding: .1em .6em; border-radius: 4px; color: #fff;
  font-weight: 600; }
.pass { background: var(--pass); } .fail { background: var(--fail); }
.scroll { overflow-x: auto; margin: .6em 0 1em; }
table { border-collapse: collapse; font-size: .92em; min-width: 60%; }
caption { text-align: left; font-weight: 600; padding: .2em 0; }
th, td { border-bottom: 1px solid var(--line); padding: .25em .6em; text-align: left;
  vertical-align: top; }
th { background: #f3f5f8; }
td.failure { color: var(--fail); font-weight: 600; } td.warning { color: var(--warn); }
figure { margin: .8em 0 1.2em; }
figure img, figure svg { width: 100%; max-width: 760px; height: auto; display: block; }
svg.chart { font-size: 12px; fill: var(--fg); }
svg.chart .t { font-weight: 600; font-size: 13px; }
svg.chart .g { stroke: #e3e7ec; } svg.chart .frame { fill: none; stroke: #9aa5b1; }
figcaption { color: var(--muted); font-size: .9em; }
@media (max-width: 600px) { body { padding: 10px; font-size: 14px; }
  th, td { padding: .2em .35em; } }
"""


def to_html(report: Report, figures: list[Figure], title: str) -> str:
    e = html.escape
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        # nothing but what the page holds: no request may leave it
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; "
        "img-src data:; style-src 'unsafe-inline'\">",
        f"<title>{e(title)}</title><style>{CSS}</style></head><body>",
        f"<h1>{e(title)}</h1>",
        f'<p class="meta">{e(_inputs_line(report))}</p>',
        "<nav>" + "".join(f'<a href="#{s.id}">{e(s.title)}</a>' for s in report.sections)
        + "</nav>",
    ]
    for section in report.sections:
        parts.append(f'<section id="{section.id}"><h2>{e(section.title)}</h2>')
        if section.id == "verdict":
            cls = "pass" if report.verdict == "pass" else "fail"
            parts.append(f'<p><span class="badge {cls}">{e(report.verdict.upper())}</span> '
                         f"{e(section.intro.split(': ', 1)[-1])}</p>")
            for note in report.notes:
                parts.append(f'<p class="meta">{e(note)}</p>')
        elif section.intro:
            parts.append(f"<p>{e(section.intro)}</p>")
        for table in section.tables:
            parts.append(_html_table(table, section.id == "verdict"))
        for f in figures:
            if f.section != section.id:
                continue
            if f.svg:
                parts.append(f"<figure>{f.svg}</figure>")
            else:
                data = base64.b64encode(f.png).decode("ascii")
                parts.append(f'<figure><img alt="{e(f.title)}" src="data:image/png;base64,'
                             f'{data}"><figcaption>{e(f.title)}</figcaption></figure>')
        parts.append("</section>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


def _html_table(table: Table, link_last: bool) -> str:
    e = html.escape
    out = ['<div class="scroll"><table>']
    if table.caption:
        out.append(f"<caption>{e(table.caption)}</caption>")
    if any(table.columns):  # a two-column list of name and value has no header
        out.append("<tr>" + "".join(f"<th>{e(c)}</th>" for c in table.columns) + "</tr>")
    for row in table.rows:
        cells = []
        for i, cell in enumerate(row):
            if link_last and i == len(row) - 1 and table.columns[-1] == "section":
                cells.append(f'<td><a href="#{e(cell)}">{e(cell)}</a></td>')
            elif link_last and i == 0 and cell in ("failure", "warning", "info"):
                cells.append(f'<td class="{cell}">{e(cell)}</td>')
            else:
                cells.append(f"<td>{e(cell)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table></div>")
    return "".join(out)


def _inputs_line(report: Report) -> str:
    i = report.inputs
    parts = []
    if i["eni"]:
        parts.append(f"ENI {i['eni']}")
    parts += [f"capture {c}" for c in i["captures"]]
    sim = i["simulation"]
    if sim:
        parts.append(f"simulation {sim['cycles']:,} cycles at {sim['rate_hz']:,g} Hz "
                     f"({sim['mode']})")
    parts += [f"{name} {i[key]}" for key, name in (("joint_track", "joint track"),
                                                   ("joint_bode", "joint bode")) if i.get(key)]
    return "; ".join(parts) or "no inputs"


def to_markdown(report: Report, figures: list[Figure], title: str,
                figure_names: dict[str, str]) -> str:
    """Markdown; ``figure_names`` maps each figure's name to the file written beside."""
    lines = [f"# {title}", "", _inputs_line(report), "",
             " · ".join(f"[{s.title}](#{s.id})" for s in report.sections), ""]
    for section in report.sections:
        lines += [f'<a id="{section.id}"></a>', "", f"## {section.title}", ""]
        if section.id == "verdict":
            lines += [f"**{report.verdict.upper()}** — {section.intro.split(': ', 1)[-1]}", ""]
            lines += [f"> {note}" for note in report.notes] + ([""] if report.notes else [])
        elif section.intro:
            lines += [section.intro, ""]
        for table in section.tables:
            lines += _md_table(table, section.id == "verdict")
        for f in figures:
            if f.section == section.id:
                lines += [f"![{f.title}]({figure_names[f.name]})", ""]
    return "\n".join(lines)


def _md_table(table: Table, link_last: bool) -> list[str]:
    def cell(text: str) -> str:
        return text.replace("|", "\\|").replace("\n", " ")

    out = [f"**{cell(table.caption)}**", ""] if table.caption else []
    out.append("| " + " | ".join(cell(c) or " " for c in table.columns) + " |")
    out.append("|" + "---|" * len(table.columns))
    for row in table.rows:
        cells = [cell(c) for c in row]
        if link_last and table.columns[-1] == "section":
            cells[-1] = f"[{cells[-1]}](#{cells[-1]})"
        out.append("| " + " | ".join(cells) + " |")
    return [*out, ""]

