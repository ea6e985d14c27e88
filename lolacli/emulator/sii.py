"""The SII EEPROM image of an emulated slave (ETG.1000.6 §5.4, ETG.2010): what goes in it,
from an ENI slave or an ESI device, and what the emulated ESC reads back from it.

Every layout and code (header words, categories, SYNCM/PDO/FMMU/DC entries) is
:mod:`lolacli.wire.sii`'s; this module chooses the content. Categories written: STRINGS
(10), GENERAL (30), FMMU (40), SYNCM (41), TXPDO (50), RXPDO (51), DC (60). Pure: values
in, bytes out.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, replace

from lolacli.devices.base import assigned_pdos
from lolacli.eni.esi import EsiDevice
from lolacli.eni.model import ConfiguredSyncManager, Direction, Pdo, Slave
from lolacli.errors import WireError
from lolacli.wire.datatypes import data_type_from_name
from lolacli.wire.registers import (
    SM_CONTROL_INPUTS,
    SM_CONTROL_MAILBOX_IN,
    SM_CONTROL_MAILBOX_OUT,
    SM_CONTROL_OUTPUTS,
    SyncManager,
)
from lolacli.wire.sii import (  # the one definition of every layout and code
    CATEGORY_END,
    HEADER_BYTES,
    PDO_NOT_ASSIGNED,
    PROTOCOL_NAMES,
    CoeDetails,
    FmmuUsage,
    MailboxProtocol,
    SiiCategory,
    SiiGeneral,
    SiiHeader,
    SiiPdo,
    SiiPdoEntry,
    SiiSyncManager,
    SmType,
    decode_sii_header,
    decode_sii_pdos,
    decode_sii_strings,
    decode_sii_sync_managers,
    encode_sii_category,
    encode_sii_dc,
    encode_sii_fmmus,
    encode_sii_general,
    encode_sii_header,
    encode_sii_pdos,
    encode_sii_strings,
    encode_sii_sync_managers,
    sii_categories,
)

_U16 = struct.Struct("<H")

_PROTOCOL_NAMES = {name: int(bit) for bit, name in PROTOCOL_NAMES}  # "CoE" -> 0x04

SM_CONTROL = {
    SmType.MAILBOX_OUT: SM_CONTROL_MAILBOX_OUT,
    SmType.MAILBOX_IN: SM_CONTROL_MAILBOX_IN,
    SmType.OUTPUTS: SM_CONTROL_OUTPUTS,
    SmType.INPUTS: SM_CONTROL_INPUTS,
}


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
    bootstrap_out_start: int = 0
    bootstrap_out_bytes: int = 0
    bootstrap_in_start: int = 0
    bootstrap_in_bytes: int = 0
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
    #: the bootstrap mailbox (BOOT state) as ``mailbox``; None: the standard mailbox's
    bootstrap: tuple[int, int, int, int] | None = None
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


def _type_code(name: str) -> int:
    """The CoE data type code (ETG.1000.6 Table 64) of an ENI/ESI type name, as every
    reader of one types it (:func:`lolacli.wire.datatypes.data_type_from_name`); 0 when
    it names none."""
    found = data_type_from_name(name) if name else None
    return 0 if found is None else int(found)


def _sii_pdos(pdos: list[Pdo], sm_of: dict[int, int]) -> list[SiiPdo]:
    """The PDOs as SII states them: a PDO that no sync manager takes by default has SM
    0xFF, so a master that maps from the SII leaves it out."""
    return [
        SiiPdo(
            pdo.index,
            pdo.sync_manager
            if pdo.sync_manager is not None
            else sm_of.get(pdo.index, PDO_NOT_ASSIGNED),
            tuple(
                SiiPdoEntry(e.index, e.subindex, e.bit_size, _type_code(e.data_type))
                for e in pdo.entries
            ),
            flags=(0x0001 if pdo.mandatory else 0) | (0x0010 if pdo.fixed else 0),
        )
        for pdo in pdos
    ]


#: PDI control word 0x0C05 (SPI, enhanced link detection) where no ESI gives words 0-6
_DEFAULT_CONFIG = _U16.pack(0x0C05) + bytes(12)


def build_sii(spec: SiiSpec) -> bytes:
    """The EEPROM image of ``spec``: 64-word header and categories up to 0xFFFF."""
    config = bytearray(_DEFAULT_CONFIG)
    given = spec.config_data[:14]
    config[: len(given)] = given
    alias = spec.station_alias
    if given and not alias:
        alias = _U16.unpack_from(config, 8)[0]  # the ESI's word 4
    out_start, out_len, in_start, in_len = spec.mailbox or (0, 0, 0, 0)
    boot_out, boot_out_len, boot_in, boot_in_len = spec.bootstrap or spec.mailbox or (0, 0, 0, 0)
    header = SiiHeader(
        station_alias=alias,
        vendor_id=spec.vendor_id,
        product_code=spec.product_code,
        revision=spec.revision,
        serial=spec.serial,
        rx_mailbox_offset=out_start,
        rx_mailbox_bytes=out_len,
        tx_mailbox_offset=in_start,
        tx_mailbox_bytes=in_len,
        mailbox_protocols=spec.protocols if spec.mailbox is not None else 0,
        size_bytes=spec.eeprom_kibit * 128,
        version=1,
        checksum=0,
        checksum_ok=True,
        bootstrap_rx_mailbox_offset=boot_out,
        bootstrap_rx_mailbox_bytes=boot_out_len,
        bootstrap_tx_mailbox_offset=boot_in,
        bootstrap_tx_mailbox_bytes=boot_in_len,
    )
    general = SiiGeneral(
        group_index=2,
        image_index=0,
        order_index=3,
        name_index=1,
        coe_details=spec.coe_details,
        ds402_channels=spec.ds402_channels,
        physical_ports=0x0011,  # ports 0 and 1: MII
    )
    body = [
        encode_sii_category(
            SiiCategory.STRINGS, encode_sii_strings([spec.name, spec.group, spec.name])
        ),
        encode_sii_category(SiiCategory.GENERAL, encode_sii_general(general)),
        encode_sii_category(SiiCategory.FMMU, encode_sii_fmmus(spec.fmmus)),
        encode_sii_category(SiiCategory.SYNCM, encode_sii_sync_managers(spec.sync_managers)),
    ]
    sm_of = spec.pdo_sync_manager or {}
    tx = [p for p in spec.pdos if p.direction == Direction.INPUT]
    rx = [p for p in spec.pdos if p.direction == Direction.OUTPUT]
    if tx:
        body.append(encode_sii_category(SiiCategory.TXPDO, encode_sii_pdos(_sii_pdos(tx, sm_of))))
    if rx:
        body.append(encode_sii_category(SiiCategory.RXPDO, encode_sii_pdos(_sii_pdos(rx, sm_of))))
    if spec.dc:
        body.append(encode_sii_category(SiiCategory.DC, encode_sii_dc(spec.dc_assign_activate)))
    body.append(_U16.pack(CATEGORY_END))
    image = encode_sii_header(header, bytes(config)) + b"".join(body)
    size = max(len(image), spec.eeprom_kibit * 128)
    return image + b"\xff" * (size - len(image))


# ------------------------------------------------------------ from an ENI
DEFAULT_MAILBOX = (0x1000, 128, 0x1080, 128)
#: each direction of the bootstrap mailbox of an emulated slave: a bootloader's larger
#: mailbox carries a firmware in fewer FoE packets (one ESI of the corpus states this
#: very layout, 0x1000/0x1400 of 1 KiB each)
BOOTSTRAP_MAILBOX_BYTES = 0x400


def bootstrap_mailbox(
    mailbox: tuple[int, int, int, int] | None,
) -> tuple[int, int, int, int] | None:
    """The bootstrap mailbox of an emulated slave with the standard ``mailbox``: out where
    the standard one starts, in right after it, :data:`BOOTSTRAP_MAILBOX_BYTES` each (in
    BOOT no process data uses the RAM after it); the standard mailbox where that would run
    past the ESC's 64 KiB."""
    if mailbox is None:
        return None
    start = mailbox[0]
    size = BOOTSTRAP_MAILBOX_BYTES
    if start + 2 * size > 0x10000:
        return mailbox
    return (start, size, start + size, size)


def _sm(start: int, length: int, control: int, enable: int, kind: int) -> SiiSyncManager:
    return SiiSyncManager(SyncManager(start, length, control, 0, enable), kind)


DEFAULT_OUTPUTS_START = 0x1100
DEFAULT_INPUTS_START = 0x1400


def _pdo_bytes(pdos: tuple[Pdo, ...], direction: Direction) -> int:
    bits = sum(p.bit_size for p in pdos if p.direction == direction)
    return (bits + 7) // 8


def _eni_sm_type(sm: ConfiguredSyncManager) -> SmType | None:
    """The SM's use as the ENI types it, else as its control byte says (an ENI whose
    InitCmds alone set the SM up: mode bits 1:0 mailbox or buffered, direction bits 3:2
    written or read by the master)."""
    kind = sm.kind.lower()
    if not kind:
        mode, direction = sm.sync_manager.control & 0x03, (sm.sync_manager.control >> 2) & 0x03
        if mode not in (0x00, 0x02) or direction not in (0x00, 0x01):
            return None
        written = direction == 0x01
        if mode == 0x02:
            return SmType.MAILBOX_OUT if written else SmType.MAILBOX_IN
        return SmType.OUTPUTS if written else SmType.INPUTS
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
                out.append(_sm(0, 0, 0, 0, SmType.UNUSED))
                continue
            configured, kind = by_index[i]
            sm = configured.sync_manager
            control = sm.control  # as the ENI states it: 0 stays 0 (buffered, ECAT reads)
            enable = 1 if sm.enabled else 0
            out.append(_sm(sm.physical_start, sm.length_bytes, control, enable, kind))
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
            sms.append(_sm(start, length, SM_CONTROL[kind], 1, kind))
    out_enable = 1 if out_bytes else 0
    in_enable = 1 if in_bytes else 0
    outputs, inputs = SmType.OUTPUTS, SmType.INPUTS
    sms.append(_sm(DEFAULT_OUTPUTS_START, out_bytes, SM_CONTROL[outputs], out_enable, outputs))
    sms.append(_sm(DEFAULT_INPUTS_START, in_bytes, SM_CONTROL[inputs], in_enable, inputs))
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
        bootstrap=bootstrap_mailbox(mailbox),
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
_ESI_FMMU_TYPES = {
    "outputs": FmmuUsage.OUTPUTS,
    "inputs": FmmuUsage.INPUTS,
    "mboxstate": FmmuUsage.SYNCM_STATUS,
}


def _esi_sync_managers(device: EsiDevice) -> tuple[SiiSyncManager, ...]:
    return tuple(
        _sm(
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
        fmmus=tuple(int(_ESI_FMMU_TYPES.get(f.lower(), FmmuUsage.UNUSED)) for f in device.fmmus),
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
def _first_string(data: bytes) -> str:
    try:
        strings = decode_sii_strings(data)
    except WireError:
        return ""
    return strings[0] if strings else ""


def _assigned_bits(data: bytes) -> int:
    """Bits of the PDOs a sync manager takes by default (SM not 0xFF)."""
    return sum(p.bit_length for p in decode_sii_pdos(data) if p.sync_manager != PDO_NOT_ASSIGNED)


def sii_layout(image: bytes) -> SiiLayout:
    """Read identity, mailbox, SMs and process-data sizes back from an image."""
    if len(image) < HEADER_BYTES:
        return SiiLayout()
    h = decode_sii_header(image)
    cats = sii_categories(image)
    sms = decode_sii_sync_managers(cats.get(SiiCategory.SYNCM, b""))
    return SiiLayout(
        vendor_id=h.vendor_id,
        product_code=h.product_code,
        revision=h.revision,
        serial=h.serial,
        station_alias=h.station_alias,
        mailbox_out_start=h.rx_mailbox_offset,
        mailbox_out_bytes=h.rx_mailbox_bytes,
        mailbox_in_start=h.tx_mailbox_offset,
        mailbox_in_bytes=h.tx_mailbox_bytes,
        bootstrap_out_start=h.bootstrap_rx_mailbox_offset,
        bootstrap_out_bytes=h.bootstrap_rx_mailbox_bytes,
        bootstrap_in_start=h.bootstrap_tx_mailbox_offset,
        bootstrap_in_bytes=h.bootstrap_tx_mailbox_bytes,
        protocols=h.mailbox_protocols,
        name=_first_string(cats.get(SiiCategory.STRINGS, b"")),
        sync_managers=sms,
        outputs_bytes=(_assigned_bits(cats.get(SiiCategory.RXPDO, b"")) + 7) // 8,
        inputs_bytes=(_assigned_bits(cats.get(SiiCategory.TXPDO, b"")) + 7) // 8,
        mailbox_out_sm=_sm_of(sms, SmType.MAILBOX_OUT, 0),
        mailbox_in_sm=_sm_of(sms, SmType.MAILBOX_IN, 1),
        outputs_sm=_sm_of(sms, SmType.OUTPUTS, 2),
        inputs_sm=_sm_of(sms, SmType.INPUTS, 3),
    )
