"""What the bench verbs (`bus reg`, `bus sii`, `bus alias`, `bus state`) share: the bus
opened on --iface, SLAVE resolved as `sdo` and `bus scan` name slaves (a position, an
@station address, a name), the --timeout option."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from lolacli.master.bench import BenchBus, BenchSlave



@contextmanager
def bench_bus(iface: str, frame_timeout: str = "20ms") -> Iterator[BenchBus]:
    """Our master on ``iface`` with the slaves counted; closed afterwards."""
    from lolacli.master.bench import BenchBus
    from lolacli.master.transport import RawSocketTransport

    timeout_ns = duration_ns(frame_timeout, "--frame-timeout")
    transport = RawSocketTransport(iface)
    try:
        yield BenchBus(transport, where=iface, timeout_ns=timeout_ns)
    finally:
        transport.close()


def duration_ns(text: str, option: str) -> int:
    from lolacli.timing.model import parse_duration_ns

    ns = parse_duration_ns(text, None, option)
    if ns <= 0:
        raise typer.BadParameter(f"{text!r} is not a positive duration", param_hint=option)
    return ns


def resolve(bus: BenchBus, spec: str) -> BenchSlave:
    """The slave SLAVE names on the bus (names read from the SIIs only when needed)."""
    from lolacli.sdo.address import SlaveRef, resolve_ref

    text = spec.strip()
    by_number = text.startswith("@") or text.isdigit()
    if not by_number:
        bus.read_names()
    refs = [SlaveRef(s.position, s.station_address, s.name) for s in bus.slaves]
    ref = resolve_ref(text, refs, source=f"the bus on {bus.where}")
    return bus.slaves[ref.position - 1]


def label(s: BenchSlave) -> str:
    """``slave 3 (0x1003 (4099))``, with its name when known."""
    from lolacli.text import station

    out = f"slave {s.position}"
    if s.station_address:
        out += f" ({station(s.station_address)})"
    return out + (f" {s.name}" if s.name else "")
