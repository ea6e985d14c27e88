"""Thin file loaders: read bytes, hand them to a pure parser, map OS errors to exit-3 errors."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from lolacli.errors import EniError, InputError, UsageError

if TYPE_CHECKING:
    from lolacli.eni.esi import EsiFile
    from lolacli.eni.model import Eni
    from lolacli.motion.joint import JointParams

#: Refuse absurdly large "ENI" files before reading them (the largest real exports are ~1 MB).
MAX_ENI_BYTES = 64 * 1024 * 1024


def read_bounded(
    path: str | Path, what: str, max_bytes: int, error: type[InputError] = InputError
) -> bytes:
    """The bytes of an input file of at most ``max_bytes`` (``what`` names its kind in
    errors: "an ENI file"); ``error`` (exit 3, with the path) when it cannot be read or is
    larger. Bounded for files with no size to stat too (pipes, /dev/zero)."""
    p = Path(path)
    name = str(path)
    try:
        if p.is_dir():
            raise error(f"is a directory, not {what}", path=name)
        if p.is_file() and (size := p.stat().st_size) > max_bytes:
            raise error(f"file too large for {what} ({size:,} bytes)", path=name)
        with p.open("rb") as f:
            data = f.read(max_bytes + 1)
    except FileNotFoundError:
        raise error("no such file", path=name) from None
    except PermissionError:
        raise error("permission denied", path=name) from None
    except OSError as exc:
        raise error(f"cannot read: {exc.strerror or exc}", path=name) from None
    if len(data) > max_bytes:
        raise error(f"file too large for {what} (over {max_bytes:,} bytes)", path=name)
    return data


def read_eni_bytes(path: str | Path) -> bytes:
    """The bytes of an ENI file; :class:`EniError` (exit 3) when it cannot be read."""
    return read_bounded(path, "an ENI file", MAX_ENI_BYTES, EniError)


def lola_path() -> Path:
    """Where the embedded LOLA chain's ENI is (package data: works from any directory)."""
    from importlib.resources import files

    return Path(str(files("lolacli.eni_examples").joinpath("lola.xml")))


def load_eni(path: str | Path | None = None) -> Eni:
    """Read and parse an ENI file (``None``: the embedded LOLA chain). Every failure is an
    :class:`EniError` naming the file."""
    from lolacli.eni.parser import parse_eni

    if path is None:
        path = lola_path()
    return parse_eni(read_eni_bytes(path), source=str(path))


def load_esi(path: str | Path) -> EsiFile:
    """Read and parse an ESI file. Every failure is an :class:`EniError` naming the file."""
    from lolacli.eni.esi import parse_esi

    return parse_esi(read_eni_bytes(path), source=str(path))


def check_output_file(path: str | Path, option: str,
                      inputs: Iterable[tuple[str, str | Path | None]] = (),
                      regular: bool = True) -> None:
    """UsageError (exit 2, one line) before any work when the file ``option`` names must not
    be written: no name (an empty path, which a Path spells "."); with ``regular``, a path
    that exists and is no regular file (a folder, a FIFO, a device: the writers rename a
    temporary file over their target or cut it to length); or the same file as one of
    ``inputs`` ((what names it, its path) pairs, such as ("--eni", path)), by any spelling
    or link. A path that does not exist yet passes: whether its folder takes it is for
    the writer to say."""
    name = str(path)
    if name in ("", "."):
        raise UsageError(f"{option}: no file name given")
    try:
        st: os.stat_result | None = os.stat(path)
    except OSError:  # not there yet (or not to be looked at: the writer says)
        st = None
    if regular and st is not None and not stat.S_ISREG(st.st_mode):
        raise UsageError(f"{option} {name}: is {_kind(st.st_mode)}, not a regular file; "
                         "give a file name")
    for what, other in inputs:
        if other is None or str(other) in ("", "-"):
            continue
        try:
            same = os.path.samestat(st, os.stat(other)) if st is not None else (
                Path(path).resolve() == Path(other).resolve())
        except OSError:
            same = Path(path).resolve() == Path(other).resolve()
        if same:
            raise UsageError(f"{option} {name}: is the same file as {what} {other}; "
                             "give another file name")


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "a special file"


__all__ = [
    "MAX_ENI_BYTES",
    "check_output_file",
    "joints_path",
    "load_eni",
    "load_esi",
    "load_joints",
    "lola_path",
    "read_bounded",
    "read_eni_bytes",
]


def joints_path() -> Path:
    """The packaged joint parameters of the LOLA chain (``lolacli/motion/joints.toml``)."""
    from importlib.resources import files

    return Path(str(files("lolacli.motion").joinpath("joints.toml")))


def load_joints(path: str | Path | None = None) -> dict[str, JointParams]:
    """Read and parse a joints file (``None``: the packaged one). Every failure is an
    :class:`~lolacli.errors.InputError` (exit 3) naming the file."""
    from lolacli.motion.joint import parse_joints

    p = Path(path) if path is not None else joints_path()
    try:
        text = read_bounded(p, "a joints file", 1 << 20).decode("utf-8")
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", path=str(p)) from None
    return parse_joints(text, str(p))
