"""The report's HTML in a real headless Chromium (Debian's ``chromium``, driven through
playwright's Python API): every figure drawn, no console error, no request leaves the
page, every section of its inputs present; screenshots at 1280 and 390 px go to
``$LOLACLI_ARTIFACTS`` (default: the test's tmp_path) for CI to keep."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from tests.conftest import CORPUS

CHROMIUM = shutil.which("chromium")
try:
    from playwright.sync_api import sync_playwright
except ImportError:  # pragma: no cover - depends on the machine
    sync_playwright = None

pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt install chromium)"),
    pytest.mark.skipif(sync_playwright is None,
                       reason="playwright not installed (pip install playwright)"),
]

WIDTHS = (1280, 390)


@pytest.fixture(scope="module")
def pages(tmp_path_factory) -> dict[str, Path]:
    """Reports of three kinds of input: the simulated LOLA chain with its ENI (every
    section but the comparison), two captures side by side, and a simulation that moved a
    joint with joint track's and joint bode's documents (the joints' sections)."""
    from typer.testing import CliRunner

    from lolacli.cli.main import app

    folder = tmp_path_factory.mktemp("pages")
    dc = CORPUS / "pcap" / "ethercrab__replay-dc.pcapng"
    other = CORPUS / "pcap" / "ethercrab__replay-issue-255.pcapng"
    runs = {"simulation": ["--simulate", "--duration", "2s", "--drift-ppb", "20000"]}
    # the joints' sections: a move, joint track's Table III and Fig. 9, joint bode's Fig. 10
    docs = {}
    for name, args in (("track", ["track", "--steps", "1", "--series"]),
                       ("bode", ["bode", "--duration", "1"])):
        docs[name] = folder / f"{name}.json"
        result = CliRunner().invoke(app, ["joint", *args, "--format", "json"])
        assert result.exit_code == 0, result.stderr
        docs[name].write_text(result.stdout)
    runs["joints"] = ["--simulate", "--duration", "0.5s", "--move", "3:20000", "--joint-track",
                      str(docs["track"]), "--joint-bode", str(docs["bode"])]
    if CORPUS.is_dir():
        runs["captures"] = ["--capture", str(dc), "--capture", str(other)]
    out = {}
    for name, args in runs.items():
        path = folder / f"{name}.html"
        result = CliRunner().invoke(app, ["report", *args, "-o", str(path)])
        assert result.exit_code in (0, 1), result.stdout
        out[name] = path
    return out


def _artifacts(tmp_path: Path) -> Path:
    folder = Path(os.environ.get("LOLACLI_ARTIFACTS") or tmp_path)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@pytest.mark.parametrize("name", ["simulation", "captures", "joints"])
def test_page_in_chromium(name, pages, tmp_path):
    if name not in pages:
        pytest.skip(f"corpus not found at {CORPUS}")
    page_path = pages[name]
    sections = json.loads(page_path.with_suffix(".json").read_text())["sections"]
    artifacts = _artifacts(tmp_path)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        try:
            for width in WIDTHS:
                page = browser.new_page(viewport={"width": width, "height": 900})
                errors: list[str] = []
                outside: list[str] = []
                page.on("console", lambda m, e=errors: e.append(m.text)
                        if m.type == "error" else None)
                page.on("pageerror", lambda exc, e=errors: e.append(str(exc)))

                def route(r, seen=outside):
                    url = r.request.url
                    if url.startswith(("file:", "data:")):
                        r.continue_()
                    else:
                        seen.append(url)
                        r.abort()

                page.route("**/*", route)
                page.goto(page_path.as_uri())
                page.wait_for_load_state("load")
                assert errors == [], errors
                assert outside == [], outside
                shown = page.eval_on_selector_all("section", "s => s.map(x => x.id)")
                assert shown == sections
                for section in sections:  # each linked from the top
                    assert page.locator(f'nav a[href="#{section}"]').count() == 1
                images = page.eval_on_selector_all(
                    "img", "xs => xs.map(x => [x.complete, x.naturalWidth])")
                assert all(done and w > 0 for done, w in images), images
                boxes = page.eval_on_selector_all(
                    "svg", "xs => xs.map(x => { const b = x.getBoundingClientRect();"
                           " return [b.width, b.height, x.querySelectorAll("
                           "'rect,polyline').length]; })")
                assert boxes and all(w > 0 and h > 0 and n > 0 for w, h, n in boxes), boxes
                assert len(boxes) + len(images) >= 3  # histogram, CDF, over time at least
                # the page fits the phone's width: nothing wider than the viewport but
                # the tables' own scroll boxes
                wide = page.evaluate("document.documentElement.scrollWidth")
                assert wide <= width, (width, wide)
                shot = artifacts / f"report-{name}-{width}.png"
                page.screenshot(path=str(shot), full_page=True)
                assert shot.stat().st_size > 10_000
                page.close()
        finally:
            browser.close()
