"""The library outside the repository: every Python block of the README and of
docs/python-api.md, and the scripts in docs/examples, run as they are from an empty
temporary directory on the installed package (no path into the checkout)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "docs" / "python-api.md"]
_BLOCK = re.compile(r"```python\n(.*?)```", re.S)


def _blocks() -> list[tuple[str, str]]:
    out = []
    for page in PAGES:
        for k, code in enumerate(_BLOCK.findall(page.read_text())):
            out.append((f"{page.name}#{k + 1}", code))
    for script in sorted((ROOT / "docs" / "examples").glob("*.py")):
        out.append((script.name, script.read_text()))
    return out


BLOCKS = _blocks()


def _run(code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if os.environ.get("PYTHONPATH"):  # a worktree under test, not the installed main
        env["PYTHONPATH"] = os.environ["PYTHONPATH"]
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


def test_the_pages_have_examples() -> None:
    assert len([n for n, _ in BLOCKS if n.startswith("python-api")]) >= 6
    assert len([n for n, _ in BLOCKS if n.startswith("README")]) >= 3


@pytest.mark.parametrize(("name", "code"), BLOCKS, ids=[n for n, _ in BLOCKS])
def test_an_example_runs_from_any_directory(name: str, code: str, tmp_path: Path) -> None:
    done = _run(code, tmp_path)
    assert done.returncode == 0, f"{name}:\n{done.stderr[-2000:]}"
    assert "Traceback" not in done.stderr
    assert done.stdout.strip(), f"{name} printed nothing"


def test_the_embedded_chain_and_positions(tmp_path: Path) -> None:
    done = _run(
        "import lolacli\n"
        "from lolacli.emulator.slave import build_chain\n"
        "from lolacli.master import ChainTransport, Cia402Drive, Master\n"
        "eni = lolacli.load_eni()\n"
        "assert lolacli.lola_path().is_file() and eni.source == str(lolacli.lola_path())\n"
        "m = Master(eni, ChainTransport(build_chain(eni)))\n"
        "assert Cia402Drive(m, 4).slave == 'Joint04 L Knee' == eni.slaves[3].name\n"
        "from lolacli.errors import LinkError\n"
        "try:\n    Cia402Drive(m, 99)\nexcept LinkError as e:\n    print(e)\n",
        tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert "no slave at position 99 (1 to 25)" in done.stdout
