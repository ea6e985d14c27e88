"""What the user typed: ``INDEX[:SUB]`` and ``SLAVE`` (pure: text and models in, values out).

SLAVE on EtherCAT is one of

* ``3`` — a position, 1-based in chain order (as ``eni inspect`` numbers them);
* ``@1003`` / ``@0x03EB`` — a station (configured) address;
* ``Joint04 L Knee`` — a slave name: exact first, then case-insensitive, then a unique
  case-insensitive part of one name.

On CANopen SLAVE is the node ID (1..127).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from lolacli.errors import UsageError
from lolacli.text import station
from lolacli.wire.datatypes import parse_int

if TYPE_CHECKING:  # the ENI modules load only where an ENI is read (start-up time)
    from lolacli.eni.model import Eni, Identity


@dataclass(frozen=True, slots=True)
class ObjectAddress:
    """An object entry: ``index`` and ``subindex`` (0 when the user gave none)."""

    index: int
    subindex: int = 0

    def __str__(self) -> str:
        return f"0x{self.index:04X}:{self.subindex:02X}"


def parse_object(text: str) -> ObjectAddress:
    """``0x6041``, ``0x1018:1``, ``0x1018:0x01``, ``6041:01``, ``#x1018:01``.

    Index and subindex are hexadecimal with or without a prefix, as every object listing
    (ours included: ``0x1018:0A``) writes them: ``6041`` is 0x6041 and ``:10`` is 16.
    """
    raw = text.strip()
    head, sep, tail = raw.partition(":")
    try:
        index = _hex(head)
        subindex = _hex(tail) if sep else 0
    except ValueError:
        raise UsageError(
            f"{text!r} is not an object address INDEX[:SUB] (like 0x1018:01)"
        ) from None
    if not 0 <= index <= 0xFFFF:
        raise UsageError(f"object index {text!r} is outside 0x0000..0xFFFF")
    if not 0 <= subindex <= 0xFF:
        raise UsageError(f"subindex of {text!r} is outside 0..255")
    return ObjectAddress(index, subindex)


def _hex(text: str) -> int:
    t = text.strip().lower()
    for prefix in ("0x", "#x"):
        if t.startswith(prefix):
            t = t[len(prefix) :]
    if not t:
        raise ValueError(text)
    return int(t, 16)


# --- slaves ---------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SlaveRef:
    """A slave as a transport or an ENI knows it."""

    position: int  # 1-based
    station_address: int
    name: str
    identity: Identity | None = None


def slave_refs(eni: Eni) -> tuple[SlaveRef, ...]:
    return tuple(SlaveRef(s.position, s.station_address, s.name, s.identity) for s in eni.slaves)


def resolve_slave(spec: str | int, eni: Eni) -> SlaveRef:
    """The ENI slave that SLAVE names (position, ``@station`` or name); UsageError if none."""
    return resolve_ref(spec, slave_refs(eni), source=eni.source or "the ENI")


def resolve_ref(
    spec: str | int, slaves: Sequence[SlaveRef], *, source: str = "the bus"
) -> SlaveRef:
    """The slave of ``slaves`` that SLAVE names (a position, also as an int; ``@station``;
    a name); UsageError with the choices if none."""
    text = str(spec).strip()
    if not text:
        raise UsageError("SLAVE is empty: give a position, @station address or name")
    if text.startswith("@"):
        try:
            address = parse_int(text[1:], "station address")
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        for s in slaves:
            if s.station_address == address:
                return s
        raise UsageError(f"no slave with station address {station(address)} in {source}")
    if text.isdigit() or (text[:1] in "+-" and text[1:].isdigit()):
        position = int(text)
        for s in slaves:
            if s.position == position:
                return s
        raise UsageError(
            f"no slave at position {position} in {source} (positions 1 to {len(slaves)}; "
            "a station address is written @ADDR)"
        )
    return _by_name(text, slaves, source)


def _by_name(text: str, slaves: Sequence[SlaveRef], source: str) -> SlaveRef:
    exact = [s for s in slaves if s.name == text]
    if len(exact) == 1:
        return exact[0]
    low = text.lower()
    folded = [s for s in slaves if s.name.lower() == low]
    if len(folded) == 1:
        return folded[0]
    part = [s for s in slaves if low in s.name.lower()]
    if len(part) == 1:
        return part[0]
    many = exact or folded or part
    if many:
        names = ", ".join(f"{s.position}: {s.name}" for s in many[:5])
        raise UsageError(f"slave name {text!r} is ambiguous in {source} ({names})")
    raise UsageError(f"no slave named {text!r} in {source}")


def parse_node_id(spec: str | int) -> int:
    """A CANopen node ID (1..127) from SLAVE or ``--node``."""
    try:
        node = parse_int(str(spec), "node ID")
    except ValueError:
        raise UsageError(f"{spec!r} is not a CANopen node ID (1..127)") from None
    if not 1 <= node <= 127:
        raise UsageError(f"CANopen node ID {node} is outside 1..127")
    return node


__all__ = [
    "ObjectAddress",
    "SlaveRef",
    "parse_node_id",
    "parse_object",
    "resolve_ref",
    "resolve_slave",
    "slave_refs",
]
