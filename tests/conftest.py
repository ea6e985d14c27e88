"""Shared fixtures: the corpus beside the repo (LOLACLI_CORPUS), the CLI runner."""

from __future__ import annotations

import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parent.parent
CORPUS = Path(os.environ.get("LOLACLI_CORPUS", ROOT.parent / "shared" / "corpus"))


def corpus_files(kind: str, pattern: str = "*") -> list[Path]:
    """Files of one corpus folder (eni, pcap, esi, eds); empty when the corpus is absent."""
    folder = CORPUS / kind
    return sorted(folder.glob(pattern)) if folder.is_dir() else []


def script_module(relative: str) -> Any:
    """A script of the repository (``tools/…``, ``benchmarks/…``) imported as a module."""
    import importlib.util
    import sys

    path = ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def corpus_ids(paths: list[Path]) -> list[str]:
    return [p.name for p in paths]


@pytest.fixture(autouse=True)
def _no_process_left_behind(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Every process a test starts (subprocess.Popen, also under run()) is gone when the
    test ends, however it ends: a failed assertion before a test's own clean-up must not
    leave a 600 s simulation or an emulator running into the next tests."""
    started: list[subprocess.Popen[bytes]] = []
    original = subprocess.Popen.__init__

    def tracking_init(self: subprocess.Popen[bytes], *args: object, **kwargs: object) -> None:
        original(self, *args, **kwargs)  # type: ignore[arg-type]
        started.append(self)

    monkeypatch.setattr(subprocess.Popen, "__init__", tracking_init)
    yield
    for proc in started:
        if proc.poll() is None:
            proc.kill()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass


@pytest.fixture
def corpus() -> Path:
    if not CORPUS.is_dir():
        pytest.skip(f"corpus not found at {CORPUS}")
    return CORPUS


@pytest.fixture
def cli():
    """Run the CLI in-process: returns (exit_code, stdout, stderr)."""
    from typer.testing import CliRunner

    from lolacli.cli.main import app

    runner = CliRunner()

    def run(*args: str) -> tuple[int, str, str]:
        result = runner.invoke(app, [str(a) for a in args])
        if result.exception is not None and not isinstance(result.exception, SystemExit):
            raise result.exception
        return result.exit_code, result.stdout, result.stderr

    return run


@pytest.fixture
def fast() -> str:
    """The compiled capture-scanner engine, C (a test taking ``fast`` compares it with
    the plain-Python reference)."""
    from lolacli.capture.cengine import c_available

    if not c_available():
        pytest.fail("the C scanner was not built: install a C compiler, then pip install -e .")
    return "c"
