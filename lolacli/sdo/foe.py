"""FoE firmware download and upload over the transports of ``sdo`` (EtherCAT only).

The same options open the same buses as :mod:`lolacli.sdo.session`: no ``--iface`` is
lolacli's own master against the emulated chain in process, ``--iface IF`` our master on
a live bus, ``--iface IF --backend soem`` pysoem. :func:`open_foe` gives a session whose
:meth:`~FoeSession.target` resolves SLAVE as ``sdo`` does; a target's :meth:`write` and
:meth:`read` each take the slave to BOOT with its bootstrap mailbox (from its SII), run
the transfer, and take it back to INIT (as SOEM's ``firm_update`` does), so a file
written is read back by a second BOOT.

Errors: an FoE error packet from the slave is :class:`~lolacli.errors.FoeError` (exit 1);
a slave that refuses BOOT is :class:`~lolacli.errors.TransportError` naming its AL status
code, as are no answer and a mailbox error (exit 4); a slave whose SII states no
bootstrap mailbox, or a CANopen transport, is :class:`~lolacli.errors.UsageError`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from lolacli.errors import FoeError, TransitionRefusedError, TransportError, UsageError
from lolacli.sdo.address import resolve_ref, slave_refs
from lolacli.sdo.session import LolaSession, SoemSession, TransportOptions

if TYPE_CHECKING:
    from lolacli.master.foe import FoeTransfer, SlaveAt

Progress = Callable[[int], None]

#: pysoem's FoE result codes below 0 (SOEM's ec_err_type): what each says
_SOEM_FOE_RESULTS = {
    -5: "the slave sent an FoE error (SOEM does not tell its code)",
    -6: "the file is larger than the buffer",
    -7: "a packet number was wrong",
    -10: "the file was not found (0x8001)",
    -3: "the slave sent an unexpected mailbox",
}
#: the largest file ``--backend soem`` reads (pysoem needs its size up front)
SOEM_READ_BUFFER_BYTES = 16 * 1024 * 1024


@dataclass(frozen=True, slots=True)
class FoeResult:
    """One transfer as the command reports it."""

    slave: str
    direction: str  # "write" or "read"
    name: str
    bytes: int
    packets: int | None
    busy: int | None
    seconds: float
    backend: str

    def to_dict(self) -> dict[str, Any]:
        """The fields of ``lolacli.foe/1`` (``None``: the backend does not tell)."""
        return {
            "slave": self.slave,
            "direction": self.direction,
            "name": self.name,
            "size_bytes": self.bytes,
            "packets": self.packets,
            "busy_answers": self.busy,
            "elapsed_s": round(self.seconds, 6),
            "backend": self.backend,
        }


class FoeTarget:
    """One slave's FoE (see the module docstring)."""

    label: str
    backend: str

    def write(
        self, name: str, data: bytes, password: int = 0, *, progress: Progress | None = None
    ) -> FoeResult:
        raise NotImplementedError

    def read(
        self,
        name: str,
        password: int = 0,
        *,
        max_bytes: int | None = None,
        progress: Progress | None = None,
    ) -> tuple[bytes, FoeResult]:
        raise NotImplementedError


class FoeSession:
    def target(self, spec: str | int) -> FoeTarget:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> FoeSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# ------------------------------------------------------------------ our master
class LolaFoeSession(FoeSession):
    """Our master (in process or ``--iface``), opened as ``sdo`` opens it."""

    def __init__(self, options: TransportOptions) -> None:
        self.session = LolaSession(options)
        self.bus = self.session.bus

    def target(self, spec: str | int) -> FoeTarget:
        from lolacli.master.foe import SlaveAt

        ref = resolve_ref(spec, self.bus.slaves(), source=self.session.source)
        slave = self.bus.eni.slaves[ref.position - 1]
        where = " ".join(filter(None, (f"slave {slave.position} ({slave.name})", self.bus.where)))
        at = SlaveAt(ref.position, ref.station_address, slave.name, where)
        return LolaFoeTarget(self, at, str(spec).strip())

    def close(self) -> None:
        self.session.close()


class LolaFoeTarget(FoeTarget):
    backend = "lolacli"

    def __init__(self, session: LolaFoeSession, slave: SlaveAt, label: str) -> None:
        self.session = session
        self.slave = slave
        self.label = label

    def _in_boot(self, run: Callable[[Any], FoeTransfer | tuple[bytes, FoeTransfer]]) -> Any:
        from lolacli.master.foe import FoeClient, enter_boot, leave_boot
        from lolacli.master.mailbox import MailboxClient

        bus = self.session.bus
        master = bus.bus.master
        try:
            layout = enter_boot(master, self.slave)
        except TransitionRefusedError as exc:
            raise TransportError(f"{self.slave.where} did not enter BOOT: {exc}") from None
        mailbox = MailboxClient(bus.port, layout, timeout_ns=bus.timeout_ns)
        try:
            result = run(FoeClient(mailbox, self.slave.where))
        except BaseException:
            _quietly(lambda: leave_boot(bus.port, self.slave))  # the first error tells
            raise
        leave_boot(bus.port, self.slave)
        return result

    def write(
        self, name: str, data: bytes, password: int = 0, *, progress: Progress | None = None
    ) -> FoeResult:
        done = self._in_boot(lambda c: c.write(name, data, password, progress=progress))
        return _result(self, "write", done)

    def read(
        self,
        name: str,
        password: int = 0,
        *,
        max_bytes: int | None = None,
        progress: Progress | None = None,
    ) -> tuple[bytes, FoeResult]:
        data, done = self._in_boot(
            lambda c: c.read(name, password, max_bytes=max_bytes, progress=progress)
        )
        return data, _result(self, "read", done)


def _quietly(call: Callable[[], object]) -> None:
    """``call()`` on the way out of a failed transfer: its own failure is not the news."""
    try:
        call()
    except Exception:  # noqa: BLE001 - the transfer's error is raised instead
        pass


def _result(target: FoeTarget, direction: str, done: FoeTransfer) -> FoeResult:
    return FoeResult(
        target.label,
        direction,
        done.name,
        done.bytes,
        done.packets,
        done.busy,
        done.elapsed_ns / 1e9,
        target.backend,
    )


# ------------------------------------------------------------------------- SOEM
class SoemFoeSession(FoeSession):
    """pysoem on ``--iface``, opened as ``sdo --backend soem`` opens it."""

    def __init__(self, options: TransportOptions) -> None:
        self.session = SoemSession(options)
        self.timeout_us = max(1000, int(options.timeout_s * 1e6))

    def target(self, spec: str | int) -> FoeTarget:
        s = self.session
        on_bus = s.bus.slaves()
        if s.eni is not None:
            ref = resolve_ref(spec, slave_refs(s.eni), source=s.eni.source or "the ENI")
        else:
            ref = resolve_ref(spec, on_bus, source=s.bus.iface)
        if not 1 <= ref.position <= len(on_bus):
            raise UsageError(f"no slave at position {ref.position} on {s.bus.iface}")
        return SoemFoeTarget(self, ref.position, str(spec).strip())

    def close(self) -> None:
        self.session.close()


class SoemFoeTarget(FoeTarget):
    backend = "soem"

    def __init__(self, session: SoemFoeSession, position: int, label: str) -> None:
        bus = session.session.bus
        self.pysoem = bus.pysoem
        self.slave = bus.master.slaves[position - 1]
        self.timeout_us = session.timeout_us
        self.label = label
        self.where = f"slave {position} ({self.slave.name}) on {bus.iface} via pysoem"

    def _state(self, state: int, name: str) -> None:
        s = self.slave
        s.state = state
        s.write_state()
        if s.state_check(state, 5_000_000) != state:
            code = s.al_status
            raise TransportError(f"{self.where} did not enter {name} (AL status code 0x{code:04X})")

    def _in_boot(self, run: Callable[[], Any]) -> Any:
        p = self.pysoem
        self._state(p.INIT_STATE, "INIT")
        out, out_bytes = struct.unpack("<HH", self.slave.eeprom_read(p.SiiOffset.BOOT_RX_MBX))
        inn, in_bytes = struct.unpack("<HH", self.slave.eeprom_read(p.SiiOffset.BOOT_TX_MBX))
        if not (out_bytes and in_bytes):
            raise UsageError(f"{self.where}: its SII states no bootstrap mailbox: no FoE")
        self.slave.amend_mbx("out", out, out_bytes)
        self.slave.amend_mbx("in", inn, in_bytes)
        self._state(p.BOOT_STATE, "BOOT")
        try:
            result = run()
        except BaseException:
            _quietly(lambda: self._state(p.INIT_STATE, "INIT"))  # the first error tells
            raise
        self._state(p.INIT_STATE, "INIT")
        return result

    def _check(self, result: int) -> None:
        if result > 0:
            return
        if result == 0:
            raise TransportError(f"{self.where}: FoE: no answer")
        text = _SOEM_FOE_RESULTS.get(result, f"SOEM FoE result {result}")
        code = 0x8001 if result == -10 else None
        raise FoeError(self.where, code, text)

    def write(
        self, name: str, data: bytes, password: int = 0, *, progress: Progress | None = None
    ) -> FoeResult:
        import time

        start = time.monotonic()

        def run() -> int:
            return int(self.slave.foe_write(name, password, bytes(data), self.timeout_us))

        self._check(self._in_boot(run))
        if progress is not None:
            progress(len(data))
        seconds = time.monotonic() - start
        return FoeResult(self.label, "write", name, len(data), None, None, seconds, "soem")

    def read(
        self,
        name: str,
        password: int = 0,
        *,
        max_bytes: int | None = None,
        progress: Progress | None = None,
    ) -> tuple[bytes, FoeResult]:
        import time

        start = time.monotonic()
        size = max_bytes or SOEM_READ_BUFFER_BYTES

        def run() -> bytes:
            return bytes(self.slave.foe_read(name, password, size, self.timeout_us))

        data = self._in_boot(run)
        if not data:  # pysoem gives SOEM's result no way out: an error reads as no data
            raise FoeError(self.where, None, "the slave sent no data (SOEM tells no FoE error)")
        if progress is not None:
            progress(len(data))
        seconds = time.monotonic() - start
        return data, FoeResult(self.label, "read", name, len(data), None, None, seconds, "soem")


def open_foe(options: TransportOptions) -> FoeSession:
    """The transport the options ask for (as :func:`lolacli.sdo.session.open_session`);
    UsageError for CANopen, which has no FoE."""
    from lolacli.sdo.session import BACKENDS

    if options.backend not in BACKENDS:
        raise UsageError(f"unknown --backend {options.backend!r} (one of {', '.join(BACKENDS)})")
    if options.backend == "soem":
        if options.iface is None:
            raise UsageError("--backend soem drives a live bus: give --iface IF too")
        return SoemFoeSession(options)
    return LolaFoeSession(options)


__all__ = [
    "FoeResult",
    "FoeSession",
    "FoeTarget",
    "LolaFoeSession",
    "LolaFoeTarget",
    "SoemFoeSession",
    "SoemFoeTarget",
    "open_foe",
]
