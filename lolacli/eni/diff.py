"""Differences between two ENIs (pure: two models in, a list of changes out).

Slaves are matched by station address (the stable name of a slave in an ENI; a moved slave
shows as a position change), cyclic commands by (frame, command) index, process-image
variables by name. Each change is ``added``, ``removed`` or ``changed`` with before/after,
and says itself in words (:meth:`Change.describe`): "slave 0x03E9 (1001): revision
0x00010420 in A, 0x00010421 in B", "slave 0x03EA (1002) Joint02 L Hip Roll: only in A".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from lolacli.eni.model import Eni, Slave, Variable
from lolacli.eni.report import datagram_dict, datagram_where
from lolacli.text import hex32, number, station

DIFF_SCHEMA = "lolacli.eni-diff/1"


@dataclass(frozen=True, slots=True)
class Change:
    kind: str  # "added", "removed", "changed"
    area: str  # "slave", "cyclic", "variable", "process_image", "cycle_time"
    key: str
    before: Any = None
    after: Any = None
    subject: str = ""  # how a person names it: "slave 0x03E9 (1001)", "cycle time"
    detail: str = ""  # said where it is only in one file: the slave's name, the command

    def describe(self) -> tuple[str, ...]:
        """The change in words, a line per field that differs; no Python values."""
        subject = self.subject or self.key
        if self.kind != "changed":
            named = f"{subject} {self.detail}" if self.detail else subject
            return (f"{named}: only in {'A' if self.kind == 'removed' else 'B'}",)
        return tuple(
            f"{subject}: {_field(field, self.before[field], self.after[field])}"
            for field in self.before
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "area": self.area,
            "key": self.key,
            "before": self.before,
            "after": self.after,
            "message": "; ".join(self.describe()),
        }


def _bits(v: int) -> str:
    return number(v, "bit", 0)


def _bytes(v: int) -> str:
    return number(v, "B", 0)


def _quoted(v: str) -> str:
    return '"' + " ".join(v.split()) + '"'


def _states(v: list[str]) -> str:
    return ", ".join(v) if v else "none"


#: field -> (how it is called, how its value is written)
_FIELDS: dict[str, tuple[str, Callable[[Any], str]]] = {
    "position": ("position", str),
    "name": ("name", _quoted),
    "vendor_id": ("vendor ID", hex32),
    "product_code": ("product code", hex32),
    "revision": ("revision", hex32),
    "station_address": ("station address", station),
    "auto_inc_address": ("auto-increment address", lambda v: f"0x{v:04X}"),
    "inputs_bits": ("inputs", _bits),
    "outputs_bits": ("outputs", _bits),
    "cmd": ("command", str),
    "adp": ("ADP", lambda v: f"0x{v:04X}"),
    "ado": ("ADO", lambda v: f"0x{v:04X}"),
    "logical_address": ("logical address", lambda v: f"0x{v:08X}"),
    "length_bytes": ("length", _bytes),
    "expected_wkc": ("expected WKC", str),
    "input_offset_bytes": ("input offset", _bytes),
    "output_offset_bytes": ("output offset", _bytes),
    "states": ("states", _states),
    "direction": ("direction", str),
    "bit_offset": ("offset", _bits),
    "bit_size": ("size", _bits),
    "data_type": ("data type", lambda v: v or "not given"),
    "inputs_bytes": ("inputs", _bytes),
    "outputs_bytes": ("outputs", _bytes),
    "cycle_time_ns": ("", lambda v: number(v / 1000, "µs")),
}


def _field(field: str, a: Any, b: Any) -> str:
    label, form = _FIELDS.get(field, (field.replace("_", " "), str))
    text_a = "not given" if a is None else form(a)
    text_b = "not given" if b is None else form(b)
    return f"{label} {text_a} in A, {text_b} in B".lstrip()


def _slave_fields(s: Slave) -> dict[str, Any]:
    return {
        "position": s.position,
        "name": s.name,
        "vendor_id": s.identity.vendor_id,
        "product_code": s.identity.product_code,
        "revision": s.identity.revision,
        "station_address": s.station_address,
        "auto_inc_address": s.auto_inc_address,
        "inputs_bits": s.inputs_bits,
        "outputs_bits": s.outputs_bits,
    }


def _var_fields(v: Variable) -> dict[str, Any]:
    return {
        "direction": v.direction.value,
        "bit_offset": v.bit_offset,
        "bit_size": v.bit_size,
        "data_type": v.data_type,
    }


@dataclass(frozen=True, slots=True)
class _Item:
    """One thing compared: its fields, and how a person names it."""

    fields: dict[str, Any]
    subject: str
    detail: str = ""


def _keyed_changes(area: str, before: dict[str, _Item], after: dict[str, _Item]) -> list[Change]:
    """added/removed/changed between two keyed dicts; ``changed`` carries only what differs."""
    out: list[Change] = []
    for key, item in before.items():
        if key not in after:
            out.append(Change("removed", area, key, item.fields, None, item.subject, item.detail))
        elif item.fields != after[key].fields:
            a, b = item.fields, after[key].fields
            fields = [f for f in a if a.get(f) != b.get(f)]
            out.append(
                Change(
                    "changed",
                    area,
                    key,
                    {f: a[f] for f in fields},
                    {f: b.get(f) for f in fields},
                    item.subject,
                )
            )
    out += [
        Change("added", area, key, None, item.fields, item.subject, item.detail)
        for key, item in after.items()
        if key not in before
    ]
    return out


def _slaves(eni: Eni) -> dict[str, _Item]:
    out: dict[str, _Item] = {}
    for s in eni.slaves:
        key, subject = f"station {s.station_address}", f"slave {station(s.station_address)}"
        if key in out:  # duplicate station addresses: fall back to the position
            key, subject = f"position {s.position}", f"{subject} at position {s.position}"
        out[key] = _Item(_slave_fields(s), subject, " ".join(s.name.split()))
    return out


def _cyclic(eni: Eni) -> dict[str, _Item]:
    out: dict[str, _Item] = {}
    for i, frame in enumerate(eni.cyclic_frames):
        for j, c in enumerate(frame.commands):
            d = datagram_dict(c)
            where = datagram_where(c)
            out[f"frame {i + 1} cmd {j + 1}"] = _Item(
                d,
                f"cyclic frame {i + 1}, command {j + 1} ({d['cmd']})",
                f"{where}, {_bytes(c.data_length_bytes)}",
            )
    return out


def _variables(eni: Eni) -> dict[str, _Item]:
    return {
        f"{v.direction.value}:{v.name}": _Item(
            _var_fields(v), f"{v.direction.value} {' '.join(v.name.split())}"
        )
        for v in eni.process_image.variables
    }


def _image(eni: Eni) -> dict[str, _Item]:
    pi = eni.process_image
    fields = {"inputs_bytes": pi.inputs_bytes, "outputs_bytes": pi.outputs_bytes}
    return {"process_image": _Item(fields, "process image")}


def _cycle(eni: Eni) -> dict[str, _Item]:
    return {"cycle_time": _Item({"cycle_time_ns": eni.cycle_time_ns}, "cycle time")}


AREAS = ("cycle_time", "slave", "cyclic", "process_image", "variable")


def diff_eni(a: Eni, b: Eni) -> tuple[Change, ...]:
    """Every difference from ``a`` to ``b``; empty when they configure the same bus."""
    changes: list[Change] = []
    changes += _keyed_changes("cycle_time", _cycle(a), _cycle(b))
    changes += _keyed_changes("slave", _slaves(a), _slaves(b))
    changes += _keyed_changes("cyclic", _cyclic(a), _cyclic(b))
    changes += _keyed_changes("process_image", _image(a), _image(b))
    changes += _keyed_changes("variable", _variables(a), _variables(b))
    return tuple(changes)


def diff_report(a: Eni, b: Eni, changes: tuple[Change, ...]) -> dict[str, Any]:
    """The ``lolacli.eni-diff/1`` document."""
    counts = {area: 0 for area in AREAS}
    for c in changes:
        counts[c.area] = counts.get(c.area, 0) + 1
    return {
        "schema": DIFF_SCHEMA,
        "a": a.source,
        "b": b.source,
        "equal": not changes,
        "change_count": len(changes),
        "changes_by_area": counts,
        "changes": [c.as_dict() for c in changes],
    }


__all__ = ["AREAS", "DIFF_SCHEMA", "Change", "diff_eni", "diff_report"]
