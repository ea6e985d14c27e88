"""`lolacli report`'s joint sections from real runs: a simulation that moved joints
(``--simulate --move``), ``joint track --format json`` (Table III, Fig. 9 with
``--series``) and ``joint bode --format json`` (Fig. 10). Each section present exactly when
its input is, its numbers those of the document, the page's tables and figures parsed;
the regression gate on the joints' headline figures; bad documents exit 3 in one line."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from lolacli.files import load_eni
from lolacli.report import build_report, load_joint_bode, load_joint_track, write_report
from lolacli.report.joints import BODE_SCHEMA, TRACK_SCHEMA, mrad
from lolacli.report.svg import log_ticks
from lolacli.simulate import options_from_cli, simulate

#: the joint commands' runs: one walking step, a 1 s chirp (about a second each)
TRACK_ARGS = ("joint", "track", "--steps", "1", "--format", "json")
BODE_ARGS = ("joint", "bode", "--duration", "1", "--format", "json")


def _run(*args: str) -> str:
    from typer.testing import CliRunner

    from lolacli.cli.main import app

    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.stderr
    return result.stdout


@pytest.fixture(scope="module")
def docs(tmp_path_factory) -> dict[str, Path]:
    """``joint track`` with and without --series and ``joint bode``, as their JSON files."""
    folder = tmp_path_factory.mktemp("joint-docs")
    out = {}
    for name, args in (("track", (*TRACK_ARGS, "--series")), ("track-plain", TRACK_ARGS),
                       ("bode", BODE_ARGS)):
        out[name] = folder / f"{name}.json"
        out[name].write_text(_run(*args))
    return out


@pytest.fixture(scope="module")
def moved():
    """The LOLA chain simulated for 0.5 s with the left hip pitch moved 20 000 increments."""
    eni = load_eni()
    return eni, simulate(eni, options_from_cli(duration="0.5s", moves=["3:20000"]))


def _json(path: Path) -> dict:
    return json.loads(path.read_text())


class _Page(HTMLParser):
    """Each section's tables (rows of cell texts) and figures (svg elements' tags)."""

    def __init__(self) -> None:
        super().__init__()
        self.sections: dict[str, dict] = {}
        self.current: dict | None = None
        self.row: list[str] | None = None
        self.cell: list[str] | None = None
        self.svg: list | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self.current = self.sections.setdefault(a["id"], {"tables": [], "svgs": []})
        elif self.current is None:
            return
        elif tag == "table":
            self.current["tables"].append([])
        elif tag == "tr":
            self.row = []
        elif tag in ("td", "th"):
            self.cell = []
        elif tag == "svg":
            self.svg = []
            self.current["svgs"].append(self.svg)
        if self.svg is not None and tag != "svg":
            self.svg.append((tag, a))

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self.cell is not None and self.row is not None:
            self.row.append("".join(self.cell).strip())
            self.cell = None
        elif tag == "tr" and self.row is not None and self.current is not None:
            self.current["tables"][-1].append(self.row)
            self.row = None
        elif tag == "svg":
            self.svg = None
        elif tag == "section":
            self.current = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell.append(data)


def parse(path: Path) -> dict[str, dict]:
    page = _Page()
    page.feed(path.read_text())
    return page.sections


# ---------------------------------------------------------------- the documents


def test_track_series_only_with_the_option(docs):
    """The default JSON stays small; --series adds each case's error every 0.1 ms, the very
    error the case's RMS and max were computed from."""
    plain, full = _json(docs["track-plain"]), _json(docs["track"])
    assert plain["schema"] == TRACK_SCHEMA and _json(docs["bode"])["schema"] == BODE_SCHEMA
    assert all("error_series" not in c for c in plain["cases"])
    assert docs["track"].stat().st_size > 20 * docs["track-plain"].stat().st_size
    for c in full["cases"]:
        s = c["error_series"]
        e = np.asarray(s["error_rad"])
        assert s["sample_s"] == pytest.approx(1e-4)
        assert e.size == round(full["trajectory"]["steps"] * full["trajectory"]["step_s"] / 1e-4)
        assert np.sqrt(np.mean(e**2)) == pytest.approx(c["rms_error_rad"], rel=1e-5)
        assert np.abs(e).max() == pytest.approx(c["max_error_rad"], rel=1e-5)


# ---------------------------------------------------------------- sections per input


def test_all_three_sections_from_real_runs(docs, tmp_path, cli):
    out = tmp_path / "r.html"
    code, stdout, err = cli("report", "--simulate", "--duration", "0.5s", "--move", "3:20000",
                            "--joint-track", docs["track"], "--joint-bode", docs["bode"],
                            "-o", out)
    assert code == 0, err
    doc = _json(out.with_suffix(".json"))
    assert doc["sections"][-3:] == ["joints", "tracking", "bandwidth"]
    assert doc["inputs"]["joint_track"] == str(docs["track"])
    assert doc["inputs"]["joint_bode"] == str(docs["bode"])
    page = parse(out)
    assert set(page) == set(doc["sections"])

    # joints: the simulation's moves, one row a moved joint, its error over time drawn
    moves = doc["data"]["joints"]["moves"]
    assert [m["slave"] for m in moves] == [3] and moves[0]["complete"]
    (table,) = page["joints"]["tables"]
    assert table[0] == ["slave", "joint", "distance", "duration", "error RMS", "error max"]
    assert table[1][:2] == ["3", "Joint03 L Hip Pitch"]
    assert table[1][4] == f"{moves[0]['following_error_rms']:.1f} inc"
    assert table[1][5] == f"{moves[0]['following_error_max']} inc"
    assert doc["headline"]["simulation"]["following_error_rms"] == \
        moves[0]["following_error_rms"]
    (svg,) = page["joints"]["svgs"]
    assert sum(tag == "polyline" for tag, _ in svg) == 1

    # tracking: Table III as joint track wrote it, Fig. 9 one line a case
    track = _json(docs["track"])
    (table,) = page["tracking"]["tables"]
    assert table[0] == ["case", "control rate", "bus rate", "k_e", "RMS error", "max error",
                        "RMS change vs the first"]
    assert [r[0] for r in table[1:]] == [c["name"] for c in track["cases"]]
    assert [r[4] for r in table[1:]] == [mrad(c["rms_error_rad"]) for c in track["cases"]]
    assert [r[5] for r in table[1:]] == [mrad(c["max_error_rad"]) for c in track["cases"]]
    ref = track["cases"][0]["rms_error_rad"]
    for row, c in zip(table[2:], track["cases"][1:], strict=True):
        assert row[6] == f"{100 * (c['rms_error_rad'] - ref) / ref:+.1f} %"
    assert "extrapolated" in table[3][2]
    data = doc["data"]["tracking"]
    assert [c["rms_error_rad"] for c in data["cases"]] == [c["rms_error_rad"]
                                                           for c in track["cases"]]
    assert all("error_series" not in c for c in data["cases"])  # not copied into report.json
    (svg,) = page["tracking"]["svgs"]
    assert sum(tag == "polyline" for tag, _ in svg) == len(track["cases"])
    for c in track["cases"]:
        assert doc["headline"][f"joint track: {c['name']}"]["tracking_rms_error_mrad"] == \
            pytest.approx(c["rms_error_rad"] * 1e3)

    # bandwidth: Fig. 10's gain with the -3 dB line and the bandwidth marked, and phase
    bode = _json(docs["bode"])
    assert bode["bandwidth_hz"] is not None
    rows = dict(page["bandwidth"]["tables"][0])
    assert rows["-3 dB bandwidth"] == f"{bode['bandwidth_hz']:,.1f}".rstrip("0").rstrip(".") \
        + " Hz"
    assert doc["data"]["bandwidth"]["bandwidth_hz"] == bode["bandwidth_hz"]
    assert doc["headline"]["joint bode"] == {"bandwidth_hz": bode["bandwidth_hz"]}
    gain, phase = page["bandwidth"]["svgs"]
    for svg in (gain, phase):
        (line,) = [a for tag, a in svg if tag == "polyline"]
        assert len(line["points"].split()) == len(bode["points"])
        assert any(a.get("class") == "vline" for _, a in svg)
    assert any(a.get("class") == "hline" for _, a in gain)
    # the marked bandwidth sits between the ticks around it on the log axis
    ticks = {float(t.replace(",", "")): None for t in re.findall(
        r'text-anchor="middle">([\d,.]+)</text>', out.read_text().split(
            'id="bandwidth"')[1].split("</svg>")[0])}
    assert min(ticks) < bode["bandwidth_hz"] < max(ticks)


def test_sections_only_for_their_inputs(docs, moved, tmp_path):
    eni, simulation = moved
    plain = simulate(eni, options_from_cli(duration="0.1s"))
    track, bode = load_joint_track(docs["track"]), load_joint_bode(docs["bode"])

    def ids(**kw) -> list[str]:
        return [s.id for s in build_report(**kw).sections]

    assert not {"joints", "tracking", "bandwidth"} & set(ids(eni=eni, simulation=plain))
    assert "joints" in ids(eni=eni, simulation=simulation)
    assert ids(joint_track=track) == ["verdict", "tracking"]
    assert ids(joint_bode=bode) == ["verdict", "bandwidth"]
    # a track without --series: Table III, no figure, and the page says why
    report = build_report(joint_track=load_joint_track(docs["track-plain"]))
    out = write_report(report, tmp_path / "plain.html")[0]
    section = parse(out)["tracking"]
    assert section["svgs"] == [] and len(section["tables"][0]) == 4
    assert "joint track --series" in report.section("tracking").intro
    headline = report.to_dict()["headline"]
    assert set(headline) == {f"joint track: {c['name']}" for c in track.doc["cases"]}


def test_the_series_is_the_error_the_table_reports(moved):
    """The following error drawn is the one the simulation's RMS and max came from."""
    eni, simulation = moved
    report = build_report(eni=eni, simulation=simulation)
    (move,) = report.section("joints").data["moves"]
    t, err = simulation.series.following_error[move["joint"]]
    assert np.sqrt(np.mean(err.astype(float) ** 2)) == pytest.approx(
        move["following_error_rms"], abs=1e-3)
    assert np.abs(err).max() == move["following_error_max"]
    assert t[-1] - t[0] == pytest.approx(move["duration_s"], abs=2 / 2000)


def test_markdown_has_the_sections_and_their_pngs(docs, tmp_path, cli):
    out = tmp_path / "r.md"
    code, _, err = cli("report", "--simulate", "--duration", "0.5s", "--move", "3:20000",
                       "--joint-track", docs["track"], "--joint-bode", docs["bode"],
                       "-f", "md", "-o", out)
    assert code == 0, err
    text = out.read_text()
    for title in ("## Joints", "## Joint tracking", "## Bandwidth",
                  "| 1 kHz ref | 1,000 Hz | 1,000 Hz |"):
        assert title in text
    for name in ("following-error", "tracking-error", "bode-gain", "bode-phase"):
        png = tmp_path / f"r-{name}.png"
        assert f"]({png.name})" in text
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000


# ---------------------------------------------------------------- findings and the gate


def test_findings_link_to_their_sections(docs, tmp_path, cli):
    """A learned case no better than the reference (the document edited), a bandwidth
    not reached and a move cut short by the run's end: findings linked to their section."""
    worse = _json(docs["track"])
    worse["cases"][1]["rms_error_rad"] = worse["cases"][0]["rms_error_rad"] * 1.5
    (tmp_path / "worse.json").write_text(json.dumps(worse))
    open_bode = _json(docs["bode"]) | {"bandwidth_hz": None}
    (tmp_path / "open.json").write_text(json.dumps(open_bode))
    out = tmp_path / "r.html"
    code, stdout, err = cli("report", "--simulate", "--duration", "0.1s", "--move", "3:20000",
                            "--joint-track", tmp_path / "worse.json", "--joint-bode",
                            tmp_path / "open.json", "-o", out)
    assert code == 0, err  # warnings and info: the verdict passes
    findings = {f["kind"]: f for f in _json(out.with_suffix(".json"))["findings"]}
    assert findings["joint-tracking"]["section"] == "tracking"
    assert findings["joint-tracking"]["severity"] == "warning"
    assert worse["cases"][1]["name"] in findings["joint-tracking"]["message"]
    assert findings["joint-bandwidth"]["section"] == "bandwidth"
    assert findings["move-incomplete"]["section"] == "joints"
    verdict = parse(out)["verdict"]["tables"][0]
    assert {r[-1] for r in verdict[1:]} >= {"tracking", "bandwidth", "joints"}
    html = out.read_text()
    for section in ("tracking", "bandwidth", "joints"):
        assert f'<a href="#{section}">{section}</a>' in html
    assert "not below" in " ".join(stdout.split())


def test_gate_on_the_joints_figures(docs, tmp_path, cli):
    base = tmp_path / "base.html"
    args = ("--joint-track", docs["track"], "--joint-bode", docs["bode"])
    assert cli("report", "--simulate", "--duration", "0.5s", "--move", "3:20000", *args,
               "-o", base)[0] == 0
    baseline = base.with_suffix(".json")
    same = tmp_path / "same.html"
    code, _, err = cli("report", "--simulate", "--duration", "0.5s", "--move", "3:20000",
                       *args, "-o", same, "--baseline", baseline)
    assert code == 0, err
    compared = {c["figure"] for c in _json(same.with_suffix(".json"))["gate"]["compared"]}
    assert {"simulation: largest following error RMS", "joint bode: -3 dB bandwidth",
            "joint track: 1 kHz w/ff: RMS tracking error"} <= compared
    # worse: a faster move follows further behind, the learned case tracks worse, the
    # bandwidth fell
    track, bode = _json(docs["track"]), _json(docs["bode"])
    track["cases"][1]["rms_error_rad"] *= 1.3
    bode["bandwidth_hz"] *= 0.8
    (tmp_path / "t.json").write_text(json.dumps(track))
    (tmp_path / "b.json").write_text(json.dumps(bode))
    worse = tmp_path / "worse.html"
    code, out, _ = cli("report", "--simulate", "--duration", "0.5s", "--move",
                       "3:20000:200000:2e6:4e7", "--joint-track", tmp_path / "t.json",
                       "--joint-bode", tmp_path / "b.json", "-o", worse, "--baseline", baseline)
    assert code == 1
    doc = _json(worse.with_suffix(".json"))
    assert {r["figure"] for r in doc["regressions"]} == {
        "simulation: largest following error RMS",
        "joint track: 1 kHz w/ff: RMS tracking error", "joint bode: -3 dB bandwidth"}
    sections = {f["message"].split(" got worse")[0]: f["section"] for f in doc["findings"]
                if f["kind"] == "regression"}
    assert sections == {"simulation: largest following error RMS": "joints",
                        "joint track: 1 kHz w/ff: RMS tracking error": "tracking",
                        "joint bode: -3 dB bandwidth": "bandwidth"}
    assert "RMS tracking error got worse" in " ".join(out.split())


# ---------------------------------------------------------------- bad input


def test_bad_documents_exit_3_in_one_line(docs, tmp_path, cli):
    track, bode = _json(docs["track-plain"]), _json(docs["bode"])
    broken = tmp_path / "broken.json"
    broken.write_text(docs["track-plain"].read_text()[:200])
    no_rms = json.loads(json.dumps(track))
    no_rms["cases"][2]["rms_error_rad"] = "small"
    nan_gain = json.loads(json.dumps(bode))
    nan_gain["points"][3]["gain_db"] = float("nan")
    files = {"no_rms.json": no_rms, "nan_gain.json": nan_gain,
             "no_points.json": bode | {"points": []}, "list.json": [1, 2]}
    for name, content in files.items():
        (tmp_path / name).write_text(json.dumps(content))
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    cases = [
        ("--joint-track", broken, "not JSON"),
        ("--joint-track", docs["bode"], f"not a {TRACK_SCHEMA} document"),
        ("--joint-bode", docs["track"], f"not a {BODE_SCHEMA} document"),
        ("--joint-track", tmp_path / "no_rms.json", "cases[2].rms_error_rad"),
        ("--joint-bode", tmp_path / "nan_gain.json", "points[3].gain_db"),
        ("--joint-bode", tmp_path / "no_points.json", "points"),
        ("--joint-track", tmp_path / "list.json", "not a"),
        ("--joint-track", tmp_path / "missing.json", "no such file"),
        ("--joint-bode", tmp_path, "is a directory"),
    ]
    for option, path, says in cases:
        code, _, err = cli("report", option, path, "-o", out_dir / "r.html")
        assert code == 3, (option, path, err)
        assert len(err.strip().splitlines()) == 1 and says in err, (path, err)
        assert str(path) in err and "Traceback" not in err
        assert list(out_dir.iterdir()) == []
    code, _, err = cli("report", "--joint-bode", docs["bode"], "--move", "3:100",
                       "-o", out_dir / "r.html")
    assert code == 2 and "--move: options of the simulation; add --simulate" in err


def test_log_ticks():
    assert log_ticks(12.6, 400) == [20, 50, 100, 200]
    assert log_ticks(1, 1e6) == [1, 10, 100, 1000, 1e4, 1e5, 1e6]
    assert log_ticks(0, 10) == []
