"""Differences between two ENIs (pure: two models in, a list of changes out).

Slaves are matched by station address (the stable name of a slave in an ENI; a moved slave
shows as a position change), cyclic commands by (frame, command) index, process-image
variables by name. Each change is ``added``, ``removed`` or ``changed`` with before/after.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from lolacli.eni.model import Eni, Slave, Variable
from lolacli.eni.report import datagram_dict

DIFF_SCHEMA = "lolacli.eni-diff/1"


@dataclass(frozen=True, slots=True)
class Change:
    kind: str  # "added", "removed", "changed"
    area: str  # "slave", "cyclic", "variable", "process_image", "cycle_time"
    key: str
    before: Any = None
    after: Any = None

    def as_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "area": self.area,
            "key": self.key,
            "before": self.before,
            "after": self.after,
        }


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


def _keyed_changes(
    area: str, before: dict[str, dict[str, Any]], after: dict[str, dict[str, Any]]
) -> list[Change]:
    """added/removed/changed between two keyed dicts; ``changed`` carries only what differs."""
    out: list[Change] = []
    for key in before:
        if key not in after:
            out.append(Change("removed", area, key, before[key], None))
        elif before[key] != after[key]:
            a, b = before[key], after[key]
            fields = [f for f in a if a.get(f) != b.get(f)]
            out.append(
                Change("changed", area, key, {f: a[f] for f in fields}, {f: b[f] for f in fields})
            )
    out += [Change("added", area, key, None, after[key]) for key in after if key not in before]
    return out


def _slaves(eni: Eni) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for s in eni.slaves:
        key = f"station {s.station_address}"
        if key in out:  # duplicate station addresses: fall back to the position
            key = f"position {s.position}"
        out[key] = _slave_fields(s)
    return out


def _cyclic(eni: Eni) -> dict[str, dict[str, Any]]:
    return {
        f"frame {i + 1} cmd {j + 1}": datagram_dict(c)
        for i, frame in enumerate(eni.cyclic_frames)
        for j, c in enumerate(frame.commands)
    }


def _variables(eni: Eni) -> dict[str, dict[str, Any]]:
    return {f"{v.direction.value}:{v.name}": _var_fields(v) for v in eni.process_image.variables}


def _image(eni: Eni) -> dict[str, dict[str, Any]]:
    pi = eni.process_image
    return {"process_image": {"inputs_bytes": pi.inputs_bytes, "outputs_bytes": pi.outputs_bytes}}


def _cycle(eni: Eni) -> dict[str, dict[str, Any]]:
    return {"cycle_time": {"cycle_time_ns": eni.cycle_time_ns}}


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
    counts = {area: 0 for area in ("cycle_time", "slave", "cyclic", "process_image", "variable")}
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


__all__ = ["DIFF_SCHEMA", "Change", "diff_eni", "diff_report"]
