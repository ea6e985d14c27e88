"""Thin file loaders: read bytes, hand them to a pure parser, map OS errors to exit-3 errors."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from lolacli.errors import EniError, InputError

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


__all__ = [
    "MAX_ENI_BYTES",
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
