"""Parsed ENI models kept between runs, so a command that only needs the model (``sdo read``
on the emulated chain, in a CI loop) does not parse the same XML again.

:func:`load_eni_cached` reads the file, and where a model parsed from exactly these bytes
by exactly this parser is in the cache, returns it; else parses (:func:`lolacli.files.
load_eni`) and stores the model. The key is a BLAKE2 digest of the file's bytes, the
Python version and the parser's source (name, size and modification time of each module of
lolacli's ``eni`` and ``wire`` packages, which hold its limits and register decoding), so
an edited file or parser never meets an old model. A model read back must also hold the
limits the parser enforces (:func:`lolacli.eni.validate.within_limits`): one that does not
(an entry written by other code) is parsed over, and the file's error is the parser's.

The cache is a directory of pickles: ``$LOLACLI_CACHE_DIR``, else ``$XDG_CACHE_HOME/lolacli``,
else ``~/.cache/lolacli``; ``LOLACLI_CACHE_DIR=""`` turns it off. Unpickling runs code, so an
entry is only read from a directory and a file that belong to the user and that nobody else
can write to; anything wrong with an entry (unreadable, damaged, another owner) means parsing
as if there were none. Storing is best effort: an unwritable cache never fails a command.
At most :data:`MAX_ENTRIES` entries are kept (the oldest go).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import stat
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from lolacli.files import read_eni_bytes

if TYPE_CHECKING:
    from lolacli.eni.model import Eni

MAX_ENTRIES = 32
_SUFFIX = ".eni.pickle"


def cache_dir() -> Path | None:
    """Where the cache lives; None when it is turned off."""
    configured = os.environ.get("LOLACLI_CACHE_DIR")
    if configured is not None:
        return Path(configured) if configured.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "lolacli"


#: the packages whose source makes the parser: the ENI reader, model and limits; the
#: register codecs and frame constants it decodes InitCmds and checks datagrams with
_PARSER_PACKAGES = ("eni", "wire")


def _package_fingerprint() -> bytes:
    """Names, sizes and modification times of the modules the parser is made of."""
    root = Path(__file__).resolve().parent
    parts = [f"{sys.version_info[0]}.{sys.version_info[1]}"]
    for package in _PARSER_PACKAGES:
        try:
            with os.scandir(root / package) as it:
                for entry in sorted(it, key=lambda e: e.name):
                    if entry.name.endswith(".py"):
                        st = entry.stat()
                        parts.append(f"{package}/{entry.name}:{st.st_size}:{st.st_mtime_ns}")
        except OSError:
            parts.append(f"{package}/?")
    return "|".join(parts).encode()


def cache_key(data: bytes) -> str:
    h = hashlib.blake2b(digest_size=20)
    h.update(_package_fingerprint())
    h.update(b"\0")
    h.update(data)
    return h.hexdigest()


def _private(st: os.stat_result, *, directory: bool) -> bool:
    """Ours, and nobody else may write to it."""
    if st.st_uid != os.geteuid() or st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return False
    return stat.S_ISDIR(st.st_mode) if directory else stat.S_ISREG(st.st_mode)


def _read(path: Path) -> Eni | None:
    try:
        if not _private(os.stat(path.parent), directory=True):
            return None
        with open(path, "rb") as f:
            if not _private(os.fstat(f.fileno()), directory=False):
                return None
            model = pickle.load(f)
    except Exception:  # missing, unreadable or damaged: parse instead
        return None
    from lolacli.eni.model import Eni
    from lolacli.eni.validate import within_limits

    return model if isinstance(model, Eni) and within_limits(model) else None


def _write(folder: Path, path: Path, model: Eni) -> None:
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        if not _private(os.stat(folder), directory=True):
            return
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                pickle.dump(model, f, protocol=pickle.HIGHEST_PROTOCOL)
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise
        _prune(folder)
    except Exception:  # best effort: a cache that cannot be written is no cache
        return


def _prune(folder: Path) -> None:
    entries = sorted(folder.glob("*" + _SUFFIX), key=lambda p: p.stat().st_mtime_ns)
    for old in entries[:-MAX_ENTRIES]:
        old.unlink(missing_ok=True)


def load_eni_cached(path: str | Path) -> Eni:
    """:func:`lolacli.files.load_eni`, from the cache where it holds this file's model
    (see the module docstring). Errors are load_eni's (EniError, exit 3)."""
    data = read_eni_bytes(path)
    folder = cache_dir()
    entry = None
    if folder is not None:
        entry = folder / (cache_key(data) + _SUFFIX)
        model = _read(entry)
        if model is not None:
            from dataclasses import replace

            return model if model.source == str(path) else replace(model, source=str(path))
    from lolacli.eni.parser import parse_eni

    model = parse_eni(data, source=str(path))
    if folder is not None and entry is not None:
        _write(folder, entry, model)
    return model


__all__ = ["MAX_ENTRIES", "cache_dir", "cache_key", "load_eni_cached"]
