"""SDO over EtherCAT through pysoem (SOEM): ``--backend soem --iface IF``.

SOEM scans the bus (``config_init``: addresses, mailboxes, PREOP; tried
:data:`SCAN_ATTEMPTS` times) and runs the CoE transfers itself. Timeouts, raised from
SOEM's defaults because the emulated chain (``bus emulate``) answers single datagrams in
0.2–2 ms on a loaded host today and stalls for 10–20 ms at worst (hardware behind a
switch or a slow NIC can too): datagram return :data:`FRAME_TIMEOUT_US` (SOEM: 2 ms), the
slave-counting broadcast :data:`SAFE_TIMEOUT_US` (20 ms), both mailbox waits the caller's
``timeout_s`` (SOEM: 20 ms to send, 700 ms to receive). A bus that does not answer at
all fails in about 2 s (exit 4).
"""

from __future__ import annotations

from typing import Any

from lolacli.errors import TransportError, UsageError
from lolacli.od import Dictionary, from_sdo_info
from lolacli.sdo.address import SlaveRef, resolve_ref
from lolacli.sdo.client import abort_error
from lolacli.text import plural

FRAME_TIMEOUT_US = 20_000
#: SOEM's wait for the broadcast that counts the slaves (its default: 20 ms).
SAFE_TIMEOUT_US = 100_000
SCAN_ATTEMPTS = 3
#: Upload buffer: SOEM refuses objects larger than the buffer it is given.
UPLOAD_BUFFER_BYTES = 65_536
#: SOEM sets station addresses 0x1001, 0x1002, … in chain order (ecx_config_init).
SOEM_FIRST_STATION = 0x1001


class SoemBus:
    """An open pysoem master on an interface, its slaves in PREOP."""

    def __init__(self, iface: str, *, timeout_s: float = 1.0) -> None:
        import pysoem

        self.pysoem = pysoem
        self.iface = iface
        microseconds = max(1000, int(timeout_s * 1e6))
        timeouts = pysoem.settings.timeouts
        timeouts.ret = max(timeouts.ret, FRAME_TIMEOUT_US)
        timeouts.safe = max(timeouts.safe, SAFE_TIMEOUT_US)
        # SOEM waits tx_mailbox for the slave to take a mailbox write and rx_mailbox for
        # its answer; both are the caller's timeout (SOEM's 20 ms send wait loses
        # segmented uploads to a slave that stalls, as the emulated chain does under load)
        timeouts.tx_mailbox = max(timeouts.tx_mailbox, microseconds)
        timeouts.rx_mailbox = microseconds
        self.master = pysoem.Master()
        try:
            self.master.open(iface)
        except Exception as exc:  # ConnectionError: no such interface, no permission
            raise TransportError(f"cannot open {iface}: {exc}") from None
        found = 0
        for _ in range(SCAN_ATTEMPTS):  # a scan lost to a stalled frame is tried again
            try:
                found = self.master.config_init()
            except Exception as exc:
                self.close()
                raise TransportError(f"{iface}: bus scan failed: {exc}") from None
            if found > 0:
                break
        if found <= 0:
            self.close()
            raise TransportError(f"{iface}: no slaves answering")
        self.master.sdo_read_timeout = microseconds
        self.master.sdo_write_timeout = microseconds
        self.master.state_check(pysoem.PREOP_STATE, 2_000_000)

    def slaves(self) -> tuple[SlaveRef, ...]:
        from lolacli.eni.model import Identity

        return tuple(
            SlaveRef(i + 1, SOEM_FIRST_STATION + i, s.name, Identity(s.man, s.id, s.rev))
            for i, s in enumerate(self.master.slaves)
        )

    def client(self, position: int, label: str = "") -> SoemClient:
        if not 1 <= position <= len(self.master.slaves):
            raise UsageError(
                f"no slave at position {position} on {self.iface} "
                f"({plural(len(self.master.slaves), 'slave')})"
            )
        return SoemClient(self, position, label)

    def close(self) -> None:
        try:
            self.master.close()
        except Exception:  # never opened
            pass


class SoemClient:
    """One slave's CoE SDO server through SOEM."""

    def __init__(self, bus: SoemBus, position: int, label: str = "") -> None:
        self.bus = bus
        self.position = position
        self.slave = bus.master.slaves[position - 1]
        name = label or self.slave.name
        self.description = f"slave {position} ({name}) on {bus.iface} via pysoem"

    def upload(self, index: int, subindex: int, *, complete_access: bool = False) -> bytes:
        return bytes(
            self._call(
                index,
                subindex,
                self.slave.sdo_read,
                index,
                subindex,
                UPLOAD_BUFFER_BYTES,
                complete_access,
            )
        )

    def download(
        self, index: int, subindex: int, data: bytes, *, complete_access: bool = False
    ) -> None:
        self._call(
            index, subindex, self.slave.sdo_write, index, subindex, bytes(data), complete_access
        )

    def dictionary(self) -> Dictionary | None:
        pysoem = self.bus.pysoem
        try:
            objects = self.slave.od
        except pysoem.SdoInfoError:
            return None
        except Exception as exc:
            raise TransportError(f"{self.description}: SDO Information: {exc}") from None
        return from_sdo_info(
            (
                o.index,
                _text(o.name),
                o.object_code,
                o.data_type,
                o.bit_length,
                (
                    (sub, _text(e.name), e.data_type, e.bit_length, e.obj_access)
                    for sub, e in enumerate(o.entries)
                ),
            )
            for o in objects
        )

    def sdo_info(self) -> None:
        """pysoem reads SDO Information only whole (``slave.od``: seconds on a large
        drive), too slow to type one read by it; ``sdo list`` uses it."""
        return None

    def close(self) -> None:
        self.bus.close()

    def _call(self, index: int, subindex: int, fn: Any, *args: Any) -> Any:
        pysoem = self.bus.pysoem
        try:
            return fn(*args)
        except pysoem.SdoError as exc:
            raise abort_error(index, subindex, exc.abort_code) from None
        except pysoem.WkcError as exc:
            raise TransportError(
                f"0x{index:04X}:{subindex:02X}: {self.description}: no answer "
                f"(working counter {getattr(exc, 'wkc', 0)})"
            ) from None
        except (pysoem.MailboxError, pysoem.PacketError) as exc:
            raise TransportError(
                f"0x{index:04X}:{subindex:02X}: {self.description}: {exc}"
            ) from None


def _text(name: Any) -> str:
    return name.decode("latin-1") if isinstance(name, bytes) else str(name)


def resolve_on_bus(bus: SoemBus, spec: str) -> SlaveRef:
    """SLAVE against what the bus reports (position, SOEM's station address, SII name)."""
    return resolve_ref(spec, bus.slaves(), source=bus.iface)


__all__ = ["FRAME_TIMEOUT_US", "SoemBus", "SoemClient", "resolve_on_bus"]
