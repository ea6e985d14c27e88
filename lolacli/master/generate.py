"""``lolacli eni generate``: the ENI of a bus that has none, from what its slaves say.

The bus is scanned and configured as far as PREOP, as SOEM's ``ecx_config_init`` and
``ecx_config_map`` do, and what was learnt is written down as an ENI model
(:mod:`lolacli.eni.model`; :mod:`lolacli.eni.writer` makes the XML):

1. slaves counted (BRD 0x0000), station addresses 1001, 1002, … (0x03E9…, the ENI
   convention) written by auto-increment address;
2. every slave's SII read whole (:func:`lolacli.master.eeprom.read_sii` with its
   categories): identity, name, mailbox and protocols, SYNCM (sync managers and what
   each is for), TXPDO/RXPDO;
3. the PDO assignment of each slave, from the first source that has it:

   * an ESI device of the same identity (``--esi``): its default-assigned PDOs, its sync
     managers, its DC op mode (the first with an AssignActivate); the assignment and the
     mapping of configurable PDOs are written by CoE InitCmds on PREOP → SAFEOP;
   * CoE, for a slave with a CoE mailbox: the slave is brought to PREOP
     (:class:`~lolacli.master.preop.PreopBus`) and 0x1C10+n (n the SII's output and input
     sync managers) and the mapping objects they list are read by SDO upload, as
     ``ecx_readPDOmap`` does;
   * the SII: the PDOs its TXPDO/RXPDO categories give a sync manager;

4. the layout: each slave one block of the logical image, as long as the larger of its
   outputs and inputs (outputs and inputs at the same logical address, one LRW),
   blocks in the order of :func:`layout_order` (the LOLA ENI's, ``tools/make_examples``);
   an FMMU per process-data sync manager;
5. one cyclic frame: the LRW with its expected working counter (ETG.1000.4 Table 13:
   3 per slave that reads and writes, 1 read only, 2 write only), the ARMW that
   distributes the reference clock's time where DC is configured, a BRD of AL status;
6. InitCmds per transition as the LOLA ENI has them (INIT with error acknowledge, station
   address, watchdogs, mailbox SMs, PREOP; process SMs, FMMUs, DC, SAFEOP; OP; and back).

The slaves are left in INIT (one BWR of AL control) once everything is read.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from lolacli.eni.esi import EsiDevice, EsiFile
from lolacli.eni.model import (
    CoeInitCmd,
    ConfiguredFmmu,
    ConfiguredSyncManager,
    Cyclic,
    CyclicCommand,
    CyclicFrame,
    Direction,
    DistributedClock,
    Eni,
    Identity,
    InitCmd,
    Mailbox,
    Pdo,
    PdoEntry,
    ProcessDataArea,
    ProcessImage,
    Slave,
    Variable,
)
from lolacli.eni.model import Master as EniMaster
from lolacli.errors import (
    LolaError,
    TransportError,
)
from lolacli.master import eeprom
from lolacli.master.core import Master, MasterOptions
from lolacli.master.preop import PreopBus, count_slaves, preop_init_cmds
from lolacli.master.transport import Transport
from lolacli.wire.commands import Command, wkc_increment
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import (
    SM_CONTROL_MAILBOX_IN,
    SM_CONTROL_MAILBOX_OUT,
    AlState,
    Fmmu,
    Register,
    SyncManager,
    encode_fmmu,
    encode_sync_manager,
    fmmu_address,
    sync_manager_address,
)
from lolacli.wire.sii import (
    PDO_NOT_ASSIGNED,
    SiiCategory,
    SiiInfo,
    SiiPdo,
    SiiSyncManager,
    SmType,
    decode_sii_pdos,
    decode_sii_sync_managers,
    protocol_names,
    sii_string,
)

SCHEMA = "lolacli.eni-generate/1"
#: the ENI convention: station addresses 1001, 1002, … in line order
FIRST_STATION = 1001
#: where the logical process image starts (the LOLA ENI's, TwinCAT's 0x00010000)
LOGICAL_BASE = 0x0001_0000
#: the cycle time written where the caller gives none
DEFAULT_CYCLE_NS = 1_000_000

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_AL_MASK = _U16.pack(0x001F)  # state bits and the error indicator

#: CoE data type codes (ETG.1000.6 Table 64) as the IEC names the ENI variables carry
_IEC = {
    0x0001: "BOOL", 0x0002: "SINT", 0x0003: "INT", 0x0004: "DINT", 0x0005: "USINT",
    0x0006: "UINT", 0x0007: "UDINT", 0x0008: "REAL", 0x0011: "LREAL", 0x0015: "LINT",
    0x001B: "ULINT",
}  # fmt: skip
_BY_BITS = {1: "BOOL", 8: "USINT", 16: "UINT", 32: "UDINT", 64: "ULINT"}

_KIND = {
    SmType.MAILBOX_OUT: "MBoxOut",
    SmType.MAILBOX_IN: "MBoxIn",
    SmType.OUTPUTS: "Outputs",
    SmType.INPUTS: "Inputs",
}
_ESI_KIND = {v.lower(): k for k, v in _KIND.items()}


@dataclass(frozen=True, slots=True)
class GenerateOptions:
    cycle_time_ns: int = DEFAULT_CYCLE_NS
    first_station: int = FIRST_STATION
    frame_timeout_ns: int = 20_000_000  # one acyclic frame (hosts and veth are slow)
    frame_retries: int = 3
    coe: bool = True  # read the PDO assignment over CoE where a slave has it


@dataclass(frozen=True, slots=True)
class SlaveOrigin:
    """Where the generated configuration of one slave comes from."""

    position: int
    station_address: int
    name: str
    identity: Identity
    pdo_source: str  # "esi", "coe", "sii" or "none" (no process data)
    esi: str | None = None  # the ESI file the device was found in
    inputs_bits: int = 0
    outputs_bits: int = 0
    dc: bool = False
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "position": self.position,
            "station_address": self.station_address,
            "name": self.name,
            "vendor_id": self.identity.vendor_id,
            "product_code": self.identity.product_code,
            "revision": self.identity.revision,
            "serial": self.identity.serial,
            "pdo_source": self.pdo_source,
            "esi": self.esi,
            "inputs_bits": self.inputs_bits,
            "outputs_bits": self.outputs_bits,
            "dc": self.dc,
            "notes": list(self.notes),
        }


@dataclass(frozen=True, slots=True)
class Generated:
    eni: Eni
    slaves: tuple[SlaveOrigin, ...]
    frames_sent: int = 0
    frames_lost: int = 0

    def to_dict(self, output: str | None = None) -> dict[str, Any]:
        eni = self.eni
        pi = eni.process_image
        frames = []
        for frame in eni.cyclic_frames:
            frames.append(
                {
                    "frame_bytes": frame.frame_bytes,
                    "commands": [
                        {
                            "cmd": Command(c.cmd).name,
                            "length_bytes": c.data_length_bytes,
                            "expected_wkc": c.expected_wkc,
                        }
                        for c in frame.commands
                    ],
                }
            )
        return {
            "schema": SCHEMA,
            "iface": eni.master.name.removeprefix("lolacli eni generate on ") or None,
            "output": output,
            "cycle_time_us": (eni.cycle_time_ns or 0) / 1000,
            "slave_count": len(eni.slaves),
            "slaves": [s.to_dict() for s in self.slaves],
            "process_image": {
                "inputs_bytes": pi.inputs_bytes,
                "outputs_bytes": pi.outputs_bytes,
                "variables": len(pi.variables),
            },
            "cyclic_frames": frames,
            "frames_sent": self.frames_sent,
            "frames_lost": self.frames_lost,
        }


# ------------------------------------------------------------------ what a slave is
@dataclass(slots=True)
class _Found:
    """One slave as read: its SII, then the PDOs and SMs chosen for it."""

    position: int
    station: int
    sii: SiiInfo
    categories: dict[int, bytes]
    sync_managers: list[SiiSyncManager] = field(default_factory=list)
    pdos: list[Pdo] = field(default_factory=list)
    source: str = "none"
    esi: tuple[EsiFile, EsiDevice] | None = None
    assign_activate: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def identity(self) -> Identity:
        h = self.sii.header
        return Identity(h.vendor_id, h.product_code, h.revision, h.serial)

    @property
    def name(self) -> str:
        return self.sii.name or f"Slave {self.position}"

    @property
    def mailbox(self) -> Mailbox | None:
        h = self.sii.header
        if not (h.rx_mailbox_bytes and h.tx_mailbox_bytes):
            return None
        return Mailbox(
            h.rx_mailbox_offset,
            h.rx_mailbox_bytes,
            h.tx_mailbox_offset,
            h.tx_mailbox_bytes,
            protocols=protocol_names(h.mailbox_protocols),
        )

    def string(self, index: int) -> str:
        return sii_string(self.sii.strings, index) or ""


def generate(
    transport: Transport,
    *,
    esi: Sequence[EsiFile] = (),
    options: GenerateOptions | None = None,
    where: str = "",
) -> Generated:
    """The ENI of the bus behind ``transport`` (see the module docstring). TransportError
    when nothing answers or a slave's SII does not read."""
    opts = options or GenerateOptions()
    empty = Eni(EniMaster(), (), (), ProcessImage(0, 0), source=where)
    master = Master(
        empty,
        transport,
        options=MasterOptions(
            frame_timeout_ns=opts.frame_timeout_ns, frame_retries=opts.frame_retries
        ),
    )
    count = count_slaves(master, where)
    stations = [opts.first_station + k for k in range(count)]
    master.exchange_many(
        [
            Datagram.physical(Command.APWR, (-k) & 0xFFFF, Register.STATION_ADDRESS, _U16.pack(s))
            for k, s in enumerate(stations)
        ]
    )
    found: list[_Found] = []
    reads = eeprom.read_sii(master, stations, auto_increment=False, categories=True)
    for k, (station, got) in enumerate(zip(stations, reads, strict=True), start=1):
        if got.error is not None or got.info is None:
            raise TransportError(
                f"slave {k} (station 0x{station:04X}): {got.error or 'SII not read'}"
            )
        found.append(_Found(k, station, got.info, got.categories))
    for f in found:
        f.sync_managers = list(
            decode_sii_sync_managers(f.categories.get(SiiCategory.SYNCM, b""))
        )
        f.esi = _esi_device(esi, f)
    bus = PreopBus(empty, transport, master=master)
    try:
        for f in found:
            _choose_pdos(f, bus, opts)
    finally:
        master.exchange_many(  # leave the bus in INIT, as found after power-up
            [Datagram.physical(Command.BWR, 0, Register.AL_CONTROL, _U16.pack(AlState.INIT))]
        )
    eni = build_eni(found, opts, where)
    origins = tuple(
        SlaveOrigin(
            f.position,
            f.station,
            f.name,
            f.identity,
            f.source,
            f.esi[0].source if f.esi is not None else None,
            s.inputs_bits,
            s.outputs_bits,
            s.dc is not None,
            tuple(f.notes),
        )
        for f, s in zip(found, eni.slaves, strict=True)
    )
    return Generated(eni, origins, master.stats.frames_sent, master.stats.frames_lost)


def _esi_device(esi: Sequence[EsiFile], f: _Found) -> tuple[EsiFile, EsiDevice] | None:
    ident = f.identity
    for file in esi:
        device = file.find(ident.vendor_id, ident.product_code, ident.revision)
        if device is not None:
            if device.identity.revision != ident.revision:
                f.notes.append(
                    f"ESI revision 0x{device.identity.revision:08X} used for revision "
                    f"0x{ident.revision:08X}"
                )
            return file, device
    return None


# ------------------------------------------------------------------ PDO assignment
def _choose_pdos(f: _Found, bus: PreopBus, opts: GenerateOptions) -> None:
    if f.esi is not None:
        _from_esi(f, f.esi[1])
        return
    mailbox = f.mailbox
    if opts.coe and mailbox is not None and "CoE" in mailbox.protocols:
        try:
            f.pdos = _from_coe(f, bus, mailbox)
            f.source = "coe"
        except LolaError as exc:
            f.notes.append(f"PDO assignment not read over CoE ({exc}): the SII's used")
            f.pdos = []
    if f.source != "coe":
        f.pdos = _from_sii(f)
        f.source = "sii"
    if not f.pdos:
        f.source = "none"


def _process_sms(f: _Found) -> list[tuple[int, Direction]]:
    out = []
    for n, sm in enumerate(f.sync_managers):
        if sm.type == SmType.OUTPUTS:
            out.append((n, Direction.OUTPUT))
        elif sm.type == SmType.INPUTS:
            out.append((n, Direction.INPUT))
    return out


def _sii_pdo_list(f: _Found) -> list[tuple[SiiPdo, Direction]]:
    out: list[tuple[SiiPdo, Direction]] = []
    for kind, direction in (
        (SiiCategory.RXPDO, Direction.OUTPUT),
        (SiiCategory.TXPDO, Direction.INPUT),
    ):
        out += [(p, direction) for p in decode_sii_pdos(f.categories.get(kind, b""))]
    return out


def _pdo_from_sii(f: _Found, p: SiiPdo, direction: Direction, sm: int | None) -> Pdo:
    prefix = "RxPDO" if direction is Direction.OUTPUT else "TxPDO"
    return Pdo(
        p.index,
        f.string(p.name_index) or f"{prefix} 0x{p.index:04X}",
        direction,
        sm,
        tuple(
            PdoEntry(
                e.index,
                e.subindex,
                e.bit_length,
                f.string(e.name_index) or _entry_name(e.index, e.subindex),
                _type_name(e.data_type, e.bit_length) if e.index else "",
            )
            for e in p.entries
        ),
        fixed=bool(p.flags & 0x0010),
        mandatory=bool(p.flags & 0x0001),
    )


def _from_sii(f: _Found) -> list[Pdo]:
    return [
        _pdo_from_sii(f, p, direction, p.sync_manager)
        for p, direction in _sii_pdo_list(f)
        if p.sync_manager != PDO_NOT_ASSIGNED and p.sync_manager < len(f.sync_managers)
    ]


def _from_coe(f: _Found, bus: PreopBus, mailbox: Mailbox) -> list[Pdo]:
    """``ecx_readPDOmap``: for each process SM n, 0x1C10+n and the PDOs it lists."""
    slave = Slave(
        position=f.position,
        name=f.name,
        identity=f.identity,
        station_address=f.station,
        auto_inc_address=(-(f.position - 1)) & 0xFFFF,
        mailbox=mailbox,
        init_cmds=preop_init_cmds(f.station, mailbox),
    )
    slave = bus.bring_up(slave)
    sdo = bus.master.sdo(slave)
    known = {(p.index, d): p for p, d in _sii_pdo_list(f)}
    pdos: list[Pdo] = []
    for n, direction in _process_sms(f):
        assign = 0x1C10 + n
        for k in range(1, _u(sdo.upload(assign, 0)) + 1):
            index = _u(sdo.upload(assign, k))
            entries = []
            for j in range(1, _u(sdo.upload(index, 0)) + 1):
                word = _u(sdo.upload(index, j))
                e_index, e_sub, bits = word >> 16, (word >> 8) & 0xFF, word & 0xFF
                entries.append((e_index, e_sub, bits))
            pdos.append(_coe_pdo(f, known.get((index, direction)), index, direction, n, entries))
    return pdos


def _coe_pdo(
    f: _Found,
    sii: SiiPdo | None,
    index: int,
    direction: Direction,
    sm: int,
    entries: list[tuple[int, int, int]],
) -> Pdo:
    """A PDO as CoE maps it, named as the SII names it where the SII has it."""
    by_entry = {(e.index, e.subindex): e for e in sii.entries} if sii is not None else {}
    prefix = "RxPDO" if direction is Direction.OUTPUT else "TxPDO"
    out = []
    for e_index, e_sub, bits in entries:
        e = by_entry.get((e_index, e_sub))
        name = (f.string(e.name_index) if e is not None else "") or _entry_name(e_index, e_sub)
        code = e.data_type if e is not None else 0
        out.append(PdoEntry(e_index, e_sub, bits, name, _type_name(code, bits) if e_index else ""))
    name = (f.string(sii.name_index) if sii is not None else "") or f"{prefix} 0x{index:04X}"
    return Pdo(index, name, direction, sm, tuple(out))


def _from_esi(f: _Found, device: EsiDevice) -> None:
    f.source = "esi"
    sms: list[SiiSyncManager] = []
    for sm in sorted(device.sync_managers, key=lambda s: s.index):
        while len(sms) < sm.index:
            sms.append(SiiSyncManager(SyncManager(0, 0, 0), SmType.UNUSED))
        kind = _ESI_KIND.get(sm.kind.lower(), SmType.UNUSED)
        sms.append(
            SiiSyncManager(
                SyncManager(sm.start_address, sm.default_size_bytes, sm.control, 0, int(sm.enable)),
                kind,
            )
        )
    if sms:
        f.sync_managers = sms
    defaults = {d: n for n, d in reversed(_process_sms(f))}
    f.pdos = [
        p if p.sync_manager is not None else _with_sm(p, defaults.get(p.direction))
        for p in device.assigned_pdos
    ]
    modes = [m for m in device.dc_op_modes if m.assign_activate]
    if modes:
        f.assign_activate = modes[0].assign_activate
        f.notes.append(f"DC op mode {modes[0].name!r} of the ESI")


def _with_sm(p: Pdo, sm: int | None) -> Pdo:
    from dataclasses import replace

    return replace(p, sync_manager=sm)


def _u(raw: bytes) -> int:
    return int.from_bytes(raw, "little")


def _entry_name(index: int, subindex: int) -> str:
    return "padding" if index == 0 else f"0x{index:04X}:{subindex:02X}"


def _type_name(code: int, bits: int) -> str:
    return _IEC.get(code) or _BY_BITS.get(bits) or f"BIT{bits}"


# ------------------------------------------------------------------ the ENI
@dataclass(slots=True)
class _Placed:
    f: _Found
    out_sms: list[tuple[int, int]]  # (SM, bytes)
    in_sms: list[tuple[int, int]]
    offset: int = 0  # bytes from LOGICAL_BASE

    @property
    def out_bytes(self) -> int:
        return sum(b for _n, b in self.out_sms)

    @property
    def in_bytes(self) -> int:
        return sum(b for _n, b in self.in_sms)


def layout_order(in_bytes: int, out_bytes: int) -> int:
    """Where a slave's block goes in the logical image (lower first; ties in line order):
    inputs and outputs of one size, then more inputs, inputs only, outputs only, more
    outputs — the LOLA ENI's order."""
    if in_bytes and out_bytes:
        return 0 if in_bytes == out_bytes else 1 if in_bytes > out_bytes else 4
    return 2 if in_bytes else 3


def _place(found: list[_Found]) -> list[_Placed]:
    placed = []
    for f in found:
        sizes: dict[int, int] = {}
        for pdo in f.pdos:
            if pdo.sync_manager is not None:
                sizes[pdo.sync_manager] = sizes.get(pdo.sync_manager, 0) + pdo.bit_size
        outs: list[tuple[int, int]] = []
        ins: list[tuple[int, int]] = []
        for n, direction in _process_sms(f):
            nbytes = (sizes.get(n, 0) + 7) // 8
            if nbytes:
                (outs if direction is Direction.OUTPUT else ins).append((n, nbytes))
        placed.append(_Placed(f, outs, ins))
    cursor = 0
    for p in sorted(placed, key=lambda q: (layout_order(q.in_bytes, q.out_bytes), q.f.position)):
        p.offset = cursor
        cursor += max(p.in_bytes, p.out_bytes)
    return placed


def build_eni(found: list[_Found], opts: GenerateOptions, where: str) -> Eni:
    placed = _place(found)
    dc_slaves = [p for p in placed if p.f.assign_activate]
    reference = dc_slaves[0].f.position if dc_slaves else None
    slaves = tuple(_slave(p, opts, reference) for p in placed)
    lrw_bytes = sum(max(p.in_bytes, p.out_bytes) for p in placed)
    commands: list[CyclicCommand] = []
    if lrw_bytes:
        wkc = sum(
            wkc_increment(Command.LRW, read=bool(p.in_bytes), write=bool(p.out_bytes))
            for p in placed
        )
        commands.append(
            CyclicCommand(
                Command.LRW,
                lrw_bytes,
                wkc,
                logical_address=LOGICAL_BASE,
                input_offset_bytes=0,
                output_offset_bytes=0,
                states=("SAFEOP", "OP"),
                comment="process data: outputs and inputs share one logical area",
            )
        )
    n = len(placed)
    if reference is not None:
        commands.append(
            CyclicCommand(
                Command.ARMW,
                8,
                n,
                adp=(-(reference - 1)) & 0xFFFF,
                ado=Register.DC_SYSTEM_TIME,
                states=("PREOP", "SAFEOP", "OP"),
                comment="DC: distribute the reference clock's system time",
            )
        )
    commands.append(
        CyclicCommand(
            Command.BRD,
            2,
            n,
            adp=0,
            ado=Register.AL_STATUS,
            states=("PREOP", "SAFEOP", "OP"),
            comment="AL status of every slave",
        )
    )
    variables = _variables(placed)
    image = ProcessImage(
        max((p.offset + p.in_bytes for p in placed if p.in_bytes), default=0),
        max((p.offset + p.out_bytes for p in placed if p.out_bytes), default=0),
        variables,
    )
    name = f"lolacli eni generate on {where}" if where else "lolacli eni generate"
    return Eni(
        EniMaster(name=name, init_cmds=_master_init_cmds(bool(dc_slaves))),
        slaves,
        (Cyclic(opts.cycle_time_ns, (CyclicFrame(tuple(commands)),)),),
        image,
        source=where,
    )


def _variables(placed: list[_Placed]) -> tuple[Variable, ...]:
    """Every mapped entry (padding aside), named slave.PDO.entry, at its image bit."""
    out: list[Variable] = []
    for direction in (Direction.INPUT, Direction.OUTPUT):
        for p in sorted(placed, key=lambda q: q.offset):
            bit = p.offset * 8
            for n, nbytes in p.in_sms if direction is Direction.INPUT else p.out_sms:
                at = bit
                for pdo in (q for q in p.f.pdos if q.sync_manager == n):
                    for e in pdo.entries:
                        if e.index:
                            name = f"{p.f.name}.{pdo.name}.{e.name}"
                            out.append(Variable(name, direction, at, e.bit_size, e.data_type))
                        at += e.bit_size
                bit += 8 * nbytes
    return tuple(out)


def _cmd(
    transitions: tuple[str, ...],
    kind: int,
    adp: int,
    ado: int,
    data: bytes,
    comment: str,
    *,
    wkc: int | None = 1,
    validate: tuple[bytes, bytes, int] | None = None,
    timeout_ms: int | None = None,
) -> InitCmd:
    return InitCmd(
        transitions,
        kind,
        adp,
        ado,
        data,
        wkc,
        comment,
        validate_data=validate[0] if validate else None,
        validate_mask=validate[1] if validate else None,
        validate_timeout_ms=validate[2] if validate else None,
        timeout_ms=timeout_ms,
    )


def _master_init_cmds(dc: bool) -> tuple[InitCmd, ...]:
    ip = ("IP",)
    cmds = [
        _cmd(ip, Command.BRD, 0, Register.AL_STATUS, bytes(2), "count slaves (AL status)",
             wkc=None),
        _cmd(ip, Command.BWR, 0, Register.STATION_ADDRESS, bytes(2), "clear station addresses",
             wkc=None),
        _cmd(("IP", "PI", "SI", "OI"), Command.BWR, 0, fmmu_address(0), bytes(256), "clear FMMUs",
             wkc=None),
        _cmd(ip, Command.BWR, 0, sync_manager_address(0), bytes(256), "clear sync managers",
             wkc=None),
    ]  # fmt: skip
    if dc:
        cmds += [
            _cmd(ip, Command.BWR, 0, 0x0900, bytes(4), "latch DC receive times", wkc=None),
            _cmd(ip, Command.BWR, 0, 0x0910, bytes(32), "clear DC system time, offset and delay",
                 wkc=None),
            _cmd(ip, Command.BWR, 0, 0x0930, _U16.pack(0x1000), "reset DC speed counter",
                 wkc=None),
            _cmd(ip, Command.BWR, 0, 0x0934, bytes([0x00, 0x0C]), "DC filter depths", wkc=None),
            _cmd(ip, Command.BWR, 0, 0x0981, bytes(1), "clear DC activation", wkc=None),
        ]  # fmt: skip
    return tuple(cmds)


def _slave(p: _Placed, opts: GenerateOptions, reference: int | None) -> Slave:
    f = p.f
    s = f.station
    a = (-(f.position - 1)) & 0xFFFF
    mailbox = f.mailbox
    mbx_sms = _mailbox_sms(f, mailbox)
    process: list[tuple[int, SyncManager, str, int, str]] = []  # SM, register, kind, fmmu type
    for n, nbytes in p.out_sms:
        process.append((n, _sm_register(f, n, nbytes), "Outputs", 2, "outputs"))
    for n, nbytes in p.in_sms:
        process.append((n, _sm_register(f, n, nbytes), "Inputs", 1, "inputs"))
    sms = [*mbx_sms, *((n, reg, kind) for n, reg, kind, _t, _l in process)]
    fmmus: list[ConfiguredFmmu] = []
    for n, reg, _kind, fmmu_type, _label in sorted(process, key=lambda q: -q[3]):
        before = sum(
            b for m, b in (p.out_sms if fmmu_type == 2 else p.in_sms) if m < n
        )
        fmmus.append(
            ConfiguredFmmu(
                len(fmmus),
                Fmmu(
                    LOGICAL_BASE + p.offset + before,
                    reg.length_bytes,
                    physical_start=reg.physical_start,
                    type=fmmu_type,
                    activate=1,
                ),
            )
        )
    dc = None
    if f.assign_activate:
        dc = DistributedClock(
            cycle_time0_ns=opts.cycle_time_ns,
            cycle_time1_ns=0,
            shift_time_ns=0,
            assign_activate=f.assign_activate,
            reference_clock=f.position == reference,
        )
    if mailbox is not None:
        mailbox = Mailbox(
            mailbox.out_start,
            mailbox.out_length_bytes,
            mailbox.in_start,
            mailbox.in_length_bytes,
            mailbox.protocols,
            coe_init_cmds=_coe_init_cmds(f) if "CoE" in mailbox.protocols else (),
            poll_time_ms=20,
        )
    init_cmds = _slave_init_cmds(a, s, mbx_sms, process, fmmus, dc)
    outputs_bits = 8 * p.out_bytes
    inputs_bits = 8 * p.in_bytes
    return Slave(
        position=f.position,
        name=f.name,
        identity=f.identity,
        station_address=s,
        auto_inc_address=a,
        mailbox=mailbox,
        sync_managers=tuple(
            ConfiguredSyncManager(n, reg, kind) for n, reg, kind in sorted(sms, key=lambda q: q[0])
        ),
        fmmus=tuple(fmmus),
        pdos=tuple(
            sorted(f.pdos, key=lambda q: q.direction is Direction.INPUT)  # RxPDOs first
        ),
        init_cmds=init_cmds,
        dc=dc,
        inputs=(ProcessDataArea(p.offset * 8, inputs_bits),) if inputs_bits else (),
        outputs=(ProcessDataArea(p.offset * 8, outputs_bits),) if outputs_bits else (),
    )


def _sm_register(f: _Found, n: int, nbytes: int) -> SyncManager:
    sm = f.sync_managers[n].sync_manager
    return SyncManager(sm.physical_start, nbytes, sm.control, activate=1)


def _mailbox_sms(f: _Found, mailbox: Mailbox | None) -> list[tuple[int, SyncManager, str]]:
    if mailbox is None:
        return []
    control = {0: SM_CONTROL_MAILBOX_OUT, 1: SM_CONTROL_MAILBOX_IN}
    for n, sm in enumerate(f.sync_managers[:2]):
        if sm.type in (SmType.MAILBOX_OUT, SmType.MAILBOX_IN) and sm.sync_manager.control:
            control[n] = sm.sync_manager.control
    return [
        (0, SyncManager(mailbox.out_start, mailbox.out_length_bytes, control[0], activate=1),
         "MBoxOut"),
        (1, SyncManager(mailbox.in_start, mailbox.in_length_bytes, control[1], activate=1),
         "MBoxIn"),
    ]  # fmt: skip


def _coe_init_cmds(f: _Found) -> tuple[CoeInitCmd, ...]:
    """For PDOs from an ESI that supports PDO assignment: the mapping of the configurable
    PDOs and the assignment, written on PREOP → SAFEOP (from the slave itself there is
    nothing to write: the slave already has it)."""
    if f.source != "esi" or f.esi is None:
        return ()
    coe = f.esi[1].coe
    if coe is None or not coe.pdo_assign:
        return ()
    ps = ("PS",)
    cmds: list[CoeInitCmd] = []

    def write(index: int, sub: int, data: bytes, comment: str) -> None:
        cmds.append(CoeInitCmd(ps, index, sub, data, fixed=True, comment=comment, timeout_ms=3000))

    for n, _direction in _process_sms(f):
        write(0x1C10 + n, 0, b"\x00", f"clear 0x{0x1C10 + n:04X} (PDO assignment)")
    if coe.pdo_config:
        for pdo in f.pdos:
            if pdo.fixed:
                continue
            write(pdo.index, 0, b"\x00", f"clear PDO 0x{pdo.index:04X} mapping")
            for k, e in enumerate(pdo.entries, start=1):
                word = (e.index << 16) | (e.subindex << 8) | e.bit_size
                write(pdo.index, k, _U32.pack(word), f"map 0x{e.index:04X}:{e.subindex:02X}")
            write(pdo.index, 0, bytes([len(pdo.entries)]), f"PDO 0x{pdo.index:04X}: entries")
    for n, _direction in _process_sms(f):
        mine = [pdo for pdo in f.pdos if pdo.sync_manager == n]
        for k, pdo in enumerate(mine, start=1):
            write(0x1C10 + n, k, _U16.pack(pdo.index), f"assign PDO 0x{pdo.index:04X}")
        write(0x1C10 + n, 0, bytes([len(mine)]), f"0x{0x1C10 + n:04X}: {len(mine)} PDOs")
    return tuple(cmds)


def _slave_init_cmds(
    a: int,
    s: int,
    mbx_sms: list[tuple[int, SyncManager, str]],
    process: list[tuple[int, SyncManager, str, int, str]],
    fmmus: list[ConfiguredFmmu],
    dc: DistributedClock | None,
) -> tuple[InitCmd, ...]:
    ip, ps, so = ("IP",), ("PS",), ("SO",)
    al = Register.AL_CONTROL
    status = Register.AL_STATUS

    def check(t: tuple[str, ...], state: int, mask: bytes, ms: int, comment: str) -> InitCmd:
        return _cmd(t, Command.FPRD, s, status, bytes(2), comment,
                    validate=(_U16.pack(state), mask, ms))  # fmt: skip

    cmds = [
        _cmd(ip, Command.APWR, a, al, _U16.pack(0x0011), "request INIT (acknowledge errors)",
             timeout_ms=3000),
        _cmd(ip, Command.APRD, a, status, bytes(2), "check INIT",
             validate=(_U16.pack(AlState.INIT), _U16.pack(0x000F), 3000)),
        _cmd(ip, Command.APWR, a, Register.STATION_ADDRESS, _U16.pack(s), "set station address"),
        _cmd(ip, Command.FPWR, s, 0x0400, _U16.pack(2498), "watchdog divider 100 us"),
        _cmd(ip, Command.FPWR, s, 0x0420, _U16.pack(1000), "SM watchdog 100 ms"),
    ]  # fmt: skip
    for n, reg, kind in mbx_sms:
        label = "mailbox out" if kind == "MBoxOut" else "mailbox in"
        cmds.append(
            _cmd(ip, Command.FPWR, s, sync_manager_address(n), encode_sync_manager(reg),
                 f"SM{n} {label}")
        )  # fmt: skip
    cmds += [
        _cmd(ip, Command.FPWR, s, al, _U16.pack(AlState.PREOP), "request PREOP", timeout_ms=3000),
        check(ip, AlState.PREOP, _AL_MASK, 3000, "check PREOP"),
    ]
    for n, reg, _kind, _t, label in process:
        cmds.append(
            _cmd(ps, Command.FPWR, s, sync_manager_address(n), encode_sync_manager(reg),
                 f"SM{n} {label}")
        )  # fmt: skip
    for fm in fmmus:
        label = "outputs (write)" if fm.fmmu.type == 2 else "inputs (read)"
        cmds.append(
            _cmd(ps, Command.FPWR, s, fmmu_address(fm.index), encode_fmmu(fm.fmmu),
                 f"FMMU{fm.index} {label}")
        )  # fmt: skip
    if dc is not None and dc.assign_activate:
        cycle = dc.cycle_time0_ns or 0
        cmds += [
            _cmd(ps, Command.FPWR, s, 0x0980, bytes(2), "clear DC activation"),
            _cmd(ps, Command.FPWR, s, 0x09A0, struct.pack("<II", cycle, 0),
                 "SYNC0/SYNC1 cycle time"),
            _cmd(ps, Command.FPWR, s, 0x0990, bytes(8),
                 "SYNC start time (the master adds its local time)"),
            _cmd(ps, Command.FPWR, s, 0x0980, _U16.pack(dc.assign_activate),
                 f"DC activation (AssignActivate 0x{dc.assign_activate:04X})"),
        ]  # fmt: skip
    cmds += [
        _cmd(ps, Command.FPWR, s, al, _U16.pack(AlState.SAFEOP), "request SAFEOP",
             timeout_ms=10000),
        check(ps, AlState.SAFEOP, _AL_MASK, 10000, "check SAFEOP"),
        _cmd(so, Command.FPWR, s, al, _U16.pack(AlState.OP), "request OP", timeout_ms=10000),
        check(so, AlState.OP, _AL_MASK, 10000, "check OP"),
        _cmd(("OS",), Command.FPWR, s, al, _U16.pack(AlState.SAFEOP), "request SAFEOP", wkc=None,
             timeout_ms=200),
        _cmd(("OP", "SP"), Command.FPWR, s, al, _U16.pack(AlState.PREOP), "request PREOP",
             wkc=None, timeout_ms=200),
    ]  # fmt: skip
    back = ("OP", "SP", "OI", "SI")
    for fm in fmmus:
        cmds.append(
            _cmd(back, Command.FPWR, s, fmmu_address(fm.index), bytes(16), f"clear FMMU{fm.index}",
                 wkc=None)
        )  # fmt: skip
    if dc is not None and dc.assign_activate:
        cmds.append(_cmd(back, Command.FPWR, s, 0x0980, bytes(2), "clear DC activation", wkc=None))
    cmds.append(
        _cmd(("OI", "SI", "PI"), Command.FPWR, s, al, _U16.pack(AlState.INIT), "request INIT",
             wkc=None, timeout_ms=5000)
    )  # fmt: skip
    return tuple(cmds)


__all__ = [
    "DEFAULT_CYCLE_NS",
    "FIRST_STATION",
    "LOGICAL_BASE",
    "SCHEMA",
    "GenerateOptions",
    "Generated",
    "SlaveOrigin",
    "build_eni",
    "generate",
    "layout_order",
]
