"""The one model of a verdict's findings, for every command that gives a verdict.

A :class:`Finding` says one thing that is wrong or worth knowing: a stable ``kind``
(scripts filter on it: ``lost``, ``wkc-mismatch``, ``duplicate-station``...), a
``severity`` (a ``failure`` makes the command exit 1), one line of ``message`` for people,
and where it shows: the capture's frame numbers (``frames``), the simulation's cycles
(``cycles``), the slave's 1-based position (``slave``) when one slave is concerned, and
how many times it happened (``count``). ``eni validate``, ``capture analyze`` and
``bus simulate`` all report their findings with it, as the same JSON object.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

#: frame or cycle numbers kept per finding (the first ones, in order)
SHOWN = 5


class Severity(StrEnum):
    FAILURE = "failure"  # the command's verdict is "fail" (exit 1)
    WARNING = "warning"
    INFO = "info"


_ORDER = {Severity.FAILURE: 0, Severity.WARNING: 1, Severity.INFO: 2}


@dataclass(frozen=True, slots=True)
class Finding:
    """One thing a check found: its kind, how bad it is, and where (frames, cycles,
    slave)."""

    kind: str
    severity: Severity
    message: str
    frames: tuple[int, ...] = ()
    cycles: tuple[int, ...] = ()
    slave: int | None = None
    count: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "severity": self.severity.value,
            "message": self.message,
            "frames": list(self.frames),
            "cycles": list(self.cycles),
            "slave": self.slave,
            "count": self.count,
        }


def first(numbers: Iterable[Any], n: int = SHOWN) -> tuple[int, ...]:
    """The ``n`` lowest distinct numbers, in order."""
    return tuple(sorted({int(x) for x in numbers})[:n])


@dataclass(slots=True)
class Findings:
    """Findings as a verdict collects them."""

    items: list[Finding] = field(default_factory=list)

    def add(
        self,
        kind: str,
        severity: Severity | str,
        message: str,
        frames: Iterable[Any] = (),
        count: int = 0,
        *,
        cycles: Iterable[Any] = (),
        slave: int | None = None,
    ) -> Finding:
        finding = Finding(
            kind, Severity(severity), message, first(frames), first(cycles), slave, count
        )
        self.items.append(finding)
        return finding

    @property
    def failed(self) -> bool:
        return failed(self.items)

    def of(self, *kinds: str) -> list[Finding]:
        return [f for f in self.items if f.kind in kinds]

    def ordered(self) -> list[Finding]:
        return ordered(self.items)


def failed(findings: Iterable[Finding]) -> bool:
    """Whether any finding is a failure: the verdict is "fail"."""
    return any(f.severity is Severity.FAILURE for f in findings)


def verdict(findings: Iterable[Finding]) -> str:
    """``"fail"`` when a finding is a failure, else ``"pass"``."""
    return "fail" if failed(findings) else "pass"


def ordered(findings: Iterable[Finding]) -> list[Finding]:
    """Failures first, then warnings, then notes; each group in the order found."""
    return sorted(findings, key=lambda f: _ORDER[f.severity])


__all__ = ["SHOWN", "Finding", "Findings", "Severity", "failed", "first", "ordered", "verdict"]
