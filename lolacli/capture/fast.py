"""Pick the scanner engine: the C kernel (built at install), numba-compiled (extra
``fast``) or plain Python. All three give identical results; the tests compare them.

The functions of :mod:`lolacli.capture.scan` are compiled into a private namespace, so
that the plain-Python originals stay importable beside the compiled ones (the tests
compare both). numba is imported here only, and only when asked for.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from lolacli.capture import scan
from lolacli.errors import UsageError

_COMPILED: SimpleNamespace | None = None


def numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


#: Below this file size the plain-Python scanner finishes before numba has even loaded
#: its compiled kernel (about 0.7 s of import and LLVM start-up; Python scans ~5 MB/s).
SMALL_FILE_BYTES = 2 * 1024 * 1024


ENGINES = ("c", "numba", "python")


def choose_engine(engine: str = "auto", file_bytes: int | None = None) -> str:
    """``"c"``, ``"numba"`` or ``"python"``; ``LOLACLI_ENGINE`` overrides ``"auto"``,
    which takes C when it was built (it loads in milliseconds), else Python for files
    under :data:`SMALL_FILE_BYTES` and numba (when installed) above.

    Raises :class:`~lolacli.errors.UsageError` for an unknown or unavailable engine."""
    if engine == "auto":
        engine = os.environ.get("LOLACLI_ENGINE", "auto")
    if engine == "auto":
        from lolacli.capture.cengine import c_available

        if c_available():
            return "c"
        if file_bytes is not None and file_bytes < SMALL_FILE_BYTES:
            return "python"
        return "numba" if numba_available() else "python"
    if engine not in ENGINES:
        raise UsageError(f"unknown capture engine {engine!r} (auto, {', '.join(ENGINES)})")
    if engine == "c":
        from lolacli.capture.cengine import c_available

        if not c_available():
            raise UsageError("capture engine c is not built: install a C compiler (gcc), "
                             "then reinstall lolacli")
    if engine == "numba" and not numba_available():
        raise UsageError("capture engine numba needs numba: pip install 'lolacli[fast]'")
    return engine


def kernels(engine: str) -> Any:
    """An object with ``scan``, ``rehash`` and ``finish`` for the engine."""
    if engine == "python":
        return scan
    if engine == "c":
        from lolacli.capture.cengine import CKernels

        return CKernels()
    global _COMPILED
    if _COMPILED is None:
        _COMPILED = _compile()
    return _COMPILED


def _compile() -> SimpleNamespace:
    import numba

    source_path = Path(scan.__file__)
    namespace: dict[str, Any] = {"__name__": "lolacli.capture.scan"}
    code = compile(source_path.read_text(encoding="utf-8"), str(source_path), "exec")
    exec(code, namespace)  # noqa: S102  (our own module, compiled for numba)
    namespace["_byte"] = _byte_int64
    for name in scan.KERNELS:
        inline: Any = "always" if name in scan.INLINE else "never"
        namespace[name] = numba.njit(cache=True, nogil=True, inline=inline)(namespace[name])
    return SimpleNamespace(**{name: namespace[name] for name in scan.KERNELS})


def _byte_int64(buf: Any, p: Any) -> Any:
    """``scan._byte`` for compiled kernels: a uint8 widened to int64 (numba would keep
    it unsigned, and unsigned mixed with signed integers promotes to float)."""
    return np.int64(buf[p])
