"""SDO through lolacli's own master: the emulated chain in process, or a live bus.

:class:`LolaBus` puts :class:`~lolacli.master.preop.PreopBus` on a transport: with an
ENI (the embedded LOLA chain, ``--eni``), a slave asked for is brought to PREOP by its
INIT → PREOP InitCmds; without one (``--iface`` alone), the bus is configured from its
SII first (station addresses 0x1001…, mailbox offsets and sizes, names) as SOEM does.
:class:`LolaClient` is the :class:`~lolacli.sdo.client.SdoClient` of one slave over the
master's CoE mailbox (:mod:`lolacli.master.mailbox`) and its SDO Information service
(:mod:`lolacli.master.sdo_info`).

Errors: an abort is :class:`~lolacli.errors.SdoAbortError` (exit 1); no answer, a
mailbox error or a slave that does not reach PREOP is
:class:`~lolacli.errors.TransportError` (exit 4).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from lolacli.errors import (
    SdoAbortError,
    TransitionRefusedError,
    TransportError,
    UsageError,
    WireError,
)
from lolacli.od import Dictionary, OdEntry, OdObject, info_entry, object_code
from lolacli.sdo.address import SlaveRef, slave_refs

if TYPE_CHECKING:
    from lolacli.eni.model import Eni, Slave
    from lolacli.master.mailbox import MailboxClient
    from lolacli.master.mailbox import SdoClient as MasterSdo
    from lolacli.master.transport import Transport

#: the longest wait for one frame on a live bus (a lost frame is sent again after it)
MAX_FRAME_TIMEOUT_NS = 50_000_000
MIN_FRAME_TIMEOUT_NS = 2_000_000


class LolaBus:
    """Our master on ``transport``, slaves brought to PREOP as they are asked for."""

    def __init__(
        self,
        transport: Transport,
        eni: Eni | None,
        *,
        where: str,
        name: str = "",
        timeout_s: float = 1.0,
    ) -> None:
        """``where`` ends the slaves' descriptions ("on eth0"); ``name`` names the bus in
        messages about it as a whole ("eth0")."""
        from lolacli.master.core import MasterOptions
        from lolacli.master.preop import PreopBus, configure_from_sii

        self.transport = transport
        self.where = where
        self.timeout_ns = max(1, int(timeout_s * 1e9))
        # a lost frame is sent again; all tries of a frame together take about --timeout
        frame_ns = min(MAX_FRAME_TIMEOUT_NS, max(MIN_FRAME_TIMEOUT_NS, self.timeout_ns // 4))
        retries = max(3, math.ceil(self.timeout_ns / frame_ns) - 1)
        options = MasterOptions(frame_timeout_ns=frame_ns, frame_retries=retries)
        try:
            if eni is None:
                eni, master = configure_from_sii(transport, where=name, options=options)
                self.bus = PreopBus(eni, transport, master=master)
            else:
                self.bus = PreopBus(eni, transport, options)
        except BaseException:
            transport.close()
            raise
        self.eni = eni
        self.port = self.bus.master  # mailbox frames: one datagram each

    def slaves(self) -> tuple[SlaveRef, ...]:
        return slave_refs(self.eni)

    def client(self, ref: SlaveRef, label: str = "") -> LolaClient:
        """The SDO client of the slave at ``ref.position``, brought to PREOP first."""
        slave = self.eni.slaves[ref.position - 1]
        name = label or slave.name
        what = f"slave {slave.position} ({slave.name}){self._on}"
        mailbox = slave.mailbox
        if mailbox is None:
            raise UsageError(f"{what} has no mailbox: no SDO")
        if mailbox.protocols and "CoE" not in mailbox.protocols:
            raise UsageError(
                f"{what} does not speak CoE (mailbox protocols: {', '.join(mailbox.protocols)})"
            )
        try:
            up = self.bus.bring_up(slave)
        except TransitionRefusedError as exc:
            raise TransportError(f"{what} did not reach PREOP: {exc}") from None
        return LolaClient(self, up, f"slave {slave.position} ({name}){self._on}")

    @property
    def _on(self) -> str:
        return f" {self.where}" if self.where else ""

    def close(self) -> None:
        self.bus.close()


class LolaClient:
    """One slave's CoE SDO server through our master (see the module docstring)."""

    def __init__(self, bus: LolaBus, slave: Slave, description: str) -> None:
        from lolacli.master.mailbox import SdoClient as MasterSdo

        self.bus = bus
        self.slave = slave
        self.description = description
        self.mailbox: MailboxClient = bus.bus.master.mailbox(slave)
        self.mailbox.port = bus.port
        self.mailbox.timeout_ns = bus.timeout_ns
        self.sdo: MasterSdo = MasterSdo(self.mailbox)
        self._info: SdoInfoEntries | None = None

    def upload(self, index: int, subindex: int, *, complete_access: bool = False) -> bytes:
        try:
            return self.sdo.upload(index, subindex, complete_access=complete_access)
        except (TransportError, WireError) as exc:
            raise self._failed(index, subindex, exc) from None

    def download(
        self, index: int, subindex: int, data: bytes, *, complete_access: bool = False
    ) -> None:
        try:
            self.sdo.download(index, subindex, data, complete_access=complete_access)
        except (TransportError, WireError) as exc:
            raise self._failed(index, subindex, exc) from None

    def sdo_info(self) -> SdoInfoEntries:
        """The slave's SDO Information service as a source of entry types and names,
        asked entry by entry (:mod:`lolacli.od.lookup`)."""
        if self._info is None:
            self._info = SdoInfoEntries(self)
        return self._info

    def dictionary(self) -> Dictionary | None:
        """The slave's own description (SDO Information); None when it has no such
        service (an SDO Info Error or mailbox error answer to Get OD List)."""
        from lolacli.master.sdo_info import od_list, read_dictionary

        try:
            indexes = od_list(self.mailbox)
        except (SdoAbortError, WireError):
            return None
        except TransportError as exc:
            raise TransportError(f"{self.description}: SDO Information: {exc}") from None
        try:
            return read_dictionary(self.mailbox, indexes)
        except (TransportError, WireError) as exc:
            raise TransportError(f"{self.description}: SDO Information: {exc}") from None

    def close(self) -> None:
        """Nothing of its own: the session closes the bus."""

    def _failed(self, index: int, subindex: int, exc: Exception) -> TransportError:
        return TransportError(f"0x{index:04X}:{subindex:02X}: {self.description}: {exc}")


class SdoInfoEntries:
    """One slave's SDO Information, asked as needed (Get Entry Description, Get Object
    Description) and kept for the session. A slave without the service (an SDO Info
    Error or mailbox error answer to the first question, or none) is not asked again;
    an entry it does not describe is None."""

    source = "sdo-info"

    def __init__(self, client: LolaClient) -> None:
        self.client = client
        self.available = True
        self._entries: dict[tuple[int, int], OdEntry | None] = {}
        self._objects: dict[int, OdObject | None] = {}

    def entry(self, index: int, subindex: int) -> OdEntry | None:
        key = (index, subindex)
        if key not in self._entries:
            self._entries[key] = self._ask_entry(index, subindex)
        return self._entries[key]

    def object(self, index: int) -> OdObject | None:
        if index not in self._objects:
            self._objects[index] = self._ask_object(index)
        return self._objects[index]

    def _ask_entry(self, index: int, subindex: int) -> OdEntry | None:
        from lolacli.master.sdo_info import entry_description

        if not self.available:
            return None
        try:
            e = entry_description(self.client.mailbox, index, subindex)
        except SdoAbortError:
            return None  # the service answers, but not for this entry
        except (WireError, TransportError):
            self.available = False
            return None
        name = e.description().decode("utf-8", "replace")
        return info_entry(index, subindex, name, e.data_type, e.bit_length, e.object_access)

    def _ask_object(self, index: int) -> OdObject | None:
        from lolacli.master.sdo_info import object_description

        if not self.available:
            return None
        try:
            o = object_description(self.client.mailbox, index)
        except SdoAbortError:
            return None
        except (WireError, TransportError):
            self.available = False
            return None
        entries = [self.entry(index, sub) for sub in range(o.max_subindex + 1)]
        found = [e for e in entries if e is not None]
        return OdObject.of(index, o.name_text, object_code(o.object_code), found)


__all__ = ["LolaBus", "LolaClient", "SdoInfoEntries"]
