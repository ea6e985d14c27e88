"""EDS/DCF files as the one model: canopen's importer reads the file (its INI dialect,
``$NODEID``, DCF values), this adapter turns its ``ObjectDictionary`` into a
:class:`~lolacli.od.model.Dictionary`. canopen is not imported here: the object given is
duck-typed (``ODVariable``, ``ODArray``, ``ODRecord`` by their attributes), so this
package stays free of python-can's import time."""

from __future__ import annotations

from typing import Any

from lolacli.od.model import ARRAY, RECORD, VAR, Dictionary, OdEntry, OdObject
from lolacli.wire.datatypes import DataType, encode_value


def from_canopen(od: Any, path: str = "") -> Dictionary:
    """A ``canopen.ObjectDictionary`` (an EDS/DCF through canopen's importer)."""
    objects = []
    for index in od:
        obj = od[index]
        subindices = getattr(obj, "subindices", None)
        if subindices is None:  # an ODVariable
            objects.append(OdObject.of(index, obj.name, VAR, [_entry(obj)]))
            continue
        code = ARRAY if type(obj).__name__ == "ODArray" else RECORD
        entries = [_entry(subindices[s]) for s in sorted(subindices)]
        objects.append(OdObject.of(index, obj.name, code, entries))
    return Dictionary(objects, "eds", path)


def _entry(var: Any) -> OdEntry:
    data_type = var.data_type
    default = var.value if var.value is not None else var.default
    return OdEntry(
        var.index,
        var.subindex,
        var.name,
        data_type,
        var.access_type,
        None if data_type is None else len(var),
        _raw(data_type, default),
        bool(var.pdo_mappable),
    )


def _raw(data_type: int | None, default: Any) -> bytes:
    """The wire bytes of canopen's typed default (our codec: exact or refused); a default
    that does not fit its type is no default (empty)."""
    if default is None:
        return b""
    if isinstance(default, bytes | bytearray):
        return bytes(default)
    if data_type is None:
        return b""
    if data_type == DataType.VISIBLE_STRING and isinstance(default, str):
        return default.encode("latin-1", "replace")
    try:
        return encode_value(data_type, default)
    except ValueError:
        return b""


__all__ = ["from_canopen"]
