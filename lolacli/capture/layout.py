"""What the master configured, as the capture shows it (pure).

The scanner flags the master's writes of station addresses (0x0010), AL control (0x0120)
and FMMUs (0x0600-0x06FF) (:func:`lolacli.capture.scan._config_write`); here they are
decoded with :mod:`lolacli.wire.registers` into

* the station address of each position (``APWR 0x0010``: auto-increment ADP = -position),
* each slave's active FMMUs (the master's own process-image layout: which logical bytes a
  slave reads or writes), the last write of each FMMU winning; a broadcast write (SOEM and
  KickCAT clear every FMMU with ``BWR 0x0600`` first) applies to every slave,
* the AL states the master requested, and when,

and the AL status reads the scanner counted are summed up per slave (last state and
status code). :mod:`lolacli.capture.wkc` computes expected working counters from the
layout; :mod:`lolacli.capture.verdict` reports slaves that did not reach OP.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from lolacli.text import station as station_name
from lolacli.wire.al import AlState, al_state_name, al_status_text
from lolacli.wire.commands import Command

if TYPE_CHECKING:
    from lolacli.wire.registers import Fmmu

# lolacli.wire.registers (~6 ms: the register map, FMMU, sync-manager and SII types) is
# imported by the first configuration write: a capture of a running bus has none.

_CONFIGURED = (Command.FPWR, Command.FPRW)
_AUTO_INCREMENT = (Command.APWR, Command.APRW)
_BROADCAST = (Command.BWR, Command.BRW)


@dataclass(frozen=True, slots=True)
class Target:
    """Whom a write addresses: one station, one position (0-based), or every slave."""

    kind: str  # "station" | "position" | "all"
    value: int = 0

    def __str__(self) -> str:
        if self.kind == "station":
            return f"station {station_name(self.value)}"
        if self.kind == "position":
            return f"position {self.value + 1}"
        return "all slaves"


def target_of(cmd: int, adp: int) -> Target | None:
    if cmd in _CONFIGURED:
        return Target("station", adp)
    if cmd in _AUTO_INCREMENT:
        return Target("position", (-adp) & 0xFFFF)
    if cmd in _BROADCAST:
        return Target("all")
    return None


@dataclass(frozen=True, slots=True)
class FmmuWrite:
    """One FMMU the master wrote: in which frame, to whom, which one."""

    frame: int
    target: Target
    index: int
    fmmu: Fmmu


@dataclass(frozen=True, slots=True)
class AlRequest:
    """One AL control write: in which frame, to whom, the value written."""

    frame: int
    target: Target
    value: int

    @property
    def state(self) -> int:
        return self.value & 0x0F


@dataclass(slots=True)
class MasterLayout:
    """The master's configuration seen in the capture (empty when it is not in it)."""

    stations: dict[int, int] = field(default_factory=dict)  # position (0-based) → station
    fmmu_writes: list[FmmuWrite] = field(default_factory=list)
    al_requests: list[AlRequest] = field(default_factory=list)

    def feed(self, frame: int, cmd: int, adp: int, ado: int, data: bytes) -> None:
        """One outgoing write the scanner flagged (its data as sent)."""
        target = target_of(cmd, adp)
        if target is None:
            return
        from lolacli.wire.registers import FMMU_BYTES, Register, decode_fmmu

        end = ado + len(data)
        sa = Register.STATION_ADDRESS
        if target.kind == "position" and ado <= sa and end >= sa + 2:
            self.stations[target.value] = struct.unpack_from("<H", data, sa - ado)[0]
        ac = Register.AL_CONTROL
        if ado <= ac and end >= ac + 2:
            value = struct.unpack_from("<H", data, ac - ado)[0]
            self.al_requests.append(AlRequest(frame, target, value))
        first = max(0, -(-(ado - Register.FMMU) // FMMU_BYTES))
        for k in range(first, 16):
            start = Register.FMMU + k * FMMU_BYTES
            if start + FMMU_BYTES > min(end, Register.FMMU + 16 * FMMU_BYTES):
                break
            if start >= ado:
                self.fmmu_writes.append(FmmuWrite(frame, target, k, decode_fmmu(data, start - ado)))

    # --- the layout at the end of the capture ----------------------------------------------
    def position_of(self, station: int) -> int | None:
        for pos, st in self.stations.items():
            if st == station:
                return pos
        return None

    def slave_key(self, target: Target) -> Target:
        """A station where the capture tells it, else the position."""
        if target.kind == "position" and target.value in self.stations:
            return Target("station", self.stations[target.value])
        return target

    def fmmus(self) -> dict[Target, list[Fmmu]]:
        """Active FMMUs per slave (station, or position when its station is unknown)."""
        last: dict[tuple[Target, int], FmmuWrite] = {}
        broadcast: dict[int, FmmuWrite] = {}
        for w in self.fmmu_writes:
            if w.target.kind == "all":
                broadcast[w.index] = w
            else:
                last[(self.slave_key(w.target), w.index)] = w
        out: dict[Target, list[Fmmu]] = {}
        for (slave, index), w in sorted(last.items(), key=lambda kv: kv[1].frame):
            cleared = broadcast.get(index)
            if cleared is not None and cleared.frame > w.frame:
                continue  # a later broadcast write (zeros, in practice) replaced it
            if w.fmmu.enabled and w.fmmu.length_bytes > 0:
                out.setdefault(slave, []).append(w.fmmu)
        return out

    def requested(self, station: int | None) -> AlRequest | None:
        """The last AL state request that reached ``station`` (None: broadcasts only)."""
        pos = self.position_of(station) if station is not None else None
        best: AlRequest | None = None
        for r in self.al_requests:
            hit = (r.target.kind == "all"
                   or (r.target.kind == "station" and r.target.value == station)
                   or (r.target.kind == "position" and r.target.value == pos))
            if hit and (best is None or r.frame > best.frame):
                best = r
        return best


def covered(fmmus: list[Fmmu], address: int, length: int) -> tuple[bool, bool]:
    """(reads, writes): whether a logical datagram [address, address + length) overlaps
    one of these FMMUs of type read (inputs) / write (outputs)."""
    reads = writes = False
    for f in fmmus:
        if address < f.logical_start + f.length_bytes and f.logical_start < address + length:
            reads = reads or bool(f.type & 0x01)
            writes = writes or bool(f.type & 0x02)
    return reads, writes


@dataclass(frozen=True, slots=True)
class AlStatusRead:
    """The AL status one slave (or, by BRD, the whole bus) reported last."""

    cmd: int
    station: int  # 0 for broadcast reads
    status: int
    code: int | None  # AL status code, where the read covered 0x0134
    answered: int  # WKC: 1 for one slave, the number of slaves for BRD
    count: int
    first_frame: int
    last_frame: int

    @property
    def broadcast(self) -> bool:
        return self.cmd in (Command.BRD, Command.BRW)

    @property
    def in_op(self) -> bool:
        return self.status & 0x1F == AlState.OP

    def describe(self) -> str:
        text = al_state_name(self.status)
        if self.code is not None and self.code:
            text += f", AL status code 0x{self.code:04X} ({al_status_text(self.code)})"
        return text


def last_al_status(rows: list[tuple[int, ...]]) -> list[AlStatusRead]:
    """The last AL status read per station (and of the broadcast reads), from the
    scanner's observations ``(cmd, station, code, wkc, status, count, first, last)``."""
    best: dict[tuple[bool, int], AlStatusRead] = {}
    for cmd, station, code, wkc, status, count, first, last in rows:
        read = AlStatusRead(cmd, station, status, None if code < 0 else code, wkc, count,
                            first, last)
        key = (read.broadcast, station)
        if key not in best or read.last_frame > best[key].last_frame:
            best[key] = read
    return sorted(best.values(), key=lambda r: (r.broadcast, r.station))
