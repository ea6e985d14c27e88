"""The bench verbs over our master, without an ENI: ESC registers, the SII EEPROM, AL states.

What `bus reg`, `bus sii`, `bus alias` and `bus state` do, as IgH's ``ethercat reg_read``,
``sii_read``/``sii_write``, ``alias`` and ``states`` do, on any interface:

* :class:`BenchBus` counts the slaves (BRD 0x0000) and reads each one's station address,
  alias and AL status by auto-increment address; every access afterwards is by
  auto-increment address too (APRD/APWR), so nothing has to be configured first and a
  station address someone else gave is left alone;
* registers: :func:`read_register`/:func:`write_register` on a span the user named
  (:func:`lolacli.wire.registers.parse_register`), the named registers in it decoded by
  :func:`decode_registers` (AL status and its code's text, DL status per port, error
  counters, DC times, FMMUs and sync managers); a write into a block a master configures
  (:data:`~lolacli.wire.registers.CONFIGURATION_BLOCKS`) of a slave in SAFEOP or OP is
  refused unless forced;
* the EEPROM: :func:`describe_sii` decodes a whole image (header with the checksum, the
  STRINGS, GENERAL, FMMU, SYNCM, TXPDO, RXPDO and DC categories); :func:`write_sii` checks
  an image (checksum; identity against the slave's, unless forced), writes the words that
  differ and reads the image back; :func:`set_alias` writes word 4 with the checksum
  (word 7) and reloads the ESC's configuration area, so register 0x0012 shows it at once;
* states: :func:`request_states` walks each slave to the requested state (INIT, PREOP,
  BOOT, SAFEOP, OP) from where it is, setting up what the slave checks on the way from
  its SII: the mailbox SMs for PREOP (the bootstrap mailbox for BOOT), the process-data
  SMs with the sizes of the PDOs the SII assigns for SAFEOP, zero outputs and the
  process-data watchdog off (0x0420 = 0: nobody sends process data after the command) for
  OP. Refusals come back with the AL status code (ETG.1000.6 Table 11) and its text.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from lolacli.eni.model import Eni
from lolacli.eni.model import Master as EniMaster
from lolacli.eni.model import ProcessImage as EniProcessImage
from lolacli.errors import InputError, TransportError, UsageError
from lolacli.master import eeprom
from lolacli.master.core import Master, MasterOptions
from lolacli.master.scan import decode_ports
from lolacli.master.transport import Transport
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import (
    AL_ERROR_INDICATOR,
    AL_STATE_MASK,
    FMMU_BYTES,
    REGISTER_BYTES,
    SM_ACTIVATE_ENABLE,
    SM_CONTROL_MAILBOX_IN,
    SM_CONTROL_MAILBOX_OUT,
    SYNC_MANAGER_BYTES,
    AlState,
    Fmmu,
    FmmuType,
    Register,
    RegisterSpan,
    SyncManager,
    al_state_name,
    al_status_text,
    configuration_block,
    decode_fmmu,
    decode_sync_manager,
    decode_system_time_difference,
    encode_fmmu,
    encode_sync_manager,
    fmmu_address,
    register_name,
    sync_manager_address,
)
from lolacli.wire.sii import (
    HEADER_BYTES,
    PDO_NOT_ASSIGNED,
    CoeDetails,
    FmmuUsage,
    SiiCategory,
    SiiPdo,
    SiiWord,
    SmType,
    crc8_sii,
    decode_sii,
    decode_sii_dc_assign_activate,
    decode_sii_header,
    decode_sii_pdos,
    decode_sii_sync_managers,
    protocol_names,
    sii_categories,
    sii_string,
)

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")

#: what `bus state` takes: the AL states by name (ETG.1000.6 Table 9)
STATE_NAMES: dict[str, AlState] = {s.name: s for s in AlState}


def parse_state_name(text: str) -> AlState:
    """``INIT``, ``PREOP``, ``BOOT``, ``SAFEOP``, ``OP`` (any case, ``SAFE-OP`` too)."""
    key = text.strip().upper().replace("-", "").replace("_", "")
    if key == "BOOTSTRAP":
        key = "BOOT"
    if key not in STATE_NAMES:
        raise UsageError(f"state {text!r} does not exist: expected INIT, PREOP, BOOT, SAFEOP or OP")
    return STATE_NAMES[key]


# ----------------------------------------------------------------------------- the bus
@dataclass(slots=True)
class BenchSlave:
    """A slave as the bench sees it: line position, the addresses it has, its AL status."""

    position: int
    station_address: int = 0
    station_alias: int = 0
    al_status: int = 0
    name: str = ""

    @property
    def adp(self) -> int:
        """Its auto-increment address (position 1 is 0, position 2 is 0xFFFF, …)."""
        return (-(self.position - 1)) & 0xFFFF

    @property
    def al_state(self) -> int:
        return self.al_status & AL_STATE_MASK

    def to_dict(self) -> dict[str, Any]:
        return {
            "position": self.position,
            "station_address": self.station_address,
            "station_alias": self.station_alias,
            "name": self.name or None,
        }


class BenchBus:
    """Our master on a transport, for the bench verbs (see the module docstring)."""

    def __init__(self, transport: Transport, *, where: str = "", timeout_ns: int = 20_000_000):
        eni = Eni(EniMaster(), (), (), EniProcessImage(0, 0), source=where)
        self.master = Master(
            eni, transport, options=MasterOptions(frame_timeout_ns=timeout_ns, frame_retries=3)
        )
        self.where = where
        self.slaves = self._find()

    def _find(self) -> list[BenchSlave]:
        at = f" on {self.where}" if self.where else ""
        try:
            got = self.master.exchange_one(Datagram.physical(Command.BRD, 0, Register.TYPE, 1))
        except TransportError:
            raise TransportError(f"no slave answers{at} (no frame came back)") from None
        if got.wkc == 0:
            raise TransportError(f"no slave answers{at} (frames come back unprocessed)")
        slaves = [BenchSlave(k) for k in range(1, got.wkc + 1)]
        self.refresh(slaves)
        return slaves

    def refresh(self, slaves: Sequence[BenchSlave]) -> None:
        """Station address, alias and AL status of ``slaves`` again."""
        reads = []
        for s in slaves:
            reads.append(self.aprd(s, Register.STATION_ADDRESS, 4))
            reads.append(self.aprd(s, Register.AL_STATUS, 2))
        got = self.master.exchange_many(reads)
        for s, addr, al in zip(slaves, got[::2], got[1::2], strict=True):
            if addr.wkc != 1 or al.wkc != 1:
                raise TransportError(f"slave {s.position} does not answer{self._at()}")
            s.station_address, s.station_alias = struct.unpack_from("<HH", addr.data)
            s.al_status = _U16.unpack_from(al.data)[0]

    def read_names(self) -> None:
        """Each slave's name from its SII (STRINGS and GENERAL)."""
        found = eeprom.read_sii(self.master, [s.adp for s in self.slaves], auto_increment=True)
        for s, got in zip(self.slaves, found, strict=True):
            s.name = (got.info.name or "") if got.info is not None else ""

    def _at(self) -> str:
        return f" on {self.where}" if self.where else ""

    @staticmethod
    def aprd(s: BenchSlave, ado: int, length: int) -> Datagram:
        return Datagram.physical(Command.APRD, s.adp, ado, length)

    @staticmethod
    def apwr(s: BenchSlave, ado: int, data: bytes) -> Datagram:
        return Datagram.physical(Command.APWR, s.adp, ado, data)

    def one(self, d: Datagram, s: BenchSlave, what: str) -> Datagram:
        """``d`` exchanged; TransportError when the slave did not take it."""
        got = self.master.exchange_one(d)
        if got.wkc != 1:
            raise TransportError(f"slave {s.position}: {what} not taken (working counter "
                                 f"{got.wkc})")  # fmt: skip
        return got

    def close(self) -> None:
        self.master.transport.close()


# ---------------------------------------------------------------------------- registers
def read_register(bus: BenchBus, s: BenchSlave, span: RegisterSpan) -> bytes:
    got = bus.one(bus.aprd(s, span.address, span.length), s, f"read of 0x{span.address:04X}")
    return bytes(got.data)


def _port_descriptor(bus: BenchBus, s: BenchSlave) -> int:
    return read_register(bus, s, RegisterSpan(Register.PORT_DESCRIPTOR, 1))[0]


def write_register(
    bus: BenchBus, s: BenchSlave, span: RegisterSpan, data: bytes, *, force: bool = False
) -> bytes:
    """Write ``data`` at the span and read it back (what the ESC holds now). A write into a
    configuration block of a slave in SAFEOP or OP is a UsageError unless ``force``."""
    block = configuration_block(span.address, span.length)
    if block is not None and s.al_state in (AlState.SAFEOP, AlState.OP) and not force:
        raise UsageError(
            f"slave {s.position} is in {al_state_name(s.al_status)}: a write to its "
            f"{block} (0x{span.address:04X}) disturbs the running process data; "
            "--force to write anyway"
        )
    bus.one(bus.apwr(s, span.address, data), s, f"write of 0x{span.address:04X}")
    return read_register(bus, s, span)


@dataclass(frozen=True, slots=True)
class Field:
    """A named register in a read span: its value and what it means."""

    name: str
    address: int
    length: int
    value: int
    text: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "address": f"0x{self.address:04X}",
            "length": self.length,
            "value": self.value,
            "text": self.text,
        }


def _int(raw: bytes) -> int:
    return int.from_bytes(raw, "little")


def _text(reg: int, raw: bytes, port_descriptor: int | None) -> str:
    v = _int(raw)
    if reg in (Register.AL_STATUS, Register.AL_CONTROL):
        return al_state_name(v) + (" (error acknowledged)" if reg == Register.AL_CONTROL
                                   and v & AL_ERROR_INDICATOR else "")  # fmt: skip
    if reg == Register.AL_STATUS_CODE:
        return f"0x{v:04X} {al_status_text(v)}"
    if reg == Register.DL_STATUS:
        ports = decode_ports(v, port_descriptor if port_descriptor is not None else 0xFF)
        return "; ".join(
            f"port {p.port}: {'link' if p.link else 'no link'}, "
            f"{'closed' if p.loop_closed else 'open'}"
            f"{', communication' if p.communication else ''}"
            for p in ports
        )
    if reg == Register.RX_ERROR_COUNTER:
        return ", ".join(f"port {p}: invalid frame {raw[2 * p]}, RX error {raw[2 * p + 1]}"
                         for p in range(4))  # fmt: skip
    if reg in (Register.FORWARDED_RX_ERROR_COUNTER, Register.LOST_LINK_COUNTER):
        return ", ".join(f"port {p}: {raw[p]}" for p in range(4))
    if reg == Register.DC_SYSTEM_TIME_DIFFERENCE:
        return f"{decode_system_time_difference(raw)} ns"
    if Register.DC_RECEIVE_TIME_PORT0 <= reg <= Register.DC_SYSTEM_TIME_DELAY or reg in (
        Register.DC_START_TIME_CYCLIC, Register.DC_NEXT_SYNC1_PULSE, Register.DC_SYNC0_CYCLE,
        Register.DC_SYNC1_CYCLE,
    ):  # fmt: skip
        return f"{v} ns"
    if reg in (Register.STATION_ADDRESS, Register.STATION_ALIAS):
        return f"0x{v:04X} ({v})"
    if reg == Register.SII_CONTROL_STATUS:
        busy = " busy" if v & 0x8000 else ""
        return f"command {(v >> 8) & 0x7}{busy}, error bits 0x{v & 0x7800:04X}"
    if reg in (Register.WD_TIME_PD, Register.WD_TIME_PDI):
        return f"{v} × watchdog divider ticks"
    return f"0x{v:0{2 * len(raw)}X}"


def decode_registers(
    address: int, data: bytes, port_descriptor: int | None = None
) -> list[Field]:
    """Every named register wholly inside ``data`` read at ``address``, decoded."""
    out: list[Field] = []
    end = address + len(data)
    for at in range(address, end):
        name = register_name(at)
        if name is None:
            continue
        if name.startswith("fmmu"):
            if at + FMMU_BYTES <= end:
                f = decode_fmmu(data, at - address)
                raw = data[at - address : at - address + FMMU_BYTES]
                out.append(Field(name, at, FMMU_BYTES, _int(raw),
                                 f"logical 0x{f.logical_start:08X} {f.length_bytes} B → "
                                 f"physical 0x{f.physical_start:04X}, type {f.type}, "
                                 f"{'on' if f.enabled else 'off'}"))  # fmt: skip
            continue
        if name.startswith("sm"):
            if at + SYNC_MANAGER_BYTES <= end:
                sm = decode_sync_manager(data, at - address)
                out.append(Field(name, at, SYNC_MANAGER_BYTES,
                                 _int(data[at - address : at - address + SYNC_MANAGER_BYTES]),
                                 f"0x{sm.physical_start:04X} {sm.length_bytes} B, control "
                                 f"0x{sm.control:02X}, status 0x{sm.status:02X}, "
                                 f"{'on' if sm.enabled else 'off'}"))  # fmt: skip
            continue
        reg = Register(at)
        size = REGISTER_BYTES.get(reg, 1)
        if at + size > end:
            continue
        raw = data[at - address : at - address + size]
        out.append(Field(name, at, size, _int(raw), _text(reg, raw, port_descriptor)))
    return out


def register_fields(bus: BenchBus, s: BenchSlave, address: int, data: bytes) -> list[Field]:
    """:func:`decode_registers`, with the port descriptor read when DL status is in it."""
    pd = None
    if address <= Register.DL_STATUS < address + len(data):
        pd = _port_descriptor(bus, s)
    return decode_registers(address, data, pd)


# ------------------------------------------------------------------------------- EEPROM
def describe_sii(image: bytes) -> dict[str, Any]:
    """A whole SII image decoded (lolacli.sii/1's ``sii``): header and checksum, and
    every category a master uses. InputError when not even the header is there."""
    if len(image) < HEADER_BYTES:
        raise InputError(f"an SII image has a 128-byte header; this one has {len(image)} bytes")
    h = decode_sii_header(image)
    info = decode_sii(image)
    cats = sii_categories(image)
    strings = info.strings
    g = info.general
    out: dict[str, Any] = {
        "bytes": len(image),
        "checksum": f"0x{h.checksum:02X}",
        "checksum_expected": f"0x{crc8_sii(image[:14]):02X}",
        "checksum_ok": h.checksum_ok,
        "identity": {
            "vendor_id": h.vendor_id,
            "product_code": h.product_code,
            "revision": h.revision,
            "serial": h.serial,
        },
        "station_alias": h.station_alias,
        "mailbox": {
            "out": {"offset": h.rx_mailbox_offset, "bytes": h.rx_mailbox_bytes},
            "in": {"offset": h.tx_mailbox_offset, "bytes": h.tx_mailbox_bytes},
            "bootstrap_out": {"offset": h.bootstrap_rx_mailbox_offset,
                              "bytes": h.bootstrap_rx_mailbox_bytes},
            "bootstrap_in": {"offset": h.bootstrap_tx_mailbox_offset,
                             "bytes": h.bootstrap_tx_mailbox_bytes},
            "protocols": list(protocol_names(h.mailbox_protocols)),
        },
        "eeprom_bytes": h.size_bytes,
        "version": h.version,
        "strings": list(strings),
        "general": None,
        "fmmus": [],
        "sync_managers": [],
        "tx_pdos": [],
        "rx_pdos": [],
        "dc_assign_activate": [],
        "categories": [
            {"type": kind, "word": word, "words": words} for kind, word, words in info.categories
        ],
    }
    if g is not None:
        out["general"] = {
            "name": sii_string(strings, g.name_index),
            "order": sii_string(strings, g.order_index),
            "group": sii_string(strings, g.group_index),
            "coe_details": [str(f.name).lower() for f in CoeDetails if g.coe_details & f],
            "foe_details": g.foe_details,
            "eoe_details": g.eoe_details,
            "ds402_channels": g.ds402_channels,
        }
    fmmus = cats.get(SiiCategory.FMMU, b"")
    out["fmmus"] = [_enum_name(FmmuUsage, b) for b in fmmus if b != 0xFF]
    out["sync_managers"] = [
        {
            "index": i,
            "type": _enum_name(SmType, e.type),
            "start": e.sync_manager.physical_start,
            "bytes": e.sync_manager.length_bytes,
            "control": f"0x{e.sync_manager.control:02X}",
            "enable": e.sync_manager.activate,
        }
        for i, e in enumerate(decode_sii_sync_managers(cats.get(SiiCategory.SYNCM, b"")))
    ]
    for key, kind in (("tx_pdos", SiiCategory.TXPDO), ("rx_pdos", SiiCategory.RXPDO)):
        out[key] = [_pdo(p, strings) for p in decode_sii_pdos(cats.get(kind, b""))]
    dc = cats.get(SiiCategory.DC)
    if dc:
        out["dc_assign_activate"] = [f"0x{a:04X}" for a in decode_sii_dc_assign_activate(dc)]
    return out


def _enum_name(kind: Any, value: int) -> str:
    try:
        return str(kind(value).name).lower()
    except ValueError:
        return f"0x{value:02X}"


def _pdo(p: SiiPdo, strings: tuple[str, ...]) -> dict[str, Any]:
    return {
        "index": f"0x{p.index:04X}",
        "name": sii_string(strings, p.name_index),
        "sync_manager": None if p.sync_manager == PDO_NOT_ASSIGNED else p.sync_manager,
        "bits": p.bit_length,
        "entries": [
            {
                "index": f"0x{e.index:04X}",
                "subindex": e.subindex,
                "name": sii_string(strings, e.name_index),
                "bits": e.bit_length,
                "data_type": e.data_type,
            }
            for e in p.entries
        ],
    }


def read_image(bus: BenchBus, s: BenchSlave) -> bytes:
    return eeprom.read_image(bus.master, s.adp, auto_increment=True)


def check_image(image: bytes, current: bytes, *, force: bool = False, path: str = "") -> None:
    """An image fit to write over ``current``: whole words, a header, a right checksum,
    the slave's identity (vendor, product); InputError naming what is wrong unless
    ``force`` (then only the whole words and the header count)."""
    where = path or "the image"
    if len(image) < HEADER_BYTES or len(image) % 2:
        raise InputError(f"{where}: {len(image)} bytes is not an SII image "
                         "(whole 16-bit words, a 128-byte header at least)")  # fmt: skip
    if force:
        return
    h = decode_sii_header(image)
    if not h.checksum_ok:
        raise InputError(
            f"{where}: SII checksum 0x{h.checksum:02X} is wrong (CRC-8 of words 0-6 is "
            f"0x{crc8_sii(image[:14]):02X}); nothing written (--force to write it anyway)"
        )
    c = decode_sii_header(current)
    if (h.vendor_id, h.product_code) != (c.vendor_id, c.product_code):
        raise InputError(
            f"{where}: identity vendor 0x{h.vendor_id:08X} product 0x{h.product_code:08X} "
            f"is not the slave's (vendor 0x{c.vendor_id:08X} product 0x{c.product_code:08X});"
            " nothing written (--force to write it anyway)"
        )


@dataclass(frozen=True, slots=True)
class SiiWrite:
    words_written: int
    verified: bool
    image: bytes  # as read back


def write_sii(bus: BenchBus, s: BenchSlave, image: bytes, current: bytes) -> SiiWrite:
    """Write the words of ``image`` that differ from ``current``, then read the image
    back; ``verified`` when its first ``len(image)`` bytes are ``image``."""
    written = 0
    for i in range(0, len(image), 2):
        if image[i : i + 2] != current[i : i + 2]:
            eeprom.write_words(bus.master, s.adp, i // 2, image[i : i + 2], auto_increment=True)
            written += 1
    back = eeprom.read_image(bus.master, s.adp, auto_increment=True)
    if len(back) < len(image):  # the walk ends at the end marker: the words behind it too
        rest = eeprom.read_words(bus.master, s.adp, len(back) // 2,
                                 (len(image) - len(back)) // 2, auto_increment=True)  # fmt: skip
        back += rest
    return SiiWrite(written, back[: len(image)] == image, back)


def with_alias(image: bytes, alias: int) -> bytes:
    """``image`` with the configured station alias (word 4) and its checksum (word 7)."""
    head = bytearray(image[:HEADER_BYTES])
    _U16.pack_into(head, 2 * SiiWord.STATION_ALIAS, alias)
    _U16.pack_into(head, 2 * SiiWord.CHECKSUM, (_U16.unpack_from(head, 14)[0] & 0xFF00)
                   | crc8_sii(bytes(head[:14])))  # fmt: skip
    return bytes(head) + image[HEADER_BYTES:]


@dataclass(frozen=True, slots=True)
class AliasChange:
    previous: int
    alias: int
    register: int  # 0x0012 after the reload (or as it was, without one)
    words_written: int


def set_alias(bus: BenchBus, s: BenchSlave, alias: int, *, reload: bool = True) -> AliasChange:
    """Write the alias into the EEPROM (word 4 and the checksum), verify it, and reload
    the ESC's configuration area so that 0x0012 has it (as at the next power-up)."""
    if not 0 <= alias <= 0xFFFF:
        raise UsageError(f"alias {alias} is outside 0..65535")
    head = eeprom.read_words(bus.master, s.adp, 0, 8, auto_increment=True)
    previous = _U16.unpack_from(head, 8)[0]
    new = with_alias(head, alias)[:16]
    written = 0
    for i in range(0, 16, 2):
        if new[i : i + 2] != head[i : i + 2]:
            eeprom.write_words(bus.master, s.adp, i // 2, new[i : i + 2], auto_increment=True)
            written += 1
    back = eeprom.read_words(bus.master, s.adp, 0, 8, auto_increment=True)
    if back != new:
        raise TransportError(
            f"slave {s.position}: the EEPROM reads back words 0-7 as {back.hex()}, "
            f"not {new.hex()}"
        )
    if reload:
        eeprom.reload(bus.master, s.adp, auto_increment=True)
    register = _U16.unpack(read_register(bus, s, RegisterSpan(Register.STATION_ALIAS, 2)))[0]
    return AliasChange(previous, alias, register, written)


# -------------------------------------------------------------------------------- states
@dataclass(slots=True)
class StateResult:
    """What one slave reached, and why not when it did not."""

    slave: BenchSlave
    requested: AlState
    before: int  # AL status before
    after: int = 0  # AL status after
    al_status_code: int = 0
    refused: str | None = None  # the step ("SAFEOP -> OP") that was refused or timed out
    timed_out: bool = False
    steps: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.refused is None

    def to_dict(self) -> dict[str, Any]:
        return {
            **self.slave.to_dict(),
            "requested": self.requested.name,
            "before": al_state_name(self.before),
            "reached": al_state_name(self.after),
            "ok": self.ok,
            "steps": self.steps,
            "refused": self.refused,
            "timed_out": self.timed_out,
            "al_status_code": f"0x{self.al_status_code:04X}" if self.refused else None,
            "al_status_text": al_status_text(self.al_status_code) if self.refused else None,
        }


def path(current: int, target: AlState) -> list[AlState]:
    """The states a slave passes from ``current`` to ``target`` (ETG.1000.6 Figure 10:
    BOOT only from and to INIT; up one state at a time; down in one step)."""
    if current == target:
        return []
    if target in (AlState.INIT, AlState.BOOT):
        return ([AlState.INIT] if current not in (AlState.INIT,) and target == AlState.BOOT
                else []) + [target]  # fmt: skip
    up = [AlState.PREOP, AlState.SAFEOP, AlState.OP]
    if current not in (AlState.PREOP, AlState.SAFEOP, AlState.OP):  # INIT, BOOT, unknown
        head = [] if current == AlState.INIT else [AlState.INIT]
        return head + up[: up.index(target) + 1]
    if up.index(AlState(current)) > up.index(target):
        return [target]
    return up[up.index(AlState(current)) + 1 : up.index(target) + 1]


@dataclass(frozen=True, slots=True)
class _Config:
    """What a slave's SII says it checks on the way up."""

    mailbox: tuple[SyncManager, SyncManager] | None
    bootstrap: tuple[SyncManager, SyncManager] | None
    process: tuple[tuple[int, SyncManager], ...]  # (SM index, content) of outputs, inputs
    outputs: tuple[int, int] | None  # (start, bytes) of the output SM buffer
    output_fmmu: int  # the FMMU the SII names for outputs (else 0)


def _mailbox_sms(out_start: int, out_len: int, in_start: int, in_len: int) -> tuple[
    SyncManager, SyncManager] | None:  # fmt: skip
    if not (out_len and in_len):
        return None
    on = SM_ACTIVATE_ENABLE
    return (SyncManager(out_start, out_len, SM_CONTROL_MAILBOX_OUT, activate=on),
            SyncManager(in_start, in_len, SM_CONTROL_MAILBOX_IN, activate=on))  # fmt: skip


def _config(image: bytes) -> _Config:
    h = decode_sii_header(image)
    cats = sii_categories(image)
    sms = decode_sii_sync_managers(cats.get(SiiCategory.SYNCM, b""))
    bits: dict[int, int] = {}
    for kind in (SiiCategory.RXPDO, SiiCategory.TXPDO):
        for p in decode_sii_pdos(cats.get(kind, b"")):
            if p.sync_manager != PDO_NOT_ASSIGNED:
                bits[p.sync_manager] = bits.get(p.sync_manager, 0) + p.bit_length
    process: list[tuple[int, SyncManager]] = []
    outputs = None
    for i, e in enumerate(sms):
        if e.type not in (SmType.OUTPUTS, SmType.INPUTS):
            continue
        length = (bits[i] + 7) // 8 if i in bits else e.sync_manager.length_bytes
        sm = e.sync_manager
        content = SyncManager(sm.physical_start, length, sm.control,
                              activate=SM_ACTIVATE_ENABLE if length else 0)  # fmt: skip
        process.append((i, content))
        if e.type == SmType.OUTPUTS and length and outputs is None:
            outputs = (sm.physical_start, length)
    return _Config(
        _mailbox_sms(h.rx_mailbox_offset, h.rx_mailbox_bytes, h.tx_mailbox_offset,
                     h.tx_mailbox_bytes),
        _mailbox_sms(h.bootstrap_rx_mailbox_offset, h.bootstrap_rx_mailbox_bytes,
                     h.bootstrap_tx_mailbox_offset, h.bootstrap_tx_mailbox_bytes),
        tuple(process),
        outputs,
        next((i for i, u in enumerate(cats.get(SiiCategory.FMMU, b"")) if u == FmmuUsage.OUTPUTS),
             0),
    )  # fmt: skip


def _step_writes(bus: BenchBus, s: BenchSlave, frm: int, to: AlState, c: _Config | None) -> list[
    Datagram]:  # fmt: skip
    """What the master sets up before requesting ``to`` from ``frm``."""
    out: list[Datagram] = []
    if c is None:
        return out
    if to == AlState.PREOP and frm in (AlState.INIT,) and c.mailbox is not None:
        out += [bus.apwr(s, sync_manager_address(i), encode_sync_manager(sm))
                for i, sm in enumerate(c.mailbox)]  # fmt: skip
    if to == AlState.BOOT and c.bootstrap is not None:
        out += [bus.apwr(s, sync_manager_address(i), encode_sync_manager(sm))
                for i, sm in enumerate(c.bootstrap)]  # fmt: skip
    if to == AlState.SAFEOP and frm == AlState.PREOP:
        out += [bus.apwr(s, sync_manager_address(i), encode_sync_manager(sm))
                for i, sm in c.process]  # fmt: skip
        if c.outputs is not None:
            start, length = c.outputs
            fmmu = Fmmu(_logical(s), length, 0, 7, start, 0, FmmuType.WRITE, 1)
            out.append(bus.apwr(s, fmmu_address(c.output_fmmu), encode_fmmu(fmmu)))
    if to == AlState.OP:
        out.append(bus.apwr(s, Register.WD_TIME_PD, _U16.pack(0)))
        if c.outputs is not None:
            out.append(_zero_outputs(s, c))
    return out


#: where `bus state` maps each slave's outputs: its own 4 KiB of the logical space
LOGICAL_BASE = 0x4000_0000


def _logical(s: BenchSlave) -> int:
    return LOGICAL_BASE + 0x1000 * s.position


def _zero_outputs(s: BenchSlave, c: _Config) -> Datagram:
    """Outputs as zeros through the slave's output FMMU (LWR): valid outputs for OP."""
    assert c.outputs is not None
    return Datagram.logical(Command.LWR, _logical(s), bytes(c.outputs[1]))


def request_states(
    bus: BenchBus,
    slaves: Sequence[BenchSlave],
    target: AlState,
    *,
    timeout_ns: int = 10_000_000_000,
) -> list[StateResult]:
    """Bring ``slaves`` to ``target``, all together step by step (see the module
    docstring); every slave's result, refused or not."""
    bus.refresh(slaves)
    results = [StateResult(s, target, s.al_status) for s in slaves]
    paths = {s.position: path(s.al_state, target) for s in slaves}
    needs_sii = any(step != AlState.INIT for p in paths.values() for step in p)
    configs: dict[int, _Config | None] = {s.position: None for s in slaves}
    if needs_sii:
        images = eeprom.read_images(bus.master, [s.adp for s in slaves], auto_increment=True)
        for s, image in zip(slaves, images, strict=True):
            if isinstance(image, str):
                raise TransportError(f"slave {s.position}: {image}")
            configs[s.position] = _config(image)
    # an error to acknowledge, or nothing to do but a state that stays: request it again
    for r in results:
        if not paths[r.slave.position] and r.slave.al_status & AL_ERROR_INDICATOR:
            paths[r.slave.position] = [target]
    step = 0
    while True:
        doing = [r for r in results if r.ok and step < len(paths[r.slave.position])]
        if not doing:
            break
        writes: list[Datagram] = []
        acked: dict[int, int] = {}  # position: the AL status whose error is acknowledged
        for r in doing:
            s, to = r.slave, paths[r.slave.position][step]
            writes += _step_writes(bus, s, s.al_state, to, configs[s.position])
            ack = AL_ERROR_INDICATOR if s.al_status & AL_ERROR_INDICATOR else 0
            if ack:
                acked[s.position] = s.al_status
            writes.append(bus.apwr(s, Register.AL_CONTROL, _U16.pack(to | ack)))
            r.steps.append(f"{al_state_name(s.al_state)} -> {to.name}")
        for d in bus.master.exchange_many(writes):
            if d.wkc != 1 and d.cmd != Command.LWR:  # LWR: the FMMU is not active yet
                raise TransportError(
                    f"a write to 0x{d.ado:04X} of the slave at auto-increment address "
                    f"0x{d.adp:04X} was not taken"
                )
        _wait(bus, doing, [paths[r.slave.position][step] for r in doing], timeout_ns,
              acked)
        for r in doing:  # OP: outputs again, for a slave that takes OP with the next ones
            c = configs[r.slave.position]
            if r.ok and paths[r.slave.position][step] == AlState.OP and c and c.outputs:
                bus.master.exchange_many([_zero_outputs(r.slave, c)])
        step += 1
    bus.refresh(slaves)
    for r in results:
        r.after = r.slave.al_status
        if r.ok and (r.slave.al_state != target or r.after & AL_ERROR_INDICATOR):
            r.refused = r.steps[-1] if r.steps else f"-> {target.name}"
            r.al_status_code = _code(bus, r.slave)
    return results


def _code(bus: BenchBus, s: BenchSlave) -> int:
    raw = read_register(bus, s, RegisterSpan(Register.AL_STATUS_CODE, 2))
    return int(_U16.unpack(raw)[0])


#: how long an acknowledged error may still show unchanged before it counts as a new
#: refusal: the slave's firmware, not its ESC, takes the request in (as IgH's master, the
#: status must change; a slave that refuses the same way again shows no change at all)
ACK_SETTLE_NS = 1_000_000_000


def _wait(bus: BenchBus, doing: list[StateResult], to: list[AlState], timeout_ns: int,
          acked: dict[int, int]) -> None:  # fmt: skip
    """Poll AL status until each slave is in its state, has refused, or time runs out.
    A slave in ``acked`` whose status still reads as it did when its error was
    acknowledged has not taken the request in yet (for up to :data:`ACK_SETTLE_NS`)."""
    start = time.monotonic_ns()
    end, settled = start + timeout_ns, start + min(ACK_SETTLE_NS, timeout_ns)
    waiting = list(zip(doing, to, strict=True))
    while waiting:
        got = bus.master.exchange_many(
            [bus.aprd(r.slave, Register.AL_STATUS, 6) for r, _ in waiting]
        )
        still = []
        for (r, state), d in zip(waiting, got, strict=True):
            if d.wkc != 1:
                still.append((r, state))
                continue
            status = _U16.unpack_from(d.data)[0]
            r.slave.al_status = status
            if acked.get(r.slave.position) == status and time.monotonic_ns() < settled:
                still.append((r, state))  # the error acknowledged, not yet taken in
            elif status & AL_ERROR_INDICATOR:
                r.refused = r.steps[-1]
                r.al_status_code = _U16.unpack_from(d.data, 4)[0]
            elif status & AL_STATE_MASK != state:
                still.append((r, state))
        waiting = still
        if waiting and time.monotonic_ns() > end:
            for r, _state in waiting:
                r.refused, r.timed_out = r.steps[-1], True
                r.al_status_code = _code(bus, r.slave)
            return
        if waiting:
            bus.master.idle(1_000_000)


__all__ = [
    "STATE_NAMES",
    "AliasChange",
    "BenchBus",
    "BenchSlave",
    "Field",
    "SiiWrite",
    "StateResult",
    "check_image",
    "decode_registers",
    "describe_sii",
    "parse_state_name",
    "path",
    "read_image",
    "read_register",
    "register_fields",
    "request_states",
    "set_alias",
    "with_alias",
    "write_register",
    "write_sii",
]
