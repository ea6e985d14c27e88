"""The ENI model: frozen dataclasses for an EtherCAT Network Information file (ETG.2100).

One vocabulary with the file: ``<Slave>`` is :class:`Slave`, ``<Cyclic>/<Frame>/<Cmd>`` is
:class:`CyclicFrame`/:class:`CyclicCommand`, ``<ProcessImage>/<Inputs>/<Variable>`` is
:class:`Variable`. Times are integer nanoseconds, sizes carry their unit in the name.
Addresses are plain ints. Other layers (timing, capture, emulator, master) read this
model, never the XML.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

from lolacli.wire import registers


class Direction(StrEnum):
    """Process-data direction, seen from the master."""

    INPUT = "input"  # slave -> master (TxPDO)
    OUTPUT = "output"  # master -> slave (RxPDO)


@dataclass(frozen=True, slots=True)
class Identity:
    vendor_id: int
    product_code: int
    revision: int
    serial: int = 0


@dataclass(frozen=True, slots=True)
class PdoEntry:
    index: int
    subindex: int
    bit_size: int
    name: str = ""
    data_type: str = ""


@dataclass(frozen=True, slots=True)
class Pdo:
    """An RxPDO (``direction`` OUTPUT) or TxPDO (INPUT) with its entries."""

    index: int
    name: str
    direction: Direction
    sync_manager: int | None
    entries: tuple[PdoEntry, ...] = ()
    fixed: bool = False
    mandatory: bool = False

    @property
    def bit_size(self) -> int:
        return sum(e.bit_size for e in self.entries)


@dataclass(frozen=True, slots=True)
class ConfiguredSyncManager:
    """A sync manager as the ENI configures it: which one (``index``), its register content
    (written to 0x0800 + 8·n by an InitCmd, or as ``<Sm>`` of the slave's ``<ProcessData>`` /
    ``<Mailbox>`` says) and, where the ENI names it, its ``kind``."""

    index: int
    sync_manager: registers.SyncManager
    kind: str = ""  # "MBoxOut", "MBoxIn", "Outputs", "Inputs" where the ENI says


@dataclass(frozen=True, slots=True)
class ConfiguredFmmu:
    """An FMMU as the ENI configures it: which one (``index``) and its register content
    (0x0600 + 16·n, ETG.1000.4 Table 56)."""

    index: int
    fmmu: registers.Fmmu


@dataclass(frozen=True, slots=True)
class InitCmd:
    """One ``<InitCmd>``: a datagram the master sends on a state transition."""

    transitions: tuple[str, ...]  # e.g. ("IP", "PS")
    cmd: int
    adp: int
    ado: int
    data: bytes
    expected_wkc: int | None
    comment: str = ""
    requires: str = ""  # "cycle", "frame" or ""
    retries: int = 0
    validate_data: bytes | None = None
    validate_mask: bytes | None = None
    validate_timeout_ms: int | None = None
    logical_address: int | None = None  # set instead of adp/ado for logical commands
    timeout_ms: int | None = None  # <Timeout> of the InitCmd itself


@dataclass(frozen=True, slots=True)
class CoeInitCmd:
    """One CoE ``<InitCmd>`` of a slave's mailbox: an SDO download/upload on a transition."""

    transitions: tuple[str, ...]
    index: int
    subindex: int
    data: bytes
    complete_access: bool = False
    fixed: bool = False
    comment: str = ""
    ccs: int = 1  # SDO initiate request (CiA 301): 1 download (write), 2 upload (read)
    timeout_ms: int | None = None


@dataclass(frozen=True, slots=True)
class Mailbox:
    out_start: int
    out_length_bytes: int
    in_start: int
    in_length_bytes: int
    protocols: tuple[str, ...] = ()  # "CoE", "EoE", "FoE", "SoE", "AoE", "VoE"
    coe_init_cmds: tuple[CoeInitCmd, ...] = ()
    poll_time_ms: int | None = None
    status_bit_address: int | None = None  # logical bit of the mailbox-state LRD, if any


@dataclass(frozen=True, slots=True)
class DistributedClock:
    cycle_time0_ns: int | None = None
    cycle_time1_ns: int | None = None
    shift_time_ns: int | None = None
    assign_activate: int | None = None
    reference_clock: bool = False


@dataclass(frozen=True, slots=True)
class ProcessDataArea:
    """Where a slave's inputs (``<Recv>``) or outputs (``<Send>``) sit in the image."""

    bit_start: int
    bit_length: int


@dataclass(frozen=True, slots=True)
class Slave:
    position: int  # 1-based, chain order
    name: str
    identity: Identity
    station_address: int
    auto_inc_address: int
    previous_port: str | None = None
    previous_station_address: int | None = None
    mailbox: Mailbox | None = None
    sync_managers: tuple[ConfiguredSyncManager, ...] = ()
    fmmus: tuple[ConfiguredFmmu, ...] = ()
    pdos: tuple[Pdo, ...] = ()
    init_cmds: tuple[InitCmd, ...] = ()
    dc: DistributedClock | None = None
    inputs: tuple[ProcessDataArea, ...] = ()  # <ProcessData><Recv>
    outputs: tuple[ProcessDataArea, ...] = ()  # <ProcessData><Send>
    #: <Info><Physics>: one letter per port A, B, C, D (Y 100BASE-TX, K E-bus, F
    #: 100BASE-FX, blank none); "" when the ENI does not say
    physics: str = ""

    @property
    def inputs_bits(self) -> int:
        return sum(a.bit_length for a in self.inputs)

    @property
    def outputs_bits(self) -> int:
        return sum(a.bit_length for a in self.outputs)


@dataclass(frozen=True, slots=True)
class CyclicCommand:
    """One ``<Cmd>`` of a cyclic ``<Frame>``."""

    cmd: int
    data_length_bytes: int
    expected_wkc: int | None  # <Cnt>
    adp: int | None = None
    ado: int | None = None
    logical_address: int | None = None
    input_offset_bytes: int | None = None  # <InputOffs>
    output_offset_bytes: int | None = None  # <OutputOffs>
    states: tuple[str, ...] = ()  # <State> elements (e.g. "SAFEOP", "OP")
    comment: str = ""


@dataclass(frozen=True, slots=True)
class CyclicFrame:
    commands: tuple[CyclicCommand, ...]
    comment: str = ""
    cycle_time_factor: int | None = None  # <Frame CycleTimeFactor=…> (Elmo Application Studio)

    @property
    def frame_bytes(self) -> int:
        from lolacli.wire.frame import frame_bytes_on_wire

        return frame_bytes_on_wire([c.data_length_bytes for c in self.commands])


@dataclass(frozen=True, slots=True)
class Cyclic:
    """One ``<Cyclic>`` task: its cycle time (``None`` when the file gives none) and frames."""

    cycle_time_ns: int | None
    frames: tuple[CyclicFrame, ...]
    comment: str = ""
    cycle_time_factor: int | None = None  # Elmo Application Studio exports


@dataclass(frozen=True, slots=True)
class Variable:
    """A process-image variable (``<ProcessImage>/<Inputs|Outputs>/<Variable>``)."""

    name: str
    direction: Direction
    bit_offset: int
    bit_size: int
    data_type: str = ""
    comment: str = ""


@dataclass(frozen=True, slots=True)
class ProcessImage:
    inputs_bytes: int
    outputs_bytes: int
    variables: tuple[Variable, ...] = ()


@dataclass(frozen=True, slots=True)
class Master:
    name: str = ""
    destination_mac: bytes = b"\xff" * 6
    source_mac: bytes = b"\x00" * 6
    ethertype: int = 0x88A4
    init_cmds: tuple[InitCmd, ...] = ()
    cycle_time_ns: int | None = None  # <Master><CycleTime> (Elmo Application Studio exports)


@dataclass(frozen=True, slots=True)
class Eni:
    """A whole ENI: master, slaves in chain order, cyclic tasks and the process image."""

    master: Master
    slaves: tuple[Slave, ...]
    cyclic: tuple[Cyclic, ...]
    process_image: ProcessImage
    root: str = "EtherCATConfig"  # or "EncryptedEtherCATConfig" (plain body)
    source: str = ""  # file name or "<string>", for messages

    @property
    def cycle_time_ns(self) -> int | None:
        for task in self.cyclic:
            if task.cycle_time_ns is not None:
                return task.cycle_time_ns
        return None

    @property
    def cyclic_frames(self) -> tuple[CyclicFrame, ...]:
        return tuple(f for task in self.cyclic for f in task.frames)


__all__ = [
    "CoeInitCmd",
    "ConfiguredFmmu",
    "ConfiguredSyncManager",
    "Cyclic",
    "CyclicCommand",
    "CyclicFrame",
    "Direction",
    "DistributedClock",
    "Eni",
    "Identity",
    "InitCmd",
    "Mailbox",
    "Master",
    "Pdo",
    "PdoEntry",
    "ProcessDataArea",
    "ProcessImage",
    "Slave",
    "Variable",
    "field",
]
