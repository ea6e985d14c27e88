"""SOEM's own C tools (``slaveinfo``, ``simple_test``, ``firm_update``), built from source
for the tests.

The build goes to a cache folder outside the repository (``$XDG_CACHE_HOME/lolacli`` or
``~/.cache/lolacli``), once per pysoem version. The sources are the sdist of the installed
pysoem, from PyPI through pip: it carries SOEM with its tools, the same SOEM the pysoem
tests use. Its copy of ``ethercatmain.c`` leaves the ``DCtO``/``DCl`` slots out of the
initializer of the default context that only the tools use (pysoem builds with EC_VER2
and never compiles it), so that initializer gets upstream's two ``0`` slots back before
the build; nothing else is touched. Nothing of SOEM is kept in the repository. ``None``
(the tests skip) only when there is no compiler or no way to the sdist.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

TOOLS = ("slaveinfo", "simple_test", "firm_update")
_CONTEXT_BEFORE = "    &EcatError,         // .ecaterror     =\n    &ec_DCtime,"
_CONTEXT_UPSTREAM = (
    "    &EcatError,         // .ecaterror     =\n"
    "    0,                  // .DCtO          =\n"
    "    0,                  // .DCl           =\n"
    "    &ec_DCtime,"
)


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "lolacli"


def soem_tools() -> tuple[dict[str, Path] | None, str]:
    """Paths of the built tools, or ``None`` and why not."""
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        return None, "no C compiler"
    return _sdist_build()


def _done(out: Path) -> dict[str, Path] | None:
    tools = {t: out / t for t in TOOLS}
    return tools if all(p.is_file() and os.access(p, os.X_OK) for p in tools.values()) else None


def _pysoem_version() -> str | None:
    try:
        from importlib.metadata import version

        return version("pysoem")
    except Exception:  # noqa: BLE001 - not installed: no sdist to take
        return None


def _sdist_build() -> tuple[dict[str, Path] | None, str]:
    version = _pysoem_version()
    if version is None:
        return None, "pysoem is not installed (its sdist carries SOEM)"
    out = cache_dir() / f"soem-pysoem-{version}"
    if (tools := _done(out)) is not None:
        return tools, f"pysoem {version} sdist"
    out.mkdir(parents=True, exist_ok=True)
    archive = out / f"pysoem-{version}.tar.gz"
    if not archive.is_file():
        done = subprocess.run(
            # offline, pip's default retries stall for minutes: one try of 10 s at most
            [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:",
             "--retries", "0", "--timeout", "10", f"pysoem=={version}", "-d", str(out)],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        if done.returncode != 0 or not archive.is_file():
            return None, f"cannot download the pysoem {version} sdist: {done.stderr[-300:]}"
    with tarfile.open(archive) as tar:
        tar.extractall(out, filter="data")
    soem = out / f"pysoem-{version}" / "soem"
    main = soem / "soem" / "ethercatmain.c"
    text = main.read_text()
    if _CONTEXT_BEFORE in text:
        main.write_text(text.replace(_CONTEXT_BEFORE, _CONTEXT_UPSTREAM))
    sources = sorted(str(p) for p in (soem / "soem").glob("*.c"))
    sources += [str(soem / "osal" / "linux" / "osal.c")]
    sources += sorted(str(p) for p in (soem / "oshw" / "linux").glob("*.c"))
    includes = [f"-I{soem / d}" for d in ("soem", "osal", "osal/linux", "oshw/linux")]
    cc = shutil.which("cc") or "gcc"
    for tool in TOOLS:
        main_c = soem / "test" / "linux" / tool / f"{tool}.c"
        cmd = [cc, "-O2", "-w", *includes, *sources, str(main_c), "-lpthread", "-lrt"]
        done = subprocess.run([*cmd, "-o", str(out / tool)], capture_output=True, text=True)
        if done.returncode != 0:
            return None, f"SOEM {tool} build failed: {done.stderr[-400:]}"
    return _done(out), f"pysoem {version} sdist"
