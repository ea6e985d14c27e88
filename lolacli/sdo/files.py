"""Object dictionaries from files: EDS/DCF through canopen's importer, ESI through ours.

Every failure is an :class:`~lolacli.errors.InputError` (exit 3) naming the file.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lolacli.errors import InputError
from lolacli.files import MAX_ENI_BYTES, read_bounded
from lolacli.od import Dictionary
from lolacli.od.eds import from_canopen

if TYPE_CHECKING:  # the ESI modules load only where an ESI is read (start-up time)
    from lolacli.eni.esi import EsiDevice, EsiFile
    from lolacli.eni.model import Identity


def read_text_file(path: str | Path, what: str) -> str:
    """A small text file (EDS, check file), bounded like ENI reads; exit 3 on failure."""
    name = str(path)
    data = read_bounded(path, what, MAX_ENI_BYTES)
    if b"\x00" in data:
        raise InputError(f"binary data, not {what}", path=name)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")  # EDS files from Windows tools are often cp1252


def load_eds_od(path: str | Path, node_id: int | None = None) -> Any:
    """A ``canopen.ObjectDictionary`` from an EDS or DCF file (``$NODEID`` resolved with
    ``node_id``)."""
    from canopen.objectdictionary import eds

    from lolacli.sdo.canopen_client import quiet_canopen

    quiet_canopen()
    text = read_text_file(path, "an EDS")
    stream = io.StringIO(text)
    stream.name = str(path)
    try:
        od = eds.import_eds(stream, node_id)  # type: ignore[no-untyped-call]
    except Exception as exc:  # configparser, ValueError, KeyError, … from the importer
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise InputError(
            f"not a valid EDS/DCF: {type(exc).__name__}: {reason}"[:300], path=str(path)
        ) from None
    if len(od) == 0:
        raise InputError("not an EDS/DCF: no objects", path=str(path))
    return od


def load_eds(path: str | Path, node_id: int | None = None) -> Dictionary:
    """An EDS/DCF file's object dictionary (exit 3 when it does not load)."""
    return from_canopen(load_eds_od(path, node_id), str(path))


def esi_device(files: list[EsiFile], identity: Identity | None) -> EsiDevice | None:
    """The ESI device with a dictionary that describes ``identity`` (exact revision first,
    else the same product's highest); with no identity, the only such device if one."""
    with_od = [(f, d) for f in files for d in f.devices if d.dictionary is not None]
    if identity is not None:
        for f in files:
            found = f.find(identity.vendor_id, identity.product_code, identity.revision)
            if found is not None and found.dictionary is not None:
                return found
        return None
    return with_od[0][1] if len(with_od) == 1 else None


def esi_dictionary(files: list[EsiFile], identity: Identity | None) -> Dictionary | None:
    device = esi_device(files, identity)
    if device is None or device.dictionary is None:
        return None
    source = next((f.source for f in files if device in f.devices), "")
    return device.dictionary.relabeled("esi", source)


__all__ = ["esi_device", "esi_dictionary", "load_eds", "load_eds_od", "read_text_file"]
