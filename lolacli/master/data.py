"""Live process data by ENI variable name (`bus data`, like IgH's ``ethercat data``).

:class:`LiveData` runs our master in OP on a transport (the emulated chain in process, or
a raw socket), links a Bus Variable (:func:`~lolacli.master.variables.variable_for`) to
every ENI process-image variable the filter selects, and reads them typed as the ENI
says: its ``DataType`` (UINT, DINT, REAL, BOOL, ``ARRAY … OF BYTE`` as hex) and bit size.
The ENI (ETG.2100) carries no scale factor or unit for a variable, so the typed value is
the value. ``NAME=VALUE`` writes an output: the name must be an output variable of the
ENI (an unknown one is a UsageError naming the closest names), the value must parse as
its type (:func:`lolacli.wire.datatypes.parse_text`) and fit it; all are checked before
anything is written. A sample (:meth:`LiveData.sample`) is one ``lolacli.data/1``
object: the cycle, the time since OP, the AL states seen, each variable's value.
"""

from __future__ import annotations

import difflib
import fnmatch
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from lolacli.eni.model import Direction, Eni, Variable
from lolacli.errors import LinkError, TransportError, UsageError
from lolacli.master.core import Master, MasterOptions
from lolacli.master.transport import Transport
from lolacli.master.variables import BusBytes, BusVariable, variable_for
from lolacli.wire.datatypes import DataType, data_type_from_name, parse_text
from lolacli.wire.registers import AlState, al_state_name

SCHEMA = "lolacli.data/1"


def select(eni: Eni, patterns: Sequence[str]) -> list[Variable]:
    """The ENI's process-image variables whose names match any of the shell-style
    ``patterns`` (case-insensitive; a pattern without wildcards matches as a substring);
    all of them without patterns. UsageError when patterns select nothing."""
    variables = list(eni.process_image.variables)
    if not patterns:
        return variables
    globs = [p if any(c in p for c in "*?[") else f"*{p}*" for p in patterns]
    chosen = [v for v in variables if any(fnmatch.fnmatch(v.name.lower(), g.lower())
                                          for g in globs)]  # fmt: skip
    if not chosen:
        raise UsageError(f"--filter {' '.join(patterns)!r} matches none of the "
                         f"{len(variables)} process-image variables of the ENI")  # fmt: skip
    return chosen


def _suggest(name: str, names: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, list(names), n=2, cutoff=0.5)
    if not close:
        low = name.lower()
        close = [n for n in names if low in n.lower()][:2]
    return f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


@dataclass(frozen=True, slots=True)
class Setting:
    """An output and the value ``NAME=VALUE`` gives it (checked, not yet written)."""

    variable: Variable
    value: Any
    text: str


def parse_setting(eni: Eni, item: str) -> Setting:
    """``NAME=VALUE`` checked against the ENI: an output variable, a value of its type
    that fits (UsageError naming the problem otherwise)."""
    name, eq, text = item.rpartition("=")
    if not eq or not name.strip():
        raise UsageError(f"--set {item!r}: expected NAME=VALUE")
    name = name.strip()
    by_name = {v.name: v for v in eni.process_image.variables}
    v = by_name.get(name)
    if v is None:
        outputs = [n for n, x in by_name.items() if x.direction is Direction.OUTPUT]
        raise UsageError(f"--set: no variable {name!r} in the ENI's process image"
                         + _suggest(name, outputs))  # fmt: skip
    if v.direction is not Direction.OUTPUT:
        raise UsageError(f"--set: {name!r} is an input; only outputs can be written")
    bus = variable_for(v)
    bus.name = v.name
    try:
        value = _parse(v, bus, text)
        bus.check(value)
    except (ValueError, LinkError) as exc:
        why = str(exc).split(": ", 1)[-1] if isinstance(exc, LinkError) else str(exc)
        raise UsageError(f"--set {name}={text}: {why} ({v.data_type or '?'}, "
                         f"{v.bit_size} bits)") from None  # fmt: skip
    return Setting(v, value, text)


def _parse(v: Variable, bus: BusVariable, text: str) -> Any:
    data_type = data_type_from_name(v.data_type)
    if isinstance(bus, BusBytes):
        return parse_text(DataType.OCTET_STRING, text)
    if data_type is None or data_type in (DataType.BITARR8, DataType.BITARR16,
                                          DataType.BITARR32):  # fmt: skip
        return parse_text(DataType.UNSIGNED64, text)
    value = parse_text(data_type, text)
    if data_type == DataType.BOOLEAN:
        return bool(value)
    return value


def show(value: Any) -> Any:
    """A value as JSON and the table show it (bytes as hex)."""
    if isinstance(value, (bytes, bytearray)):
        return bytes(value).hex()
    if isinstance(value, float):
        return round(value, 9)
    return value


class LiveData:
    """Our master in OP on ``transport`` with ``variables`` linked (see the module
    docstring). Close with :meth:`leave`."""

    def __init__(
        self,
        eni: Eni,
        transport: Transport,
        variables: Sequence[Variable],
        *,
        rate_hz: float | None = None,
        realtime: bool = False,
        frame_timeout_ns: int | None = None,
    ) -> None:
        options = MasterOptions(cycle_time_ns=round(1e9 / rate_hz) if rate_hz else None)
        if realtime:
            options.realtime = True
        if frame_timeout_ns is not None:
            options.frame_timeout_ns = frame_timeout_ns
        self.eni = eni
        self.master = Master(eni, transport, options=options)
        self.variables = list(variables)
        self.linked: list[tuple[Variable, BusVariable]] = []
        for v in self.variables:
            bus = variable_for(v)
            try:
                self.master.link(v.name, bus)
            except LinkError:
                continue  # outside the image the cyclic frames carry: not shown
            self.linked.append((v, bus))
        self.start_ns = 0
        self.refusals: list[Any] = []

    def bring_up(self) -> None:
        """INIT to OP as the ENI says (slaves that refuse are left behind and named in
        each sample's states); TransportError when nothing answers."""
        self.refusals = list(self.master.bring_up(AlState.OP, strict=False))
        if self.master.stats.slaves_found == 0:
            raise TransportError("no slave answers (no frame came back)")
        self.master.start_cyclic()
        self.start_ns = self.master.now_ns()

    def write(self, settings: Sequence[Setting]) -> None:
        """Put the settings into the outputs image (all in one cycle)."""
        image = self.master.image
        with image.lock:
            for s in settings:
                bus = variable_for(s.variable)
                image.link(s.variable.name, bus)
                bus.value = s.value

    def run_for(self, duration_ns: int) -> None:
        """Cycle for ``duration_ns``."""
        self.master.idle(duration_ns)

    def values(self) -> dict[str, Any]:
        snap = self.master.image.snapshot
        outputs = bytes(self.master.image.outputs)
        return {
            v.name: show(bus.read(snap.data if v.direction is Direction.INPUT else outputs))
            for v, bus in self.linked
        }

    def sample(self) -> dict[str, Any]:
        """One ``lolacli.data/1`` object: the process image as it is now."""
        stats = self.master.stats
        return {
            "schema": SCHEMA,
            "cycle": stats.cycles,
            "t_s": round((self.master.now_ns() - self.start_ns) / 1e9, 6),
            "wall_time": round(time.time(), 6),
            "lost_frames": stats.frames_lost,
            "values": self.values(),
        }

    def states(self) -> list[dict[str, Any]]:
        """Every slave's AL state (the master's view, read now)."""
        out = []
        for position, status in self.master.al_states():
            slave = self.eni.slaves[position - 1]
            out.append(
                {
                    "position": position,
                    "name": slave.name,
                    "state": al_state_name(status) if status is not None else None,
                }
            )
        return out

    def leave(self) -> None:
        """Stop cycling (the last frames taken), slaves back to INIT where they go."""
        try:
            if self.master.cycling:
                self.master.drain()
            self.master.transition("OI" if self.master.state == AlState.OP else "SI",
                                   strict=False)  # fmt: skip
        except (TransportError, ValueError):
            pass

    def table(self) -> list[dict[str, Any]]:
        """The linked variables with type, size, direction and value (the human form)."""
        values = self.values()
        return [
            {
                "name": v.name,
                "direction": v.direction.value,
                "type": v.data_type or f"{v.bit_size} bits",
                "bits": v.bit_size,
                "bit_offset": v.bit_offset,
                "value": values[v.name],
            }
            for v, _bus in self.linked
        ]


__all__ = ["SCHEMA", "LiveData", "Setting", "parse_setting", "select", "show"]
