"""Pick the scanner engine: the C kernel (``_cscan.c``, built by ``pip install`` when a C
compiler is present) or the plain-Python reference (:mod:`lolacli.capture.scan`). Both
give identical results; the tests compare them on every path and its damage.

Why two and no more (issue 24: a second implementation stays only where it is at least
2x faster on a figure a user sees; ``benchmarks/capture_throughput.py --engines``): on a
generated 1 M-frame capture ``capture analyze`` ran at 1.74 M frames/s with C, 0.13 M
with the numba-compiled scanner that was here, 0.016 M with Python (C 108x Python, 13.6x
numba); on the largest corpus capture (22,298 frames) C 0.78 s, Python 1.71 s, numba
2.69 s for the whole command; on the small corpus captures C and Python tie (start-up
dominates) and numba lost 3-4x (its import and LLVM start-up). numba was removed.

When the C kernel is missing (no compiler at install), ``auto`` runs Python and
:func:`fallback_note` gives the CLI its one stderr line about it, once per process.
"""

from __future__ import annotations

import os
from typing import Any

from lolacli.capture import scan
from lolacli.errors import UsageError

ENGINES = ("c", "python")

#: engines that were, and what to say when asked for one
REMOVED = {
    "numba": "was removed: the C engine is 3-14x faster; use auto (C when built, else "
             "Python)",
}

#: one stderr line within 80 columns
FALLBACK_NOTE = "lolacli: C scanner not built (install gcc, reinstall): Python scans ~100x slower"

_fallback_used = False
_fallback_noted = False


def choose_engine(engine: str = "auto", file_bytes: int | None = None) -> str:
    """``"c"`` or ``"python"``; ``LOLACLI_ENGINE`` overrides ``"auto"``, which takes C
    when it was built, else Python (and :func:`fallback_note` says so once).
    ``file_bytes`` is accepted for callers that pass it; no engine depends on it now.

    Raises :class:`~lolacli.errors.UsageError` for an unknown, removed or unavailable
    engine."""
    global _fallback_used
    source = "--engine"
    if engine == "auto":
        engine = os.environ.get("LOLACLI_ENGINE", "auto")
        source = "LOLACLI_ENGINE"
    if engine == "auto":
        from lolacli.capture.cengine import c_available

        if c_available():
            return "c"
        _fallback_used = True
        return "python"
    if engine in REMOVED:
        raise UsageError(f"{source} {engine} {REMOVED[engine]}")
    if engine not in ENGINES:
        raise UsageError(f"unknown capture engine {engine!r} (auto, {', '.join(ENGINES)})")
    if engine == "c":
        from lolacli.capture.cengine import c_available

        if not c_available():
            raise UsageError("capture engine c is not built: install a C compiler (gcc), "
                             "then reinstall lolacli")
    return engine


def fallback_note() -> str | None:
    """The line to print once when ``auto`` ran Python because the C kernel is missing:
    the first call after that returns it, every other call None."""
    global _fallback_noted
    if not _fallback_used or _fallback_noted:
        return None
    _fallback_noted = True
    return FALLBACK_NOTE


def kernels(engine: str) -> Any:
    """An object with ``scan``, ``rehash`` and ``finish`` for the engine."""
    if engine == "python":
        return scan
    from lolacli.capture.cengine import CKernels

    return CKernels()
