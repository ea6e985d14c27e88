"""SDO transactions rebuilt from the CoE mailbox traffic of a capture (pure).

The scanner hands over every returned datagram that looks like a mailbox message: a
physical write (FPWR/APWR, mailbox out: master → slave) or read (FPRD/APRD, mailbox in:
slave → master) in the process-memory area (ADO ≥ 0x1000) with WKC ≥ 1 and a plausible
mailbox header. Here each is decoded with :mod:`lolacli.wire.mailbox`,
:mod:`lolacli.wire.coe` and :mod:`lolacli.wire.sdo` and fed to a per-slave state machine
(slave = ADP of the configured-address datagram):

* upload: initiate upload request → initiate upload response (expedited: ≤ 4 bytes in
  the response; normal: complete size and data in the response, done when all data is
  there; else upload segment request/response pairs until the "last" bit: segmented);
* download: initiate download request (expedited, or normal followed by download
  segments) → initiate/segment download responses until the last segment is acknowledged;
* an abort (either side, CiA 301 abort code) ends the open transaction.

A mailbox read that repeats the previous message of the same slave (same non-zero
counter, same bytes) is a mailbox repeat and is counted once.

What each entry is comes from the one dictionary model and the one type lookup of the
``sdo`` commands (:mod:`lolacli.od.lookup`): :meth:`SdoTracker.describe` types every
completed transaction's bytes by the slave's PDO entries in the ENI (when one is given),
then the SDO Information answers the capture itself holds (Get Object/Entry Description
responses, kept per slave as a :class:`~lolacli.od.Dictionary`), then the CiA 301
objects, else a guess from the bytes — and gives its name, data type, where the type
came from and the value as ``sdo read`` would (``lolacli.sdo/1``'s ``value``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from lolacli.eni.model import Eni
    from lolacli.od import Dictionary, ObjectCode, OdEntry
    from lolacli.od.lookup import TypeLookup
    from lolacli.wire.mailbox import MailboxHeader
    from lolacli.wire.sdo import SdoUploadResponse

# The decoders (wire.mailbox, wire.coe, wire.sdo, od: ~35 ms to import) are imported by
# the first mailbox message: most captures of a running bus have none. They are kept in
# _wire then: an import statement per call cost ~6 us a message (4,000 in a LOLA
# bring-up).
_wire: Any = None


def _decoders() -> Any:
    """The decoder modules, imported once: ``.mailbox``, ``.coe``, ``.sdo``,
    ``.WireError``."""
    global _wire
    if _wire is None:
        from types import SimpleNamespace

        from lolacli.errors import WireError
        from lolacli.wire import coe, mailbox, sdo

        _wire = SimpleNamespace(mailbox=mailbox, coe=coe, sdo=sdo, WireError=WireError)
    return _wire

WRITE_COMMANDS = (2, 5)  # APWR, FPWR
#: Decoded mailbox messages kept by their bytes (polling repeats the same requests).
CACHE_ENTRIES = 4096


@dataclass(slots=True)
class SdoTransaction:
    """One SDO upload or download as seen on the wire."""

    slave: int
    index: int
    subindex: int
    kind: str  # "upload" | "download"
    start_frame: int
    start_ns: int
    transfer: str = "expedited"  # "normal" (size + data in the initiate), "segmented"
    size_bytes: int = 0
    segments: int = 0
    complete_access: bool = False
    status: str = "open"  # "ok" | "abort" | "open"
    abort_code: int | None = None
    end_frame: int | None = None
    end_ns: int | None = None
    data: bytearray = field(default_factory=bytearray)
    #: set by :meth:`SdoTracker.describe`: name ("" if none), data type name ("" if not
    #: typed), type source, value typed, value as printed
    name: str = ""
    data_type: str = ""
    type_source: str = ""
    value: Any = None
    value_text: str = ""

    def to_dict(self) -> dict[str, object]:
        from lolacli.od.lookup import json_value
        from lolacli.wire.sdo import abort_text

        return {
            "slave": self.slave,
            "index": self.index,
            "subindex": self.subindex,
            "object": f"0x{self.index:04X}:{self.subindex:02X}",
            "kind": self.kind,
            "transfer": self.transfer,
            "complete_access": self.complete_access,
            "size_bytes": self.size_bytes,
            "segments": self.segments,
            "status": self.status,
            "abort_code": None if self.abort_code is None else f"0x{self.abort_code:08X}",
            "abort_text": None if self.abort_code is None else abort_text(self.abort_code),
            "start_frame": self.start_frame,
            "end_frame": self.end_frame,
            "duration_us": None
            if self.end_ns is None
            else (self.end_ns - self.start_ns) / 1000.0,
            "data_hex": bytes(self.data[:64]).hex(),
            "name": self.name or None,
            "data_type": self.data_type or None,
            "type_source": self.type_source or None,
            "value": json_value(self.value),
            "value_text": self.value_text or None,
        }

    @property
    def raw(self) -> bytes | None:
        """The entry's bytes when the transaction carried them whole, else None."""
        if self.status != "ok" or self.kind not in ("upload", "download"):
            return None
        data = bytes(self.data)
        if self.transfer != "expedited" and self.size_bytes:
            if len(data) < self.size_bytes:
                return None
            data = data[: self.size_bytes]
        return data if data else None


#: (slave, entry, bytes) described once each, up to this many (bounded memory)
DESCRIBED_ENTRIES = 1 << 16


@dataclass(slots=True)
class MailboxStats:
    """Counts of the mailbox messages seen, by mailbox type and CoE service."""

    messages: int = 0
    repeats: int = 0
    undecodable: int = 0
    by_type: dict[str, int] = field(default_factory=dict)
    coe_by_service: dict[str, int] = field(default_factory=dict)
    sdo_info_messages: int = 0
    emergencies: int = 0


class SdoTracker:
    """Feed mailbox datagrams in file order; read :attr:`transactions` at the end."""

    def __init__(self) -> None:
        self.transactions: list[SdoTransaction] = []
        self.stats = MailboxStats()
        self._open: dict[int, SdoTransaction] = {}
        self._last_in: dict[int, tuple[int, bytes]] = {}
        self._cache: dict[bytes, tuple[MailboxHeader | None, int | None, object]] = {}
        #: SDO Information the slaves answered in the capture: entries, object names/codes
        self._info_entries: dict[int, dict[tuple[int, int], OdEntry]] = {}
        self._info_objects: dict[int, dict[int, tuple[str, ObjectCode]]] = {}

    def feed(self, frame: int, ts_ns: int, cmd: int, address: int, data: bytes) -> None:
        w = _wire or _decoders()
        slave = address & 0xFFFF
        decoded = self._cache.get(data)
        if decoded is None:
            decoded = _decode(data)
            if len(self._cache) < CACHE_ENTRIES:
                self._cache[data] = decoded
        header, service, message = decoded
        if header is None:
            self.stats.undecodable += 1
            return
        to_slave = cmd in WRITE_COMMANDS
        if not to_slave and header.counter != 0:
            wire = bytes(data[: 6 + header.length])
            if self._last_in.get(slave) == (header.counter, wire):
                self.stats.repeats += 1
                return
            self._last_in[slave] = (header.counter, wire)
        self.stats.messages += 1
        name = _type_name(header.mailbox_type)
        self.stats.by_type[name] = self.stats.by_type.get(name, 0) + 1
        if header.mailbox_type == w.mailbox.MailboxType.CoE:
            self._coe(frame, ts_ns, slave, service, message)

    def _coe(
        self, frame: int, ts_ns: int, slave: int, service: int | None, message: object
    ) -> None:
        CoeService = _wire.coe.CoeService  # noqa: N806 (the class)
        if service is None:
            self.stats.undecodable += 1
            return
        sname = service.name if isinstance(service, CoeService) else str(int(service))
        counts = self.stats.coe_by_service
        counts[sname] = counts.get(sname, 0) + 1
        if service == CoeService.EMERGENCY:
            self.stats.emergencies += 1
        elif service == CoeService.SDO_INFO:
            self.stats.sdo_info_messages += 1
            self._info(slave, message)
        elif service in (CoeService.SDO_REQUEST, CoeService.SDO_RESPONSE):
            if message is None:
                self.stats.undecodable += 1
            else:
                self._sdo(frame, ts_ns, slave, message)

    def _sdo(self, frame: int, ts_ns: int, slave: int, message: object) -> None:
        w = _wire.sdo
        if isinstance(message, w.SdoUploadRequest | w.SdoDownloadRequest):
            self._start(frame, ts_ns, slave, message)
            return
        txn = self._open.get(slave)
        if isinstance(message, w.SdoAbort):
            if txn is None or (txn.index, txn.subindex) != (message.index, message.subindex):
                txn = SdoTransaction(
                    slave, message.index, message.subindex, "unknown", frame, ts_ns
                )
                self.transactions.append(txn)
            txn.abort_code = message.code
            self._close(txn, frame, ts_ns, "abort")
            return
        if txn is None:
            return
        if isinstance(message, w.SdoUploadResponse):
            self._upload_response(txn, frame, ts_ns, message)
        elif isinstance(message, w.SdoUploadSegmentResponse):
            txn.segments += 1
            txn.transfer = "segmented"
            txn.data += message.data
            if message.last:
                self._close(txn, frame, ts_ns, "ok")
        elif isinstance(message, w.SdoDownloadSegmentRequest):
            txn.segments += 1
            txn.data += message.data
            txn.size_bytes = max(txn.size_bytes, len(txn.data))
            txn.transfer = "segmented"
            if message.last:
                txn.status = "last-sent"
        elif isinstance(message, w.SdoDownloadResponse):
            if txn.transfer != "segmented":
                self._close(txn, frame, ts_ns, "ok")
        elif isinstance(message, w.SdoDownloadSegmentResponse):
            if txn.status == "last-sent":
                self._close(txn, frame, ts_ns, "ok")

    def _start(self, frame: int, ts_ns: int, slave: int, message: Any) -> None:
        w = _wire.sdo
        kind = "upload" if isinstance(message, w.SdoUploadRequest) else "download"
        txn = SdoTransaction(slave, message.index, message.subindex, kind, frame, ts_ns)
        txn.complete_access = message.complete_access
        if isinstance(message, w.SdoDownloadRequest):
            txn.data += message.data
            if message.expedited:
                txn.size_bytes = len(message.data)
            else:
                txn.transfer = "normal"
                txn.size_bytes = message.complete_size
        self.transactions.append(txn)
        self._open[slave] = txn

    def _upload_response(
        self, txn: SdoTransaction, frame: int, ts_ns: int, message: SdoUploadResponse
    ) -> None:
        txn.data += message.data
        if message.expedited:
            txn.size_bytes = len(message.data)
            self._close(txn, frame, ts_ns, "ok")
            return
        txn.transfer = "normal"
        txn.size_bytes = message.complete_size
        if len(txn.data) >= message.complete_size:
            self._close(txn, frame, ts_ns, "ok")

    def _close(self, txn: SdoTransaction, frame: int, ts_ns: int, status: str) -> None:
        txn.status = status
        txn.end_frame = frame
        txn.end_ns = ts_ns
        if self._open.get(txn.slave) is txn:
            del self._open[txn.slave]

    def aborts(self) -> list[SdoTransaction]:
        return [t for t in self.transactions if t.status == "abort"]

    def _info(self, slave: int, message: object) -> None:
        """Keep what an SDO Information answer says of an object or entry (answers in
        fragments are not joined here: an entry's description fits one mailbox)."""
        from lolacli.od import info_entry, object_code
        from lolacli.wire.sdo import EntryDescriptionResponse, ObjectDescriptionResponse

        if isinstance(message, EntryDescriptionResponse) and not message.incomplete:
            name = message.description().decode("utf-8", "replace")
            entry = info_entry(
                message.index,
                message.subindex,
                name,
                message.data_type,
                message.bit_length,
                message.object_access,
            )
            self._info_entries.setdefault(slave, {})[(entry.index, entry.subindex)] = entry
        elif isinstance(message, ObjectDescriptionResponse) and not message.incomplete:
            code = object_code(message.object_code)
            self._info_objects.setdefault(slave, {})[message.index] = (message.name_text, code)

    def info_dictionary(self, slave: int) -> Dictionary | None:
        """What the capture's SDO Information answers describe of ``slave``'s objects."""
        from lolacli.od import Dictionary, ObjectCode, OdObject

        entries = self._info_entries.get(slave)
        if not entries:
            return None
        names = self._info_objects.get(slave, {})
        by_index: dict[int, list[OdEntry]] = {}
        for (index, _sub), entry in entries.items():
            by_index.setdefault(index, []).append(entry)
        objects = []
        for index, found in by_index.items():
            name, code = names.get(index, ("", ObjectCode.VAR))
            objects.append(OdObject.of(index, name, code, found))
        return Dictionary(objects, "sdo-info")

    def describe(self, eni: Eni | None = None) -> None:
        """Name and type every completed transaction's entry and decode its bytes (see
        the module docstring); complete-access transfers stay bytes."""
        if not self.transactions:
            return
        from lolacli.od.lookup import decode, format_value

        lookups: dict[int, TypeLookup] = {}
        # a master polls the same entries again and again (a statusword, a counter):
        # each (slave, entry, bytes) is named and decoded once
        seen: dict[tuple[int, int, int, bytes], tuple[str, str, object, str, str]] = {}
        for t in self.transactions:
            raw = t.raw
            if raw is None or t.complete_access:
                continue
            key = (t.slave, t.index, t.subindex, raw)
            said = seen.get(key)
            if said is None:
                lookup = lookups.get(t.slave)
                if lookup is None:
                    lookup = lookups[t.slave] = self._lookup(t.slave, eni)
                typed = lookup.entry_type(t.index, t.subindex, raw=raw)
                value, code, _note = decode(raw, typed)
                label = typed.type_label if code == typed.data_type else "OCTET_STRING"
                said = (typed.name, typed.source, value, label, format_value(value, code))
                if len(seen) < DESCRIBED_ENTRIES:
                    seen[key] = said
            t.name, t.type_source, t.value, t.data_type, t.value_text = said

    def _lookup(self, slave: int, eni: Eni | None) -> TypeLookup:
        from lolacli.od.lookup import TypeLookup

        dictionaries = []
        found = next((s for s in eni.slaves if s.station_address == slave), None) if eni else None
        if found is not None and eni is not None:
            from lolacli.eni.dictionary import from_eni  # (the ENI model: ~20 ms to import)

            described = from_eni(found, eni.source or "")
            if described is not None:
                dictionaries.append(described)
        return TypeLookup(tuple(dictionaries), self.info_dictionary(slave))


def _type_name(mailbox_type: int) -> str:
    if isinstance(mailbox_type, _wire.mailbox.MailboxType):
        return str(mailbox_type.name)
    return f"type{int(mailbox_type)}"


def _decode(data: bytes) -> tuple[MailboxHeader | None, int | None, object]:
    """Mailbox header, CoE service (None when not CoE or undecodable) and SDO message
    (None when not an SDO request/response or undecodable)."""
    w = _wire or _decoders()
    CoeService = w.coe.CoeService  # noqa: N806 (the class)
    try:
        mailbox = w.mailbox.decode_mailbox(data)
    except w.WireError:
        return None, None, None
    if mailbox.header.mailbox_type != w.mailbox.MailboxType.CoE:
        return mailbox.header, None, None
    try:
        service = w.coe.decode_coe_header(mailbox.payload).service
    except w.WireError:
        return mailbox.header, None, None
    if service not in (CoeService.SDO_REQUEST, CoeService.SDO_RESPONSE, CoeService.SDO_INFO):
        return mailbox.header, service, None
    try:
        return mailbox.header, service, w.sdo.decode_sdo(mailbox.payload)
    except w.WireError:
        return mailbox.header, service, None
