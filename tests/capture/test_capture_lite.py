"""A small capture is analysed without numpy (issue 28: start-up); every JSON figure is
the one the numpy path gives, on every corpus capture, the benchmark's LOLA-sized capture
and damaged files, with both engines."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import corpus_files, corpus_ids, script_module

import lolacli.capture.analyze as A
from lolacli.errors import CaptureError

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = corpus_files("pcap")


def _doc(path: Path, engine: str, numpy: bool, monkeypatch: pytest.MonkeyPatch) -> object:
    monkeypatch.setattr(A, "SMALL_BYTES", -1 if numpy else 1 << 40)
    try:
        doc = A.analyze_file(path, engine=engine, max_lost=10**9).to_dict()
    except CaptureError as exc:
        return ("error", str(exc))
    doc.pop("engine")
    return doc


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_lite_equals_numpy_on_every_corpus_capture(path, fast, monkeypatch):
    lite = _doc(path, fast, False, monkeypatch)
    assert lite == _doc(path, fast, True, monkeypatch)
    assert lite == _doc(path, "python", False, monkeypatch)


def _bench():  # type: ignore[no-untyped-def]
    return script_module("benchmarks/capture_throughput.py")


def test_lite_equals_numpy_on_a_lola_sized_capture_and_its_damage(tmp_path, fast, monkeypatch):
    """SDO uploads and cyclic traffic; then cut and flipped copies."""
    path = tmp_path / "lola.pcapng"
    _bench().write_capture(path, 1500, pcapng=True, lrw_bytes=800)
    whole = _doc(path, fast, False, monkeypatch)
    assert isinstance(whole, dict) and whole["sdo_transactions"] == 3
    assert whole == _doc(path, fast, True, monkeypatch)
    data = path.read_bytes()
    rnd = random.Random(28)
    for k in range(6):
        b = bytearray(data)
        if k % 2:
            del b[rnd.randrange(1000, len(b)):]
        else:
            for _ in range(20):
                b[rnd.randrange(100, len(b))] = rnd.randrange(256)
        damaged = tmp_path / f"{k}.pcapng"
        damaged.write_bytes(bytes(b))
        assert _doc(damaged, fast, False, monkeypatch) == _doc(damaged, fast, True,
                                                               monkeypatch), k


def test_a_small_capture_does_not_import_numpy():
    small = next((p for p in CAPTURES if p.stat().st_size < 100_000), None)
    if small is None:
        pytest.skip("corpus not found")
    code = (
        "import sys\n"
        "from lolacli.cli.main import main\n"
        f"sys.argv = ['lolacli', 'capture', 'analyze', {str(small)!r}]\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "sys.stderr.write('numpy' if 'numpy' in sys.modules else 'no numpy')\n"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert done.stderr.endswith("no numpy"), done.stderr[-500:]
    assert "Verdict" in done.stdout
