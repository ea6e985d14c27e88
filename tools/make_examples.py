#!/usr/bin/env python3
"""Write lolacli's example ENIs (lolacli/eni_examples/*.xml) from a declarative description.

Run by hand after changing a description; the output is deterministic and committed:

    python tools/make_examples.py            # writes the files, prints the totals
    python tools/make_examples.py --check    # exits 1 if a committed file differs

Element structure follows ETG.2100 (EtherCAT Network Information) as the TwinCAT and acontis
exports in the corpus use it. Register layouts: sync managers and FMMUs as
:mod:`lolacli.wire.registers` encodes them (ETG.1000.4 Tables 56 and 59);

* DC: 0x0910 system time, 0x0920 offset, 0x0928 delay, 0x0980 cyclic unit control +
  activation (AssignActivate 0x0300 = SYNC0 + cyclic operation), 0x0990 start time,
  0x09A0 SYNC0 / 0x09A4 SYNC1 cycle time (ETG.1000.4 Table 61 / ESC datasheet section 2).

Process-data layout. "As input and output variables can share the same space in an EtherCAT
frame" (seed: LOLA, "B. Bus Performance"): a slave's read FMMU and write FMMU start at the same
logical address, so the LRW carries Σ max(inputs, outputs) bytes while the process image holds
Σ inputs + Σ outputs. The image is a window on the LRW data (InputOffs = OutputOffs = 0): a
variable's BitOffs equals its bit position in the LRW data, in both images. For both images to
be gap-free (ByteSize = Σ), the logical order puts slaves with equal inputs and outputs first,
then at most one slave with more inputs than outputs, then input-only slaves (then, if any,
output-only slaves, which leave a gap in the input image). Logical order may therefore differ
from chain order; the LOLA chain's GPIO terminal sits logically before the CAN gateway.
"""

from __future__ import annotations

import argparse
import struct
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from lolacli.wire.commands import wkc_increment  # noqa: E402
from lolacli.wire.registers import (  # noqa: E402
    Fmmu,
    FmmuType,
    SyncManager,
    encode_fmmu,
    encode_sync_manager,
    fmmu_address,
    sync_manager_address,
)

OUT_DIR = ROOT / "lolacli" / "eni_examples"

# EtherCAT command codes (ETG.1000.4 Table 16).
APRD, APWR, FPRD, FPWR, BRD, BWR, LRW, ARMW = 1, 2, 4, 5, 7, 8, 12, 13

# Frame arithmetic (DESIGN.md "Definitions").
ETH_HEADER, ECAT_HEADER, DATAGRAM_OVERHEAD, FCS, MIN_FRAME = 14, 2, 12, 4, 64

LOGICAL_BASE = 0x0001_0000  # logical address of the first process-data byte


# --------------------------------------------------------------------------- description


@dataclass(frozen=True)
class Entry:
    index: int
    subindex: int
    bits: int
    name: str
    data_type: str


@dataclass(frozen=True)
class Pdo:
    index: int
    name: str
    entries: tuple[Entry, ...]

    @property
    def bits(self) -> int:
        return sum(e.bits for e in self.entries)


@dataclass(frozen=True)
class SmSpec:
    index: int
    start: int
    control: int


@dataclass(frozen=True)
class DeviceClass:
    """One kind of slave: identity, mailbox, sync managers, PDOs, DC use."""

    kind: str
    vendor_id: int
    product_code: int
    revision: int
    physics: str
    rx_pdos: tuple[Pdo, ...] = ()  # outputs (master -> slave)
    tx_pdos: tuple[Pdo, ...] = ()  # inputs (slave -> master)
    mailbox: tuple[int, int, int, int] | None = None  # out start/len, in start/len
    sm_out: SmSpec | None = None
    sm_in: SmSpec | None = None
    dc_sync: bool = False  # uses SYNC0 (AssignActivate 0x0300)
    remap_pdos: bool = False  # write the PDO mapping objects over CoE
    coe_extra: tuple[tuple[int, int, bytes, str], ...] = ()

    @property
    def out_bytes(self) -> int:
        return (sum(p.bits for p in self.rx_pdos) + 7) // 8

    @property
    def in_bytes(self) -> int:
        return (sum(p.bits for p in self.tx_pdos) + 7) // 8


@dataclass(frozen=True)
class SlaveSpec:
    name: str
    device: DeviceClass
    serial: int = 0
    reference_clock: bool = False


@dataclass(frozen=True)
class ChainSpec:
    file_name: str
    title: str
    cycle_time_us: int
    slaves: tuple[SlaveSpec, ...]
    master_source_mac: str = "001b21000001"
    dc_distribution: bool = False  # ARMW 0x0910 in the cyclic frame
    expected: dict[str, float] = field(default_factory=dict)


def e(index: int, sub: int, bits: int, name: str, dtype: str) -> Entry:
    return Entry(index, sub, bits, name, dtype)


# ---- CiA 402 drive, Elmo-Gold-like (identity as in the corpus' rocos/kpierczy exports).
# 11 bytes each way: cyclic synchronous position with a velocity feed-forward.

DRIVE = DeviceClass(
    kind="drive",
    vendor_id=0x9A,
    product_code=0x30924,
    revision=0x10420,
    physics="YY",
    rx_pdos=(
        Pdo(
            0x1600,
            "Outputs",
            (
                e(0x6040, 0, 16, "Controlword", "UINT"),
                e(0x6060, 0, 8, "Modes of operation", "SINT"),
                e(0x607A, 0, 32, "Target position", "DINT"),
                e(0x60B1, 0, 32, "Velocity offset", "DINT"),
            ),
        ),
    ),
    tx_pdos=(
        Pdo(
            0x1A00,
            "Inputs",
            (
                e(0x6041, 0, 16, "Statusword", "UINT"),
                e(0x6061, 0, 8, "Modes of operation display", "SINT"),
                e(0x6064, 0, 32, "Position actual value", "DINT"),
                e(0x606C, 0, 32, "Velocity actual value", "DINT"),
            ),
        ),
    ),
    mailbox=(0x1800, 140, 0x1900, 140),
    sm_out=SmSpec(2, 0x1100, 0x64),
    sm_in=SmSpec(3, 0x1180, 0x20),
    dc_sync=True,
    remap_pdos=True,
    coe_extra=((0x6060, 0, bytes([8]), "modes of operation: cyclic synchronous position"),),
)


def _can_gateway() -> DeviceClass:
    """CAN gateway: decoded IMU and foot F/T sensor values plus a raw CAN receive queue."""
    status = Pdo(
        0x1A00,
        "Sensor status",
        tuple(
            e(0x6000, sub, 16, name, "UINT")
            for sub, name in enumerate(
                (
                    "IMU status",
                    "IMU counter",
                    "FTS left status",
                    "FTS left counter",
                    "FTS right status",
                    "FTS right counter",
                ),
                start=1,
            )
        ),
    )
    imu_names = ("Angular rate", "Acceleration")
    imu = Pdo(
        0x1A01,
        "IMU",
        tuple(
            e(0x6010, 1 + i, 32, f"{q} {axis}", "REAL")
            for i, (q, axis) in enumerate((q, a) for q in imu_names for a in "XYZ")
        )
        + tuple(e(0x6010, 7 + i, 32, n, "REAL") for i, n in enumerate(("Roll", "Pitch", "Yaw"))),
    )

    def fts(index: int, pdo: int, side: str) -> Pdo:
        names = [f"{q} {a}" for q in ("Force", "Torque") for a in "XYZ"]
        return Pdo(
            pdo, f"FTS {side}", tuple(e(index, 1 + i, 32, n, "REAL") for i, n in enumerate(names))
        )

    queue = Pdo(
        0x1A04,
        "CAN Rx queue",
        tuple(
            entry
            for k in range(1, 38)
            for entry in (
                e(0x6100 + k - 1, 1, 32, f"Message {k:02d} header", "UDINT"),
                e(0x6100 + k - 1, 2, 64, f"Message {k:02d} data", "ARRAY [0..7] OF BYTE"),
            )
        ),
    )
    tx = Pdo(
        0x1600,
        "CAN Tx",
        (
            e(0x7000, 1, 16, "Control", "UINT"),
            e(0x7000, 2, 16, "Message id", "UINT"),
            e(0x7000, 3, 8, "Message length", "USINT"),
            e(0x7000, 4, 8, "Message flags", "USINT"),
            e(0x7000, 5, 64, "Message data", "ARRAY [0..7] OF BYTE"),
        ),
    )
    return DeviceClass(
        kind="can-gateway",
        vendor_id=0xE000_0001,  # placeholder vendor: a made-up device, not a real product
        product_code=0x0000_0C01,
        revision=0x0001_0000,
        physics="YY",
        rx_pdos=(tx,),
        tx_pdos=(status, imu, fts(0x6020, 0x1A02, "left"), fts(0x6030, 0x1A03, "right"), queue),
        mailbox=(0x1000, 128, 0x1080, 128),
        sm_out=SmSpec(2, 0x1100, 0x64),
        sm_in=SmSpec(3, 0x1400, 0x20),
    )


CAN_GATEWAY = _can_gateway()

# ---- Beckhoff-like coupler and terminals (identities as in Beckhoff's ESI files).

EK1100 = DeviceClass("coupler", 0x2, 0x044C2C52, 0x00110000, "YYK")


def _bits(base: int, count: int, pdo_base: int, label: str, dtype: str) -> tuple[Pdo, ...]:
    return tuple(
        Pdo(pdo_base + k, f"Channel {k + 1}", (e(base + 16 * k, 1, 1, label, dtype),))
        for k in range(count)
    )


DIO_8_8 = DeviceClass(  # EL1859-like: 8 digital inputs + 8 digital outputs
    kind="dio",
    vendor_id=0x2,
    product_code=0x07433052,
    revision=0x00100000,
    physics="KK",
    rx_pdos=_bits(0x7080, 8, 0x1608, "Output", "BOOL"),
    tx_pdos=_bits(0x6000, 8, 0x1A00, "Input", "BOOL"),
    sm_out=SmSpec(0, 0x0F00, 0x44),
    sm_in=SmSpec(1, 0x1000, 0x00),
)

DI_8 = DeviceClass(  # EL1008-like: 8 digital inputs
    kind="di",
    vendor_id=0x2,
    product_code=0x03F03052,
    revision=0x00100000,
    physics="KK",
    tx_pdos=_bits(0x6000, 8, 0x1A00, "Input", "BOOL"),
    sm_in=SmSpec(0, 0x1000, 0x00),
)

DO_8 = DeviceClass(  # EL2008-like: 8 digital outputs
    kind="do",
    vendor_id=0x2,
    product_code=0x07D83052,
    revision=0x00100000,
    physics="KK",
    rx_pdos=_bits(0x7000, 8, 0x1600, "Output", "BOOL"),
    sm_out=SmSpec(0, 0x0F00, 0x44),
)

AI_2 = DeviceClass(  # EL3102-like: 2 analog inputs, status + value per channel
    kind="ai",
    vendor_id=0x2,
    product_code=0x0C1E3052,
    revision=0x00140000,
    physics="KK",
    tx_pdos=tuple(
        Pdo(
            0x1A00 + 2 * k,
            f"AI Standard Channel {k + 1}",
            (
                e(0x6000 + 16 * k, 1, 16, "Status", "UINT"),
                e(0x6000 + 16 * k, 0x11, 16, "Value", "INT"),
            ),
        )
        for k in range(2)
    ),
    mailbox=(0x1000, 128, 0x1080, 128),
    sm_in=SmSpec(3, 0x1180, 0x20),
)

LOLA_JOINTS = (
    "L Hip Yaw",
    "L Hip Roll",
    "L Hip Pitch",
    "L Knee",
    "L Ankle A",
    "L Ankle B",
    "L Toe",
    "R Hip Yaw",
    "R Hip Roll",
    "R Hip Pitch",
    "R Knee",
    "R Ankle A",
    "R Ankle B",
    "R Toe",
    "Pelvis Rotation",
    "L Shoulder Pitch",
    "L Shoulder Roll",
    "L Elbow",
    "R Shoulder Pitch",
    "R Shoulder Roll",
    "R Elbow",
)

LOLA = ChainSpec(
    file_name="lola.xml",
    title="LOLA humanoid: 21 joint drives, CAN gateway (IMU, 2 foot F/T), EK1100 GPIO",
    cycle_time_us=500,
    slaves=tuple(
        SlaveSpec(f"Joint{k + 1:02d} {joint}", DRIVE, serial=0x1000 + k + 1, reference_clock=k == 0)
        for k, joint in enumerate(LOLA_JOINTS)
    )
    + (
        SlaveSpec("CAN Gateway (IMU, FTS)", CAN_GATEWAY, serial=0x2001),
        SlaveSpec("GPIO Coupler", EK1100),
        SlaveSpec("GPIO 8DI 8DO", DIO_8_8),
        SlaveSpec("GPIO 2AI", AI_2),
    ),
    dc_distribution=True,
    expected={
        "slaves": 25,
        "variables": 294,
        "image_bytes": 1026,
        "frame_bytes": 846,
        "lrw_bytes": 780,
    },
)

SINGLE_DRIVE = ChainSpec(
    file_name="single_drive.xml",
    title="One CiA 402 drive, cyclic synchronous position, 1 ms",
    cycle_time_us=1000,
    slaves=(SlaveSpec("Drive", DRIVE, serial=0x1001, reference_clock=True),),
    master_source_mac="001b21000002",
)

EK1100_IO = ChainSpec(
    file_name="ek1100_io.xml",
    title="EK1100 coupler with 8 DI, 8 DO and 2 AI terminals, 1 ms",
    cycle_time_us=1000,
    slaves=(
        SlaveSpec("Coupler", EK1100),
        SlaveSpec("DI 8", DI_8),
        SlaveSpec("DO 8", DO_8),
        SlaveSpec("AI 2", AI_2),
    ),
    master_source_mac="001b21000003",
)

CHAINS = (LOLA, SINGLE_DRIVE, EK1100_IO)


# --------------------------------------------------------------------------- layout


@dataclass(frozen=True)
class Placed:
    """A slave with its chain position, addresses and logical offset (bytes from the base)."""

    spec: SlaveSpec
    position: int
    station: int
    auto_inc: int
    logical_offset: int

    @property
    def device(self) -> DeviceClass:
        return self.spec.device


def _logical_rank(d: DeviceClass) -> int:
    if d.in_bytes and d.out_bytes:
        return 0 if d.in_bytes == d.out_bytes else 1 if d.in_bytes > d.out_bytes else 4
    return 2 if d.in_bytes else 3


def place(chain: ChainSpec) -> list[Placed]:
    """Chain positions, station addresses 1001…, auto-increment addresses, logical offsets."""
    order = sorted(
        range(len(chain.slaves)), key=lambda i: (_logical_rank(chain.slaves[i].device), i)
    )
    offsets: dict[int, int] = {}
    cursor = 0
    for i in order:
        d = chain.slaves[i].device
        offsets[i] = cursor
        cursor += max(d.in_bytes, d.out_bytes)
    return [
        Placed(s, i + 1, 1001 + i, (-i) & 0xFFFF, offsets[i]) for i, s in enumerate(chain.slaves)
    ]


def lrw_bytes(placed: list[Placed]) -> int:
    return sum(max(p.device.in_bytes, p.device.out_bytes) for p in placed)


def image_bytes(placed: list[Placed], inputs: bool) -> int:
    ends = [
        p.logical_offset + (p.device.in_bytes if inputs else p.device.out_bytes)
        for p in placed
        if (p.device.in_bytes if inputs else p.device.out_bytes)
    ]
    return max(ends, default=0)


def lrw_wkc(placed: list[Placed]) -> int:
    """DESIGN.md "Expected WKC" of the LRW over every slave's inputs and outputs."""
    return sum(
        wkc_increment(LRW, read=bool(p.device.in_bytes), write=bool(p.device.out_bytes))
        for p in placed
    )


def frame_bytes(lengths: list[int]) -> int:
    total = ETH_HEADER + ECAT_HEADER + sum(DATAGRAM_OVERHEAD + n for n in lengths) + FCS
    return max(total, MIN_FRAME)


# --------------------------------------------------------------------------- XML helpers


def sub(parent: ET.Element, tag: str, text: object | None = None, **attrib: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = str(text)
    return el


def hexstr(data: bytes) -> str:
    return data.hex()


def u16(v: int) -> bytes:
    return struct.pack("<H", v & 0xFFFF)


def init_cmd(
    parent: ET.Element,
    transitions: tuple[str, ...],
    comment: str,
    cmd: int,
    adp: int,
    ado: int,
    data: bytes | None = None,
    *,
    length: int | None = None,
    cnt: int | None = None,
    validate: tuple[bytes, bytes, int] | None = None,
    timeout_ms: int | None = None,
    before_slave: bool = False,
    retries: int | None = None,
) -> None:
    el = sub(parent, "InitCmd")
    for t in transitions:
        sub(el, "Transition", t)
    if before_slave:
        sub(el, "BeforeSlave", "true")
    sub(el, "Comment", comment)
    sub(el, "Cmd", cmd)
    sub(el, "Adp", adp)
    sub(el, "Ado", ado)
    if data is not None:
        sub(el, "Data", hexstr(data))
    else:
        sub(el, "DataLength", length)
    if cnt is not None:
        sub(el, "Cnt", cnt)
    if retries is not None:
        sub(el, "Retries", retries)
    if validate is not None:
        v = sub(el, "Validate")
        sub(v, "Data", hexstr(validate[0]))
        sub(v, "DataMask", hexstr(validate[1]))
        sub(v, "Timeout", validate[2])
    if timeout_ms is not None:
        sub(el, "Timeout", timeout_ms)


# --------------------------------------------------------------------------- master


def write_master(config: ET.Element, chain: ChainSpec) -> None:
    master = sub(config, "Master")
    info = sub(master, "Info")
    sub(info, "Name", "lolacli master")
    sub(info, "Destination", "ffffffffffff")
    sub(info, "Source", chain.master_source_mac)
    sub(info, "EtherType", "a488")  # 0x88A4 as it appears on the wire, like the exports
    cmds = sub(master, "InitCmds")
    ip = ("IP",)
    init_cmd(cmds, ip, "count slaves (AL status)", BRD, 0, 0x0130, bytes(2), before_slave=True)
    init_cmd(cmds, ip, "clear station addresses", BWR, 0, 0x0010, bytes(2), before_slave=True)
    back = ("IP", "PI", "SI", "OI")
    init_cmd(cmds, back, "clear FMMUs", BWR, 0, fmmu_address(0), length=256, before_slave=True)
    init_cmd(
        cmds, ip, "clear sync managers", BWR, 0, sync_manager_address(0), length=256,
        before_slave=True,
    )
    if any(s.device.dc_sync for s in chain.slaves):
        init_cmd(cmds, ip, "latch DC receive times", BWR, 0, 0x0900, bytes(4), before_slave=True)
        init_cmd(
            cmds,
            ip,
            "clear DC system time, offset and delay",
            BWR,
            0,
            0x0910,
            length=32,
            before_slave=True,
        )
        init_cmd(cmds, ip, "reset DC speed counter", BWR, 0, 0x0930, u16(0x1000), before_slave=True)
        init_cmd(
            cmds, ip, "DC filter depths", BWR, 0, 0x0934, bytes([0x00, 0x0C]), before_slave=True
        )
        init_cmd(cmds, ip, "clear DC activation", BWR, 0, 0x0981, bytes(1), before_slave=True)


# --------------------------------------------------------------------------- slaves


def write_slave(config: ET.Element, chain: ChainSpec, p: Placed, prev: Placed | None) -> None:
    d = p.device
    slave = sub(config, "Slave")
    info = sub(slave, "Info")
    sub(info, "Name", p.spec.name)
    sub(info, "PhysAddr", p.station)
    sub(info, "AutoIncAddr", f"#x{p.auto_inc:04x}")
    sub(info, "Physics", d.physics)
    sub(info, "VendorId", f"#x{d.vendor_id:08x}")
    sub(info, "ProductCode", f"#x{d.product_code:08x}")
    sub(info, "RevisionNo", f"#x{d.revision:08x}")
    sub(info, "SerialNo", p.spec.serial)
    write_process_data(slave, p)
    if d.mailbox is not None:
        write_mailbox(slave, p)
    write_slave_init_cmds(slave, chain, p)
    if prev is not None:
        port = sub(slave, "PreviousPort", Selected="true")
        sub(port, "Port", "B")
        sub(port, "PhysAddr", prev.station)
    if d.dc_sync:
        dc = sub(slave, "DC")
        sub(dc, "PotentialReferenceClock", "true")
        sub(dc, "ReferenceClock", "true" if p.spec.reference_clock else "false")
        sub(dc, "CycleTime0", chain.cycle_time_us * 1000)
        sub(dc, "CycleTime1", 0)
        sub(dc, "ShiftTime", 0)
        sub(dc, "AssignActivate", "#x0300")


def write_process_data(slave: ET.Element, p: Placed) -> None:
    d = p.device
    pd = sub(slave, "ProcessData")
    bit_start = p.logical_offset * 8
    if d.out_bytes:
        send = sub(pd, "Send")
        sub(send, "BitStart", bit_start)
        sub(send, "BitLength", d.out_bytes * 8)
    if d.in_bytes:
        recv = sub(pd, "Recv")
        sub(recv, "BitStart", bit_start)
        sub(recv, "BitLength", d.in_bytes * 8)
    sms: list[tuple[int, ET.Element]] = []
    if d.mailbox is not None:
        out_start, out_len, in_start, in_len = d.mailbox
        for index, kind, start, length, control in (
            (0, "MBoxOut", out_start, out_len, 0x26),
            (1, "MBoxIn", in_start, in_len, 0x22),
        ):
            sms.append((index, _sm_element(kind, length, start, control, ())))
    if d.sm_out is not None:
        pdos = tuple(x.index for x in d.rx_pdos)
        sms.append(
            (
                d.sm_out.index,
                _sm_element("Outputs", d.out_bytes, d.sm_out.start, d.sm_out.control, pdos),
            )
        )
    if d.sm_in is not None:
        pdos = tuple(x.index for x in d.tx_pdos)
        sms.append(
            (d.sm_in.index, _sm_element("Inputs", d.in_bytes, d.sm_in.start, d.sm_in.control, pdos))
        )
    for index, el in sorted(sms, key=lambda t: t[0]):
        el.tag = f"Sm{index}"
        pd.append(el)
    for tag, pdos, sm in (("TxPdo", d.tx_pdos, d.sm_in), ("RxPdo", d.rx_pdos, d.sm_out)):
        for pdo in pdos:
            attrs = {"Fixed": "false" if d.remap_pdos else "true", "Mandatory": "true"}
            if sm is not None:
                attrs["Sm"] = str(sm.index)
            el = sub(pd, tag, **attrs)
            sub(el, "Index", f"#x{pdo.index:04x}")
            sub(el, "Name", pdo.name)
            for entry in pdo.entries:
                en = sub(el, "Entry")
                sub(en, "Index", f"#x{entry.index:04x}")
                sub(en, "SubIndex", entry.subindex)
                sub(en, "BitLen", entry.bits)
                sub(en, "Name", entry.name)
                sub(en, "DataType", entry.data_type)


def _sm_element(
    kind: str, size: int, start: int, control: int, pdos: tuple[int, ...]
) -> ET.Element:
    el = ET.Element("Sm")
    sub(el, "Type", kind)
    sub(el, "DefaultSize", size)
    sub(el, "StartAddress", f"#x{start:04x}")
    sub(el, "ControlByte", f"#x{control:02x}")
    sub(el, "Enable", "true")
    for index in pdos:
        sub(el, "Pdo", f"#x{index:04x}")
    return el


def write_mailbox(slave: ET.Element, p: Placed) -> None:
    d = p.device
    assert d.mailbox is not None
    out_start, out_len, in_start, in_len = d.mailbox
    mb = sub(slave, "Mailbox")
    send = sub(mb, "Send")
    sub(send, "Start", f"#x{out_start:04x}")
    sub(send, "Length", out_len)
    recv = sub(mb, "Recv")
    sub(recv, "Start", f"#x{in_start:04x}")
    sub(recv, "Length", in_len)
    sub(recv, "PollTime", 20)
    sub(mb, "Protocol", "CoE")
    coe = sub(mb, "CoE")
    cmds = sub(coe, "InitCmds")
    for index, subindex, data, comment in coe_init_cmds(d):
        el = sub(cmds, "InitCmd", Fixed="true")
        sub(el, "Transition", "PS")
        sub(el, "Comment", comment)
        sub(el, "Timeout", 3000)
        sub(el, "Ccs", 1)  # SDO initiate download request (CiA 301 §7.2.4.3.3)
        sub(el, "Index", f"#x{index:04x}")
        sub(el, "SubIndex", subindex)
        sub(el, "Data", hexstr(data))
    if d.kind == "drive":
        profile = sub(coe, "Profile")
        channel = sub(profile, "ChannelInfo")
        sub(channel, "ProfileNo", 402)


def coe_init_cmds(d: DeviceClass) -> list[tuple[int, int, bytes, str]]:
    """PS-transition SDO downloads: PDO mapping (if remapped), PDO assignment, extras."""
    cmds: list[tuple[int, int, bytes, str]] = []
    assigns = [(0x1C12, d.rx_pdos), (0x1C13, d.tx_pdos)]
    for sm_obj, pdos in assigns:
        if pdos:
            cmds.append((sm_obj, 0, bytes(1), f"clear 0x{sm_obj:04X} (PDO assignment)"))
    if d.remap_pdos:
        for pdo in d.rx_pdos + d.tx_pdos:
            cmds.append((pdo.index, 0, bytes(1), f"clear PDO 0x{pdo.index:04X} mapping"))
            for k, entry in enumerate(pdo.entries, start=1):
                value = (entry.index << 16) | (entry.subindex << 8) | entry.bits
                cmds.append(
                    (
                        pdo.index,
                        k,
                        struct.pack("<I", value),
                        f"map 0x{entry.index:04X}:{entry.subindex:02X} {entry.name}",
                    )
                )
            cmds.append(
                (
                    pdo.index,
                    0,
                    bytes([len(pdo.entries)]),
                    f"PDO 0x{pdo.index:04X}: {len(pdo.entries)} entries",
                )
            )
    for sm_obj, pdos in assigns:
        for k, pdo in enumerate(pdos, start=1):
            cmds.append((sm_obj, k, u16(pdo.index), f"assign PDO 0x{pdo.index:04X}"))
        if pdos:
            cmds.append((sm_obj, 0, bytes([len(pdos)]), f"0x{sm_obj:04X}: {len(pdos)} PDOs"))
    cmds.extend(d.coe_extra)
    if d.dc_sync:
        cmds.append((0x60C2, 1, bytes([5]), "interpolation period: 5 x 10^-4 s"))
        cmds.append((0x60C2, 2, bytes([0xFC]), "interpolation period exponent: -4"))
    return cmds


def write_slave_init_cmds(slave: ET.Element, chain: ChainSpec, p: Placed) -> None:
    d = p.device
    a, s = p.auto_inc, p.station
    cmds = sub(slave, "InitCmds")
    al_mask = u16(0x001F)  # state bits + error indication
    init_cmd(
        cmds,
        ("IP",),
        "request INIT (acknowledge errors)",
        APWR,
        a,
        0x0120,
        u16(0x0011),
        cnt=1,
        timeout_ms=3000,
    )
    init_cmd(
        cmds,
        ("IP",),
        "check INIT",
        APRD,
        a,
        0x0130,
        bytes(2),
        cnt=1,
        validate=(u16(0x0001), u16(0x000F), 3000),
    )
    init_cmd(cmds, ("IP",), "set station address", APWR, a, 0x0010, u16(s), cnt=1)
    init_cmd(cmds, ("IP",), "watchdog divider 100 us", FPWR, s, 0x0400, u16(2498), cnt=1)
    init_cmd(cmds, ("IP",), "SM watchdog 100 ms", FPWR, s, 0x0420, u16(1000), cnt=1)
    if d.mailbox is not None:
        out_start, out_len, in_start, in_len = d.mailbox
        init_cmd(
            cmds,
            ("IP",),
            "SM0 mailbox out",
            FPWR,
            s,
            sync_manager_address(0),
            encode_sync_manager(SyncManager(out_start, out_len, 0x26, activate=1)),
            cnt=1,
        )
        init_cmd(
            cmds,
            ("IP",),
            "SM1 mailbox in",
            FPWR,
            s,
            sync_manager_address(1),
            encode_sync_manager(SyncManager(in_start, in_len, 0x22, activate=1)),
            cnt=1,
        )
    init_cmd(cmds, ("IP",), "request PREOP", FPWR, s, 0x0120, u16(0x0002), cnt=1, timeout_ms=3000)
    init_cmd(
        cmds,
        ("IP",),
        "check PREOP",
        FPRD,
        s,
        0x0130,
        bytes(2),
        cnt=1,
        validate=(u16(0x0002), al_mask, 3000),
    )
    for sm, size, label in ((d.sm_out, d.out_bytes, "outputs"), (d.sm_in, d.in_bytes, "inputs")):
        if sm is not None:
            data = encode_sync_manager(SyncManager(sm.start, size, sm.control, activate=1))
            init_cmd(
                cmds, ("PS",), f"SM{sm.index} {label}", FPWR, s,
                sync_manager_address(sm.index), data, cnt=1,
            )
    for n, (kind, sm, size) in enumerate(_fmmus(d)):
        fmmu = Fmmu(LOGICAL_BASE + p.logical_offset, size, physical_start=sm.start, type=kind,
                    activate=1)
        data = encode_fmmu(fmmu)
        label = "outputs (write)" if kind == FmmuType.WRITE else "inputs (read)"
        init_cmd(cmds, ("PS",), f"FMMU{n} {label}", FPWR, s, fmmu_address(n), data, cnt=1)
    if d.dc_sync:
        cycle_ns = chain.cycle_time_us * 1000
        init_cmd(cmds, ("PS",), "clear DC activation", FPWR, s, 0x0980, bytes(2), cnt=1)
        init_cmd(
            cmds,
            ("PS",),
            "SYNC0/SYNC1 cycle time",
            FPWR,
            s,
            0x09A0,
            struct.pack("<II", cycle_ns, 0),
            cnt=1,
        )
        init_cmd(
            cmds,
            ("PS",),
            "SYNC start time (the master adds its local time)",
            FPWR,
            s,
            0x0990,
            bytes(8),
            cnt=1,
        )
        init_cmd(
            cmds,
            ("PS",),
            "DC activation (AssignActivate 0x0300)",
            FPWR,
            s,
            0x0980,
            u16(0x0300),
            cnt=1,
        )
    init_cmd(cmds, ("PS",), "request SAFEOP", FPWR, s, 0x0120, u16(0x0004), cnt=1, timeout_ms=10000)
    init_cmd(
        cmds,
        ("PS",),
        "check SAFEOP",
        FPRD,
        s,
        0x0130,
        bytes(2),
        cnt=1,
        validate=(u16(0x0004), al_mask, 10000),
    )
    init_cmd(cmds, ("SO",), "request OP", FPWR, s, 0x0120, u16(0x0008), cnt=1, timeout_ms=10000)
    init_cmd(
        cmds,
        ("SO",),
        "check OP",
        FPRD,
        s,
        0x0130,
        bytes(2),
        cnt=1,
        validate=(u16(0x0008), al_mask, 10000),
    )
    init_cmd(cmds, ("OS",), "request SAFEOP", FPWR, s, 0x0120, u16(0x0004), timeout_ms=200)
    init_cmd(cmds, ("OP", "SP"), "request PREOP", FPWR, s, 0x0120, u16(0x0002), timeout_ms=200)
    for n, _ in enumerate(_fmmus(d)):
        init_cmd(
            cmds, ("OP", "SP", "OI", "SI"), f"clear FMMU{n}", FPWR, s, fmmu_address(n), bytes(16)
        )
    if d.dc_sync:
        init_cmd(cmds, ("OP", "SP", "OI", "SI"), "clear DC activation", FPWR, s, 0x0980, bytes(2))
    init_cmd(
        cmds, ("OI", "SI", "PI"), "request INIT", FPWR, s, 0x0120, u16(0x0001), timeout_ms=5000
    )


def _fmmus(d: DeviceClass) -> list[tuple[int, SmSpec, int]]:
    """(type, sync manager, length): FMMU0 outputs then FMMU1 inputs, as TwinCAT orders them."""
    out: list[tuple[int, SmSpec, int]] = []
    if d.sm_out is not None and d.out_bytes:
        out.append((FmmuType.WRITE, d.sm_out, d.out_bytes))
    if d.sm_in is not None and d.in_bytes:
        out.append((FmmuType.READ, d.sm_in, d.in_bytes))
    return out


# --------------------------------------------------------------------------- cyclic + image


def cyclic_commands(chain: ChainSpec, placed: list[Placed]) -> list[dict[str, object]]:
    """The commands of the one cyclic frame, in frame order."""
    n = len(placed)
    cmds: list[dict[str, object]] = [
        {
            "comment": "process data: outputs and inputs share one logical area",
            "states": ("SAFEOP", "OP"),
            "cmd": LRW,
            "addr": LOGICAL_BASE,
            "length": lrw_bytes(placed),
            "cnt": lrw_wkc(placed),
            "offs": 0,
        }
    ]
    if chain.dc_distribution:
        ref = next(p for p in placed if p.spec.reference_clock)
        cmds.append(
            {
                "comment": "DC: distribute the reference clock's system time (ARMW 0x0910)",
                "states": ("PREOP", "SAFEOP", "OP"),
                "cmd": ARMW,
                "adp": ref.auto_inc,
                "ado": 0x0910,
                "length": 8,
                "cnt": n,
            }
        )
    cmds.append(
        {
            "comment": "AL status of every slave",
            "states": ("PREOP", "SAFEOP", "OP"),
            "cmd": BRD,
            "adp": 0,
            "ado": 0x0130,
            "length": 2,
            "cnt": n,
        }
    )
    return cmds


def write_cyclic(config: ET.Element, chain: ChainSpec, placed: list[Placed]) -> int:
    cyclic = sub(config, "Cyclic")
    sub(cyclic, "Comment", chain.title)
    sub(cyclic, "CycleTime", chain.cycle_time_us)
    frame = sub(cyclic, "Frame")
    lengths = []
    for c in cyclic_commands(chain, placed):
        el = sub(frame, "Cmd")
        for state in c["states"]:  # type: ignore[attr-defined]
            sub(el, "State", state)
        sub(el, "Comment", c["comment"])
        sub(el, "Cmd", c["cmd"])
        if "addr" in c:
            sub(el, "Addr", f"#x{c['addr']:08x}")
        else:
            sub(el, "Adp", c["adp"])
            sub(el, "Ado", f"#x{c['ado']:04x}")
        sub(el, "DataLength", c["length"])
        sub(el, "Cnt", c["cnt"])
        if "offs" in c:
            sub(el, "InputOffs", c["offs"])
            sub(el, "OutputOffs", c["offs"])
        lengths.append(int(c["length"]))  # type: ignore[call-overload]
    return frame_bytes(lengths)


def image_variables(placed: list[Placed], inputs: bool) -> list[tuple[str, str, int, int]]:
    """(name, data type, bit size, bit offset) in image order; padding entries are skipped."""
    rows = []
    for p in sorted(placed, key=lambda q: q.logical_offset):
        pdos = p.device.tx_pdos if inputs else p.device.rx_pdos
        bit = p.logical_offset * 8
        for pdo in pdos:
            for entry in pdo.entries:
                if entry.index:
                    name = f"{p.spec.name}.{pdo.name}.{entry.name}"
                    rows.append((name, entry.data_type, entry.bits, bit))
                bit += entry.bits
    return rows


def write_process_image(config: ET.Element, placed: list[Placed]) -> tuple[int, int, int]:
    image = sub(config, "ProcessImage")
    sizes = []
    count = 0
    for tag, inputs in (("Inputs", True), ("Outputs", False)):
        part = sub(image, tag)
        size = image_bytes(placed, inputs)
        sizes.append(size)
        sub(part, "ByteSize", size)
        for name, dtype, bits, offs in image_variables(placed, inputs):
            var = sub(part, "Variable")
            sub(var, "Name", name)
            sub(var, "DataType", dtype)
            sub(var, "BitSize", bits)
            sub(var, "BitOffs", offs)
            count += 1
    return sizes[0], sizes[1], count


# --------------------------------------------------------------------------- document


def build(chain: ChainSpec) -> tuple[bytes, dict[str, float]]:
    placed = place(chain)
    root = ET.Element(
        "EtherCATConfig",
        {
            "xmlns:xsi": "http://www.w3.org/2001/XMLSchema-instance",
            "xsi:noNamespaceSchemaLocation": "EtherCATConfig.xsd",
            "Version": "1.3",
        },
    )
    root.append(ET.Comment(f" {chain.title}. Written by tools/make_examples.py (lolacli). "))
    config = sub(root, "Config")
    write_master(config, chain)
    for i, p in enumerate(placed):
        write_slave(config, chain, p, placed[i - 1] if i else None)
    fbytes = write_cyclic(config, chain, placed)
    in_bytes, out_bytes, variables = write_process_image(config, placed)
    ET.indent(root, space="\t")
    text = ET.tostring(root, encoding="unicode")
    data = ('<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n").encode()
    totals = {
        "slaves": len(placed),
        "variables": variables,
        "inputs_bytes": in_bytes,
        "outputs_bytes": out_bytes,
        "image_bytes": in_bytes + out_bytes,
        "lrw_bytes": lrw_bytes(placed),
        "lrw_wkc": lrw_wkc(placed),
        "frame_bytes": fbytes,
        "wire_time_us": fbytes * 8 / 100,
    }
    return data, totals


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    parser.add_argument("--out", type=Path, default=OUT_DIR)
    args = parser.parse_args(argv)
    status = 0
    for chain in CHAINS:
        data, totals = build(chain)
        for key, want in chain.expected.items():
            if totals[key] != want:
                print(f"{chain.file_name}: {key} = {totals[key]}, expected {want}", file=sys.stderr)
                status = 1
        path = args.out / chain.file_name
        summary = ", ".join(f"{k}={v:g}" for k, v in totals.items())
        if args.check:
            same = path.exists() and path.read_bytes() == data
            print(f"{path.name}: {'up to date' if same else 'DIFFERS'}; {summary}")
            status |= 0 if same else 1
        else:
            path.write_bytes(data)
            print(f"{path.name}: {len(data)} bytes; {summary}")
    return status


if __name__ == "__main__":
    sys.exit(main())
