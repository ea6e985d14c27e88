"""SII EEPROM images (ETG.1000.6 §5.4, ETG.2010): build one from an ENI slave, read it back.

Layout (word addresses)::

    0x00 PDI control   0x01 PDI configuration   0x02 SYNC impulse length  0x03 PDI config 2
    0x04 configured station alias                0x07 checksum (CRC-8 of words 0..6, low byte)
    0x08 vendor id (2 words)  0x0A product code  0x0C revision  0x0E serial number
    0x14/0x15 bootstrap receive mailbox offset/size   0x16/0x17 bootstrap send mailbox
    0x18/0x19 standard receive mailbox (master -> slave)  0x1A/0x1B standard send mailbox
    0x1C mailbox protocols   0x3E EEPROM size (KiBit - 1)   0x3F version
    0x40… categories: type (word), length in words (word), data; 0xFFFF ends the list.

Categories written: STRINGS (10), GENERAL (30), FMMU (40), SYNCM (41), TXPDO (50),
RXPDO (51), DC (60). Pure: values in, bytes out.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace
from enum import IntEnum, IntFlag

from lolacli.devices.base import assigned_pdos
from lolacli.eni.esi import EsiDevice
from lolacli.eni.model import ConfiguredSyncManager, Direction, Pdo, Slave
from lolacli.wire.registers import (
    SM_CONTROL_INPUTS,
    SM_CONTROL_MAILBOX_IN,
    SM_CONTROL_MAILBOX_OUT,
    SM_CONTROL_OUTPUTS,
)
from lolacli.wire.sii import (  # the one definition
    CATEGORY_END,
    HEADER_WORDS,
    PROTOCOL_NAMES,
    MailboxProtocol,
    SiiCategory,
)

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_SM_ENTRY = struct.Struct("<HHBBBB")
_PDO_HEAD = struct.Struct("<HBBBBH")
_PDO_ENTRY = struct.Struct("<HBBBBH")



class SmType(IntEnum):
    """SYNCM category "type" byte (ETG.2010 Table 12)."""

    UNUSED = 0
    MAILBOX_OUT = 1
    MAILBOX_IN = 2
    OUTPUTS = 3
    INPUTS = 4


class CoeDetails(IntFlag):
    """GENERAL category CoE details (ETG.2010 Table 8)."""

    SDO = 0x01
    SDO_INFO = 0x02
    PDO_ASSIGN = 0x04
    PDO_CONFIG = 0x08
    UPLOAD_AT_STARTUP = 0x10
    SDO_COMPLETE_ACCESS = 0x20


#: CoE data type codes of ENI/ESI type names (ETG.1000.6 Table 64).
DATA_TYPE_CODES = {
    "BOOL": 0x01,
    "BIT": 0x01,
    "SINT": 0x02,
    "INT": 0x03,
    "DINT": 0x04,
    "USINT": 0x05,
    "UINT": 0x06,
    "UDINT": 0x07,
    "REAL": 0x08,
    "STRING": 0x09,
    "LREAL": 0x11,
    "LINT": 0x15,
    "ULINT": 0x1B,
    "BYTE": 0x05,
    "WORD": 0x06,
    "DWORD": 0x07,
    "BIT2": 0x31,
    "BIT3": 0x32,
    "BIT4": 0x33,
    "BIT5": 0x34,
    "BIT6": 0x35,
    "BIT7": 0x36,
    "BIT8": 0x37,
}

_PROTOCOL_NAMES = {name: int(bit) for bit, name in PROTOCOL_NAMES}  # "CoE" -> 0x04

SM_CONTROL = {
    SmType.MAILBOX_OUT: SM_CONTROL_MAILBOX_OUT,
    SmType.MAILBOX_IN: SM_CONTROL_MAILBOX_IN,
    SmType.OUTPUTS: SM_CONTROL_OUTPUTS,
    SmType.INPUTS: SM_CONTROL_INPUTS,
}


@dataclass(frozen=True, slots=True)
class SiiSyncManager:
    start: int
    length_bytes: int
    control: int
    enable: int
    type: int


@dataclass(frozen=True, slots=True)
class SiiLayout:
    """What the ESC and a master learn from an SII image."""

    vendor_id: int = 0
    product_code: int = 0
    revision: int = 0
    serial: int = 0
    station_alias: int = 0
    mailbox_out_start: int = 0
    mailbox_out_bytes: int = 0
    mailbox_in_start: int = 0
    mailbox_in_bytes: int = 0
    protocols: int = 0
    name: str = ""
    sync_managers: tuple[SiiSyncManager, ...] = ()
    outputs_bytes: int = 0
    inputs_bytes: int = 0

    mailbox_out_sm: int = 0
    mailbox_in_sm: int = 1
    outputs_sm: int = 2
    inputs_sm: int = 3


def _sm_of(sms: tuple[SiiSyncManager, ...], kind: SmType, default: int) -> int:
    """The index of the first SM of ``kind`` in the SYNCM category, else ``default``."""
    return next((i for i, sm in enumerate(sms) if sm.type == kind), default)


def crc8_sii(data: bytes) -> int:
    """CRC-8 of the first 14 header bytes: polynomial x^8+x^2+x+1, initial 0xFF."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


# ------------------------------------------------------------------ building
@dataclass(frozen=True, slots=True)
class SiiSpec:
    """Everything an SII image states; :func:`sii_spec_from_slave` fills it from an ENI."""

    name: str
    vendor_id: int
    product_code: int
    revision: int
    serial: int = 0
    station_alias: int = 0
    mailbox: tuple[int, int, int, int] | None = None  # out start, out len, in start, in len
    protocols: int = 0
    coe_details: int = 0
    ds402_channels: int = 0
    sync_managers: tuple[SiiSyncManager, ...] = ()
    fmmus: tuple[int, ...] = (1, 2)
    pdos: tuple[Pdo, ...] = ()
    pdo_sync_manager: dict[int, int] | None = None  # PDO index -> SM, where the ENI omits it
    dc: bool = True
    group: str = "lolacli emulated"
    eeprom_kibit: int = 32
    dc_assign_activate: int = 0x0300
    config_data: bytes = b""  # ESI <ConfigData>: header words 0..6 (PDI control, ...)


def _category(kind: int, data: bytes) -> bytes:
    if len(data) % 2:
        data += b"\x00"
    return _U16.pack(kind) + _U16.pack(len(data) // 2) + data


def _strings(strings: list[str]) -> bytes:
    out = bytearray([len(strings)])
    for s in strings:
        raw = s.encode("latin-1", "replace")[:255]
        out += bytes([len(raw)]) + raw
    return bytes(out)


def _general(spec: SiiSpec) -> bytes:
    out = bytearray(32)
    out[0], out[2], out[3] = 2, 3, 1  # group, order, name string indices
    out[5] = spec.coe_details
    out[9] = spec.ds402_channels
    _U16.pack_into(out, 16, 0x0011)  # physical ports 0 and 1: MII
    return bytes(out)


def _pdo_category(pdos: list[Pdo], sm_of: dict[int, int]) -> bytes:
    """PDO entries (ETG.2010 Table 14): a PDO that no sync manager takes by default has
    SM 0xFF, so a master that maps from the SII leaves it out."""
    out = bytearray()
    for pdo in pdos:
        sm = pdo.sync_manager if pdo.sync_manager is not None else sm_of.get(pdo.index, 0xFF)
        flags = (0x0001 if pdo.mandatory else 0) | (0x0010 if pdo.fixed else 0)
        out += _PDO_HEAD.pack(pdo.index, len(pdo.entries), sm, 0, 0, flags)
        for e in pdo.entries:
            code = DATA_TYPE_CODES.get(e.data_type.upper(), 0)
            out += _PDO_ENTRY.pack(e.index, e.subindex, 0, code, e.bit_size, 0)
    return bytes(out)


def build_sii(spec: SiiSpec) -> bytes:
    """The EEPROM image of ``spec``: 64-word header and categories up to 0xFFFF."""
    head = bytearray(2 * HEADER_WORDS)
    _U16.pack_into(head, 0, 0x0C05)  # PDI control: SPI, enhanced link detection
    config = spec.config_data[:14]
    head[: len(config)] = config
    if spec.station_alias or not config:
        _U16.pack_into(head, 8, spec.station_alias)
    _U16.pack_into(head, 14, crc8_sii(bytes(head[:14])))
    for word, value in (
        (0x08, spec.vendor_id),
        (0x0A, spec.product_code),
        (0x0C, spec.revision),
        (0x0E, spec.serial),
    ):
        _U32.pack_into(head, 2 * word, value & 0xFFFFFFFF)
    if spec.mailbox is not None:
        out_start, out_len, in_start, in_len = spec.mailbox
        for word, value in (
            (0x14, out_start),
            (0x15, out_len),
            (0x16, in_start),
            (0x17, in_len),
            (0x18, out_start),
            (0x19, out_len),
            (0x1A, in_start),
            (0x1B, in_len),
            (0x1C, spec.protocols),
        ):
            _U16.pack_into(head, 2 * word, value)
    _U16.pack_into(head, 2 * 0x3E, spec.eeprom_kibit - 1)
    _U16.pack_into(head, 2 * 0x3F, 1)
    _U16.pack_into(head, 14, crc8_sii(bytes(head[:14])))

    body = bytearray()
    body += _category(SiiCategory.STRINGS, _strings([spec.name, spec.group, spec.name]))
    body += _category(SiiCategory.GENERAL, _general(spec))
    fmmus = bytes(spec.fmmus) + (b"\xff" if len(spec.fmmus) % 2 else b"")
    body += _category(SiiCategory.FMMU, fmmus)
    sms = b"".join(
        _SM_ENTRY.pack(s.start, s.length_bytes, s.control, 0, s.enable, s.type)
        for s in spec.sync_managers
    )
    body += _category(SiiCategory.SYNCM, sms)
    sm_of = spec.pdo_sync_manager or {}
    tx = [p for p in spec.pdos if p.direction == Direction.INPUT]
    rx = [p for p in spec.pdos if p.direction == Direction.OUTPUT]
    if tx:
        body += _category(SiiCategory.TXPDO, _pdo_category(tx, sm_of))
    if rx:
        body += _category(SiiCategory.RXPDO, _pdo_category(rx, sm_of))
    if spec.dc:
        body += _category(SiiCategory.DC, _dc_category(spec.dc_assign_activate))
    body += _U16.pack(CATEGORY_END)
    image = bytes(head) + bytes(body)
    size = max(len(image), spec.eeprom_kibit * 128)
    return image + b"\xff" * (size - len(image))


def _dc_category(assign_activate: int = 0x0300) -> bytes:
    """One DC operation mode "DC-Synchron" (ETG.2010 Table 16), default assign-activate
    0x0300 (SYNC0 + cyclic operation)."""
    out = bytearray(24)
    _U32.pack_into(out, 0, 0)  # cycle time 0: set by the master
    _U16.pack_into(out, 20, assign_activate)
    return bytes(out)


# ------------------------------------------------------------ from an ENI
DEFAULT_MAILBOX = (0x1000, 128, 0x1080, 128)
DEFAULT_OUTPUTS_START = 0x1100
DEFAULT_INPUTS_START = 0x1400


def _pdo_bytes(pdos: tuple[Pdo, ...], direction: Direction) -> int:
    bits = sum(p.bit_size for p in pdos if p.direction == direction)
    return (bits + 7) // 8


def _eni_sm_type(sm: ConfiguredSyncManager) -> SmType | None:
    kind = sm.kind.lower()
    return {
        "mboxout": SmType.MAILBOX_OUT,
        "mboxin": SmType.MAILBOX_IN,
        "outputs": SmType.OUTPUTS,
        "inputs": SmType.INPUTS,
    }.get(kind)


def sync_managers_for(slave: Slave) -> tuple[SiiSyncManager, ...]:
    """The slave's SM layout: from its ENI sync managers where they are typed, else defaults."""
    typed = [(sm, _eni_sm_type(sm)) for sm in sorted(slave.sync_managers, key=lambda s: s.index)]
    if typed and all(t is not None for _, t in typed):
        by_index = {sm.index: (sm, t) for sm, t in typed if t is not None}
        out: list[SiiSyncManager] = []
        for i in range(max(by_index) + 1):
            if i not in by_index:
                out.append(SiiSyncManager(0, 0, 0, 0, SmType.UNUSED))
                continue
            configured, kind = by_index[i]
            sm = configured.sync_manager
            control = sm.control  # as the ENI states it: 0 stays 0 (buffered, ECAT reads)
            enable = 1 if sm.enabled else 0
            out.append(SiiSyncManager(sm.physical_start, sm.length_bytes, control, enable, kind))
        return tuple(out)
    if slave.mailbox is None and not slave.pdos and not slave.outputs and not slave.inputs:
        return ()
    out_bytes = _pdo_bytes(slave.pdos, Direction.OUTPUT) or (slave.outputs_bits + 7) // 8
    in_bytes = _pdo_bytes(slave.pdos, Direction.INPUT) or (slave.inputs_bits + 7) // 8
    sms: list[SiiSyncManager] = []
    if slave.mailbox is not None:
        mb = slave.mailbox
        for start, length, kind in (
            (mb.out_start, mb.out_length_bytes, SmType.MAILBOX_OUT),
            (mb.in_start, mb.in_length_bytes, SmType.MAILBOX_IN),
        ):
            sms.append(SiiSyncManager(start, length, SM_CONTROL[kind], 1, kind))
    out_enable = 1 if out_bytes else 0
    in_enable = 1 if in_bytes else 0
    outputs, inputs = SmType.OUTPUTS, SmType.INPUTS
    sms.append(
        SiiSyncManager(DEFAULT_OUTPUTS_START, out_bytes, SM_CONTROL[outputs], out_enable, outputs)
    )
    sms.append(
        SiiSyncManager(DEFAULT_INPUTS_START, in_bytes, SM_CONTROL[inputs], in_enable, inputs)
    )
    return tuple(sms)


def sii_spec_from_slave(slave: Slave, *, complete_access: bool = False) -> SiiSpec:
    """An SII description of an ENI slave: identity, name, mailbox, SMs, PDOs."""
    ident = slave.identity
    mailbox = None
    protocols = 0
    coe = 0
    if slave.mailbox is not None:
        mb = slave.mailbox
        mailbox = (mb.out_start, mb.out_length_bytes, mb.in_start, mb.in_length_bytes)
        protocols = sum(_PROTOCOL_NAMES.get(p, 0) for p in set(mb.protocols)) or MailboxProtocol.COE
        if protocols & MailboxProtocol.COE:
            coe = CoeDetails.SDO | CoeDetails.SDO_INFO | CoeDetails.PDO_ASSIGN
            coe |= CoeDetails.SDO_COMPLETE_ACCESS if complete_access else 0
    sms = sync_managers_for(slave)
    sm_of = _pdo_sm_defaults(sms)
    return SiiSpec(
        name=slave.name,
        vendor_id=ident.vendor_id,
        product_code=ident.product_code,
        revision=ident.revision,
        serial=ident.serial,
        mailbox=mailbox,
        protocols=int(protocols),
        coe_details=int(coe),
        ds402_channels=1 if any(e.index == 0x6040 for p in slave.pdos for e in p.entries) else 0,
        sync_managers=sms,
        fmmus=(1, 2, 3) if mailbox else (1, 2),
        pdos=slave.pdos,
        pdo_sync_manager={
            p.index: sm_of[p.direction]
            for p in slave.pdos
            if p.direction in sm_of and p in assigned_pdos(slave.pdos, p.direction)
        },
        dc=slave.dc is not None or mailbox is not None,
    )


def _pdo_sm_defaults(sms: tuple[SiiSyncManager, ...]) -> dict[Direction, int]:
    out: dict[Direction, int] = {}
    for i, sm in enumerate(sms):
        if sm.type == SmType.OUTPUTS:
            out.setdefault(Direction.OUTPUT, i)
        elif sm.type == SmType.INPUTS:
            out.setdefault(Direction.INPUT, i)
    return out


def sii_from_slave(slave: Slave, *, complete_access: bool = False) -> bytes:
    return build_sii(sii_spec_from_slave(slave, complete_access=complete_access))


# ------------------------------------------------------------ from an ESI device
_ESI_SM_TYPES = {
    "mboxout": SmType.MAILBOX_OUT,
    "mboxin": SmType.MAILBOX_IN,
    "outputs": SmType.OUTPUTS,
    "inputs": SmType.INPUTS,
}

#: FMMU category bytes of ESI ``<Fmmu>`` texts (ETG.2010 Table 10); others are 0 (unused).
_ESI_FMMU_TYPES = {"outputs": 1, "inputs": 2, "mboxstate": 3}


def _esi_sync_managers(device: EsiDevice) -> tuple[SiiSyncManager, ...]:
    return tuple(
        SiiSyncManager(
            sm.start_address,
            sm.default_size_bytes,
            sm.control,
            1 if sm.enable else 0,
            _ESI_SM_TYPES.get(sm.kind.lower(), SmType.UNUSED),
        )
        for sm in device.sync_managers
    )


def _esi_coe_details(device: EsiDevice) -> int:
    coe = device.coe
    if coe is None:
        return 0
    flags = CoeDetails.SDO
    for on, flag in (
        (coe.sdo_info, CoeDetails.SDO_INFO),
        (coe.pdo_assign, CoeDetails.PDO_ASSIGN),
        (coe.pdo_config, CoeDetails.PDO_CONFIG),
        (coe.pdo_upload, CoeDetails.UPLOAD_AT_STARTUP),
        (coe.complete_access, CoeDetails.SDO_COMPLETE_ACCESS),
    ):
        flags |= flag if on else 0
    return int(flags)


def _esi_mailbox(device: EsiDevice) -> tuple[int, int, int, int] | None:
    out, inn = device.sync_manager("MBoxOut"), device.sync_manager("MBoxIn")
    if out is None or inn is None:
        return None
    return (out.start_address, out.default_size_bytes, inn.start_address, inn.default_size_bytes)


def sii_spec_from_esi_device(
    device: EsiDevice, *, serial: int = 0, station_alias: int = 0
) -> SiiSpec:
    """An SII description of an ESI device: identity, names, mailbox SMs and protocols, CoE
    details, FMMUs, SMs (default sizes), the default-assigned PDOs, DC and ConfigData."""
    ident = device.identity
    mailbox = _esi_mailbox(device)
    protocols = sum(_PROTOCOL_NAMES.get(p, 0) for p in device.mailbox_protocols)
    sms = _esi_sync_managers(device)
    sm_of = _pdo_sm_defaults(sms)
    pdos = device.assigned_pdos
    assign = next((m.assign_activate for m in device.dc_op_modes if m.assign_activate), 0)
    byte_size = device.eeprom.byte_size if device.eeprom is not None else None
    return SiiSpec(
        name=device.name or device.type_name,
        vendor_id=ident.vendor_id,
        product_code=ident.product_code,
        revision=ident.revision,
        serial=serial,
        station_alias=station_alias,
        mailbox=mailbox,
        protocols=protocols if mailbox is not None else 0,
        coe_details=_esi_coe_details(device),
        ds402_channels=1 if device.profile_no == 402 else 0,
        sync_managers=sms,
        fmmus=tuple(_ESI_FMMU_TYPES.get(f.lower(), 0) for f in device.fmmus),
        pdos=pdos,
        pdo_sync_manager={p.index: sm_of[p.direction] for p in pdos if p.direction in sm_of},
        dc=bool(device.dc_op_modes),
        group=device.group or device.type_name,
        eeprom_kibit=max(1, (byte_size or 4096) * 8 // 1024),
        dc_assign_activate=assign,
        config_data=device.eeprom.config_data if device.eeprom is not None else b"",
    )


def sii_from_esi_device(
    device: EsiDevice, *, serial: int = 0, station_alias: int = 0, revision: int | None = None
) -> bytes:
    """The EEPROM image of an ESI device; the stated size grows if the ESI's is too small.
    ``revision`` overrides the ESI's (a device matched by product code only)."""
    spec = sii_spec_from_esi_device(device, serial=serial, station_alias=station_alias)
    if revision is not None:
        spec = replace(spec, revision=revision)
    image = build_sii(spec)
    needed_kibit = (len(image) + 127) // 128
    if needed_kibit > spec.eeprom_kibit:
        image = build_sii(replace(spec, eeprom_kibit=needed_kibit))
    return image


# ------------------------------------------------------------------ reading
def categories(image: bytes) -> dict[int, bytes]:
    """Category type -> data (first occurrence), walking from word 0x40 to 0xFFFF."""
    out: dict[int, bytes] = {}
    pos = 2 * HEADER_WORDS
    while pos + 4 <= len(image):
        kind, words = struct.unpack_from("<HH", image, pos)
        if kind == CATEGORY_END:
            break
        out.setdefault(kind, image[pos + 4 : pos + 4 + 2 * words])
        pos += 4 + 2 * words
    return out


def _first_string(data: bytes) -> str:
    if len(data) < 2:
        return ""
    n = data[1]
    return data[2 : 2 + n].decode("latin-1")


def _sm_entries(data: bytes) -> tuple[SiiSyncManager, ...]:
    out = []
    for pos in range(0, len(data) - 7, 8):
        start, length, control, _status, enable, kind = _SM_ENTRY.unpack_from(data, pos)
        out.append(SiiSyncManager(start, length, control, enable, kind))
    return tuple(out)


def _pdo_bits(data: bytes) -> int:
    bits, pos = 0, 0
    while pos + 8 <= len(data):
        _index, n, sm, *_rest = _PDO_HEAD.unpack_from(data, pos)
        pos += 8
        for _ in range(n):
            if pos + 8 > len(data):
                break
            bits += data[pos + 5] if sm != 0xFF else 0
            pos += 8
    return bits


def sii_layout(image: bytes) -> SiiLayout:
    """Read identity, mailbox, SMs and process-data sizes back from an image."""
    if len(image) < 2 * HEADER_WORDS:
        return SiiLayout()
    w = struct.unpack_from("<64H", image, 0)
    cats = categories(image)
    sms = _sm_entries(cats.get(SiiCategory.SYNCM, b""))
    return SiiLayout(
        vendor_id=w[8] | w[9] << 16,
        product_code=w[10] | w[11] << 16,
        revision=w[12] | w[13] << 16,
        serial=w[14] | w[15] << 16,
        station_alias=w[4],
        mailbox_out_start=w[0x18],
        mailbox_out_bytes=w[0x19],
        mailbox_in_start=w[0x1A],
        mailbox_in_bytes=w[0x1B],
        protocols=w[0x1C],
        name=_first_string(cats.get(SiiCategory.STRINGS, b"")),
        sync_managers=sms,
        outputs_bytes=(_pdo_bits(cats.get(SiiCategory.RXPDO, b"")) + 7) // 8,
        inputs_bytes=(_pdo_bits(cats.get(SiiCategory.TXPDO, b"")) + 7) // 8,
        mailbox_out_sm=_sm_of(sms, SmType.MAILBOX_OUT, 0),
        mailbox_in_sm=_sm_of(sms, SmType.MAILBOX_IN, 1),
        outputs_sm=_sm_of(sms, SmType.OUTPUTS, 2),
        inputs_sm=_sm_of(sms, SmType.INPUTS, 3),
    )
