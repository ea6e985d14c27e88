"""docs/cli.md is generated from the app; this fails when a command changed and the docs did not.
The README's Python examples run as written."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import script_module

ROOT = Path(__file__).resolve().parent.parent


def test_cli_reference_is_current():
    module = script_module("tools/gen_cli_docs.py")
    expected = module.render()
    current = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    assert current == expected, "docs/cli.md is stale: run python tools/gen_cli_docs.py"


def _readme_python_blocks() -> list[str]:
    text = (ROOT / "README.md").read_text()
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


@pytest.mark.parametrize("index", range(len(_readme_python_blocks())))
def test_readme_python_examples_run_as_written(index: int) -> None:
    """Each ```python block of the README runs on its own from the repository root (a new
    user copies one block, not the page)."""
    code = _readme_python_blocks()[index]
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_every_docs_file_named_exists():
    """A help text, docstring, README or doc that sends the reader to docs/NAME.md names a
    file that is there."""
    named: set[str] = set()
    sources = [
        ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "lolacli").rglob("*.py")
    ]
    for path in sources:
        named.update(re.findall(r"\bdocs/[\w./-]+?\.md\b", path.read_text(encoding="utf-8")))
    assert "docs/cli.md" in named
    assert sorted(n for n in named if not (ROOT / n).is_file()) == []
