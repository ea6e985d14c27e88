"""The Bus Variables example in docs/ runs as written and moves the knee."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_bus_variables_example_runs() -> None:
    script = ROOT / "docs" / "examples" / "bus_variables.py"
    assert len(script.read_text().splitlines()) <= 20
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run(
        [sys.executable, str(script)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "knee enabled=True actual=5000"
