"""Read an ESI (ETG.2000 EtherCAT Slave Information, ``<EtherCATInfo>``) device description.

Pure: bytes in, an :class:`EsiFile` out; every failure is an
:class:`~lolacli.errors.EniError` (exit 3) naming ``source`` and, where known, the line.
The XML goes through the same hardened loader as the ENI parser
(:func:`lolacli.eni.parser.safe_tree`): no DTD, no entities, no network.

What is read per ``Descriptions/Devices/Device`` (ETG.2000 §5): ``<Type ProductCode=
RevisionNo=>``, ``<Name LcId=…>`` (1033 preferred), ``<GroupType>``, the ``Physics``
attribute, ``<Fmmu>``, ``<Sm>`` (kind, StartAddress, DefaultSize, ControlByte, Enable),
``<RxPdo>``/``<TxPdo>`` with their ``Sm`` attribute and entries, ``<Mailbox>`` protocols and
CoE flags, ``<Dc>/<OpMode>``, ``<Eeprom>`` (ByteSize, ConfigData) and the object dictionary
(``<Profile>/<Dictionary>``, :mod:`lolacli.eni.esi_dictionary`). Numbers are decimal,
``#x…`` or ``0x…``.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from typing import Any

from lolacli.eni.esi_dictionary import read_dictionary
from lolacli.eni.model import Direction, Identity, Pdo, PdoEntry
from lolacli.eni.parser import ENI_ROOTS, parse_number, safe_tree
from lolacli.errors import EniError
from lolacli.od.model import Dictionary

_El = Any  # an lxml element (lxml ships no type information)

_TRUE = frozenset({"1", "true", "yes"})
_ENGLISH = "1033"

#: Mailbox protocol element names of ``<Mailbox>`` (ETG.2000 Table 30).
MAILBOX_PROTOCOLS = ("AoE", "EoE", "CoE", "FoE", "SoE", "VoE")


@dataclass(frozen=True, slots=True)
class EsiCoe:
    """``<Mailbox>/<CoE>`` attributes (ETG.2000 Table 31)."""

    sdo_info: bool = False
    pdo_assign: bool = False
    pdo_config: bool = False
    pdo_upload: bool = False
    complete_access: bool = False


@dataclass(frozen=True, slots=True)
class EsiSyncManager:
    """One ``<Sm>``: ``kind`` is its text (MBoxOut, MBoxIn, Outputs, Inputs or empty)."""

    index: int
    kind: str
    start_address: int
    default_size_bytes: int
    control: int
    enable: bool


@dataclass(frozen=True, slots=True)
class EsiDcOpMode:
    """One ``<Dc>/<OpMode>``; ``cycle_time_sync0`` is the ESI value (0: set by the master)."""

    name: str
    assign_activate: int
    cycle_time_sync0: int = 0
    cycle_time_sync0_factor: int = 1


@dataclass(frozen=True, slots=True)
class EsiEeprom:
    byte_size: int | None = None
    config_data: bytes = b""


@dataclass(frozen=True, slots=True)
class EsiDevice:
    identity: Identity
    name: str
    type_name: str = ""
    group: str = ""
    physics: str = ""
    profile_no: int | None = None
    fmmus: tuple[str, ...] = ()
    sync_managers: tuple[EsiSyncManager, ...] = ()
    pdos: tuple[Pdo, ...] = ()
    mailbox_protocols: tuple[str, ...] = ()
    coe: EsiCoe | None = None
    dc_op_modes: tuple[EsiDcOpMode, ...] = ()
    eeprom: EsiEeprom | None = None
    line: int | None = None
    dictionary: Dictionary | None = None

    def sync_manager(self, kind: str) -> EsiSyncManager | None:
        """The first SM of ``kind`` (case-insensitive), or None."""
        low = kind.lower()
        return next((s for s in self.sync_managers if s.kind.lower() == low), None)

    @property
    def assigned_pdos(self) -> tuple[Pdo, ...]:
        """The default-assigned PDOs: those with an ``Sm`` attribute or ``Mandatory``."""
        return tuple(p for p in self.pdos if p.sync_manager is not None or p.mandatory)


@dataclass(frozen=True, slots=True)
class EsiFile:
    vendor_id: int
    vendor_name: str
    devices: tuple[EsiDevice, ...]
    source: str = "<string>"

    def find(self, vendor_id: int, product_code: int, revision: int) -> EsiDevice | None:
        """The device of that identity: exact revision first, else the same product with the
        highest revision; None when the vendor or product is not described here."""
        same = [
            d
            for d in self.devices
            if d.identity.vendor_id == vendor_id and d.identity.product_code == product_code
        ]
        exact = [d for d in same if d.identity.revision == revision]
        if exact:
            return exact[0]
        return max(same, key=lambda d: d.identity.revision, default=None)


def parse_esi(data: bytes | str, source: str = "<string>") -> EsiFile:
    """Parse an ESI document. Raises :class:`EniError` (path ``source``, line) on any defect."""
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    try:
        root = safe_tree(raw, source)
    except EniError as exc:  # the shared loader speaks of ENIs
        message = exc.message.replace("an ENI", "an ESI")
        raise EniError(message, path=exc.path, line=exc.line) from exc
    return _EsiReader(source).esi(root)


class _EsiReader:
    def __init__(self, source: str) -> None:
        self.source = source

    def error(self, el: _El | None, message: str) -> EniError:
        return EniError(message, path=self.source, line=None if el is None else el.sourceline)

    def number(self, el: _El, text: str | None, what: str, default: int | None = None) -> int:
        if text is None or not text.strip():
            if default is None:
                raise self.error(el, f"{what}: missing number")
            return default
        try:
            return parse_number(text)
        except ValueError:
            raise self.error(el, f"{what}: not a number: {text.strip()[:40]!r}") from None

    def child_number(self, el: _El, name: str, default: int | None = None) -> int:
        node = el.find(name)
        text = None if node is None else node.text
        return self.number(el if node is None else node, text, f"<{name}>", default)

    def text(self, el: _El | None, name: str) -> str:
        node = None if el is None else el.find(name)
        return "" if node is None or node.text is None else str(node.text).strip()

    # -- document --

    def esi(self, root: _El) -> EsiFile:
        if root.tag in ENI_ROOTS:
            raise self.error(
                root, f"this is an ENI (<{root.tag}>), not an ESI device description "
                f"(read it with: lolacli eni inspect {shlex.quote(self.source)})",
            )
        if root.tag != "EtherCATInfo":
            raise self.error(root, f"not an ESI: root element is <{root.tag}>, not <EtherCATInfo>")
        vendor = root.find("Vendor")
        if vendor is None:
            raise self.error(root, "<EtherCATInfo> has no <Vendor>")
        vendor_id = self.child_number(vendor, "Id")
        devices = root.findall("Descriptions/Devices/Device")
        return EsiFile(
            vendor_id=vendor_id,
            vendor_name=self.name(vendor),
            devices=tuple(self.device(d, vendor_id) for d in devices),
            source=self.source,
        )

    def name(self, el: _El) -> str:
        """The ``<Name>`` in LcId 1033 (English), else the first one."""
        names = el.findall("Name")
        english = [n for n in names if str(n.get("LcId", "")).strip() == _ENGLISH]
        chosen = (english or names or [None])[0]
        return "" if chosen is None or chosen.text is None else str(chosen.text).strip()

    def device(self, el: _El, vendor_id: int) -> EsiDevice:
        kind = el.find("Type")
        if kind is None:
            raise self.error(el, "<Device> has no <Type>")
        identity = Identity(
            vendor_id=vendor_id,
            product_code=self.number(kind, kind.get("ProductCode"), "ProductCode", 0),
            revision=self.number(kind, kind.get("RevisionNo"), "RevisionNo", 0),
        )
        mailbox = el.find("Mailbox")
        profile = el.find("Profile/ProfileNo")
        if profile is None:
            profile = el.find("Profile/ChannelInfo/ProfileNo")
        return EsiDevice(
            identity=identity,
            name=self.name(el),
            type_name=(kind.text or "").strip(),
            group=self.text(el, "GroupType"),
            physics=str(el.get("Physics", "")),
            profile_no=None if profile is None else self.number(profile, profile.text, "ProfileNo"),
            fmmus=tuple((f.text or "").strip() for f in el.iterchildren("Fmmu")),
            sync_managers=tuple(self.sm(i, s) for i, s in enumerate(el.iterchildren("Sm"))),
            pdos=self.pdos(el),
            mailbox_protocols=self.protocols(mailbox),
            coe=self.coe(mailbox),
            dc_op_modes=self.dc(el.find("Dc")),
            eeprom=self.eeprom(el.find("Eeprom")),
            line=el.sourceline,
            dictionary=read_dictionary(el.find("Profile/Dictionary"), self),
        )

    def sm(self, index: int, el: _El) -> EsiSyncManager:
        return EsiSyncManager(
            index=index,
            kind=(el.text or "").strip(),
            start_address=self.number(el, el.get("StartAddress"), "Sm StartAddress", 0),
            default_size_bytes=self.number(el, el.get("DefaultSize"), "Sm DefaultSize", 0),
            control=self.number(el, el.get("ControlByte"), "Sm ControlByte", 0),
            enable=str(el.get("Enable", "0")).strip().lower() in _TRUE,
        )

    def pdos(self, el: _El) -> tuple[Pdo, ...]:
        out = [self.pdo(p, Direction.OUTPUT) for p in el.iterchildren("RxPdo")]
        out += [self.pdo(p, Direction.INPUT) for p in el.iterchildren("TxPdo")]
        return tuple(out)

    def pdo(self, el: _El, direction: Direction) -> Pdo:
        sm = el.get("Sm")
        return Pdo(
            index=self.child_number(el, "Index"),
            name=self.text(el, "Name"),
            direction=direction,
            sync_manager=None if sm is None else self.number(el, sm, "Pdo Sm"),
            entries=tuple(self.entry(e) for e in el.iterchildren("Entry")),
            fixed=str(el.get("Fixed", "")).strip().lower() in _TRUE,
            mandatory=str(el.get("Mandatory", "")).strip().lower() in _TRUE,
        )

    def entry(self, el: _El) -> PdoEntry:
        return PdoEntry(
            index=self.child_number(el, "Index"),
            subindex=self.child_number(el, "SubIndex", 0),
            bit_size=self.child_number(el, "BitLen"),
            name=self.text(el, "Name"),
            data_type=self.text(el, "DataType"),
        )

    def protocols(self, mailbox: _El | None) -> tuple[str, ...]:
        if mailbox is None:
            return ()
        return tuple(p for p in MAILBOX_PROTOCOLS if mailbox.find(p) is not None)

    def coe(self, mailbox: _El | None) -> EsiCoe | None:
        el = None if mailbox is None else mailbox.find("CoE")
        if el is None:
            return None

        def flag(name: str) -> bool:
            return str(el.get(name, "")).strip().lower() in _TRUE

        return EsiCoe(
            sdo_info=flag("SdoInfo"),
            pdo_assign=flag("PdoAssign"),
            pdo_config=flag("PdoConfig"),
            pdo_upload=flag("PdoUpload"),
            complete_access=flag("CompleteAccess"),
        )

    def dc(self, el: _El | None) -> tuple[EsiDcOpMode, ...]:
        if el is None:
            return ()
        return tuple(self.op_mode(m) for m in el.iterchildren("OpMode"))

    def op_mode(self, el: _El) -> EsiDcOpMode:
        sync0 = el.find("CycleTimeSync0")
        factor = 1 if sync0 is None else self.number(sync0, sync0.get("Factor"), "Factor", 1)
        return EsiDcOpMode(
            name=self.text(el, "Name"),
            assign_activate=self.child_number(el, "AssignActivate", 0),
            cycle_time_sync0=self.child_number(el, "CycleTimeSync0", 0),
            cycle_time_sync0_factor=factor,
        )

    def eeprom(self, el: _El | None) -> EsiEeprom | None:
        if el is None:
            return None
        size = el.find("ByteSize")
        config = "".join(self.text(el, "ConfigData").split())
        try:
            data = bytes.fromhex(config)
        except ValueError:
            raise self.error(el, f"<ConfigData>: not hex data: {config[:40]!r}") from None
        byte_size = None if size is None else self.number(size, size.text, "<ByteSize>")
        return EsiEeprom(byte_size=byte_size, config_data=data)


__all__ = [
    "MAILBOX_PROTOCOLS",
    "EsiCoe",
    "EsiDcOpMode",
    "EsiDevice",
    "EsiEeprom",
    "EsiFile",
    "EsiSyncManager",
    "parse_esi",
]
