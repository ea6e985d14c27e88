"""docs/timing-model.md is generated from the corpus by tools/timing_model_check.py; this
fails when the model, the capture analysis or the corpus changed and the table did not."""

from __future__ import annotations

from pathlib import Path

from conftest import CORPUS, script_module

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    return script_module("tools/timing_model_check.py")


def test_timing_model_table_is_current(corpus):
    tool = _tool()
    rows = tool.measure(CORPUS)
    current = (ROOT / "docs" / "timing-model.md").read_text(encoding="utf-8")
    assert current == tool.render(rows), "stale: run python tools/timing_model_check.py"


def test_the_table_holds_every_capture_with_a_slave_count(corpus):
    rows = _tool().measure(CORPUS)
    assert len(rows) == 14  # soem-sdinfo-no-slaves: nothing answered, no slave count
    usable = [r for r in rows if r.min_us is not None]
    assert len(usable) == 10
    # the model (bus only) is short of every host capture by tens of µs at least
    assert all(r.error_us > 30 for r in usable)
    # a host latency fitted on the same host's other captures closes most of it
    fitted = [r for r in usable if r.host_latency_us is not None]
    left = sorted(abs(r.error_us - r.host_latency_us) for r in fitted)
    assert len(fitted) >= 5 and left[len(left) // 2] < 10
