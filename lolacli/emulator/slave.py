"""An emulated slave: ESC + device + mailbox protocols, and a chain built from an ENI.

:func:`build_chain` is the one call that turns an ENI model into a running line of
slaves: for each ENI slave an SII image (:mod:`lolacli.emulator.sii`), a device model
(:func:`lolacli.devices.device_for`) and, for mailbox slaves, the protocols behind the
mailbox (:mod:`lolacli.emulator.mailbox`): an SDO server (CoE) in PREOP and above and a
bootloader's file access (FoE) in BOOT, with the slave's files kept in its own store.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import replace

from lolacli.devices import device_for
from lolacli.devices.base import ASSIGN_RX, ASSIGN_TX, MAPPING_RX, MAPPING_TX, Device
from lolacli.emulator.chain import Chain, ChainTiming, Faults
from lolacli.emulator.esc import DcClock, Esc
from lolacli.emulator.mailbox import MailboxDispatcher
from lolacli.emulator.mailbox.coe import CoeHandler
from lolacli.emulator.mailbox.foe import FileStore, FoeServer
from lolacli.emulator.mailbox.sdo_server import SdoServer
from lolacli.emulator.registers import AlState
from lolacli.emulator.sii import sii_from_slave
from lolacli.eni.model import CoeInitCmd, Direction, Eni, Pdo, PdoEntry, Slave

ASSIGN_OBJECTS = {Direction.OUTPUT: ASSIGN_RX, Direction.INPUT: ASSIGN_TX}
DEFAULT_PDO = {Direction.OUTPUT: MAPPING_RX, Direction.INPUT: MAPPING_TX}
FILLER_OBJECT = {Direction.OUTPUT: 0x5FFE, Direction.INPUT: 0x5FFF}
_FILLER_TYPES = ((32, "UDINT"), (16, "UINT"), (8, "USINT"))
#: larger areas start with 64-bit entries: in 32-bit ones, 0xFFFF bytes (what an FMMU maps)
#: would take more entries than the SII's PDO category (65535 words, 8 bytes an entry) holds
_WIDE_FILLER_TYPES = ((64, "ULINT"), *_FILLER_TYPES)
_WIDE_FILLER_ABOVE_BITS = 0x8000 * 8
ENTRIES_PER_PDO = 8
#: entries one PDO mapping (and one filler object) holds: sub-indexes 1..254
MAX_PDO_ENTRIES = 254


class SlaveApplication:
    """The PDI side of one ESC: a device and the protocols of its mailbox, CoE (its SDO
    server, ``sdo``) and FoE (``foe``, over the slave's ``files``); implements
    EscApplication. ``foe_password`` is the password FoE transfers need."""

    def __init__(self, device: Device, mailbox_in_bytes: int, *, foe_password: int = 0) -> None:
        self.device = device
        self.has_coe = mailbox_in_bytes > 0
        self._coe = CoeHandler(SdoServer(device.od, mailbox_in_bytes) if self.has_coe else None)
        self.files = FileStore()
        self.foe = FoeServer(self.files, password=foe_password) if self.has_coe else None
        self.mailbox = MailboxDispatcher()
        if self.has_coe:
            self.mailbox.register(self._coe)
        if self.foe is not None:
            self.mailbox.register(self.foe)
        # called before Python uses the device: the chain's C core, which may hold the
        # device's state between cycles, gives it back (lolacli.emulator.core)
        self.before_use: Callable[[], None] | None = None

    @property
    def sdo(self) -> SdoServer | None:
        """The SDO server behind CoE (None: requests are taken and never answered)."""
        return self._coe.server

    @sdo.setter
    def sdo(self, server: SdoServer | None) -> None:
        self._coe.server = server

    def mailbox_request(self, request: bytes, read_bytes: int) -> list[bytes]:
        if self.before_use is not None:
            self.before_use()
        return self.mailbox.handle(request, read_bytes)

    def mailbox_posted(self, message: bytes) -> bytes:
        """An emergency (or any message posted unasked) with the slave's next counter."""
        return self.mailbox.numbered(message)

    def process_data_bytes(self) -> tuple[int, int]:
        return self.device.process_data_bytes()

    def state_changed(self, state: AlState) -> None:
        if self.before_use is not None:
            self.before_use()
        self.device.od.al_state = int(state)  # SDO access rights follow the AL state
        self.device.state_changed(int(state))
        self.mailbox.state_changed(int(state))

    def cycle(self, outputs: bytes, t_ns: int) -> bytes:
        if self.before_use is not None:
            self.before_use()
        return self.device.cycle(outputs, t_ns)


def build_slave(
    slave: Slave, *, drift_ppb: int = 0, start_ns: int = 0, foe_password: int = 0
) -> Esc:
    """The ESC of one ENI slave with its device behind it."""
    slave = with_process_data_pdos(slave)
    sii = sii_from_slave(slave, complete_access=True)  # real CiA 402 drives offer it
    device = device_for(slave)
    mailbox_in = slave.mailbox.in_length_bytes if slave.mailbox is not None else 0
    app = SlaveApplication(device, mailbox_in, foe_password=foe_password)
    device.od.al_state = int(AlState.INIT)
    return Esc(sii, app=app, clock=DcClock(start_ns=start_ns, drift_ppb=drift_ppb))


def build_chain(
    eni: Eni,
    *,
    timing: ChainTiming | None = None,
    faults: Faults | None = None,
    drift_ppb: int = 0,
    engine: str | None = None,
    foe_password: int = 0,
) -> Chain:
    """All slaves of ``eni`` in line order. ``drift_ppb`` spreads clock rates along the
    line (slave i runs ``i × drift_ppb`` fast) so DC has something to correct; ``engine``
    as :func:`~lolacli.emulator.chain.chain_engine` takes it; ``foe_password`` is the
    password of every slave's FoE files."""
    slaves = [
        build_slave(s, drift_ppb=i * drift_ppb, start_ns=i * 1_234_567, foe_password=foe_password)
        for i, s in enumerate(eni.slaves)
    ]
    return Chain(slaves, timing=timing, faults=faults, engine=engine)


def device_of(esc: Esc) -> Device | None:
    app = esc.app
    return app.device if isinstance(app, SlaveApplication) else None


def with_process_data_pdos(slave: Slave) -> Slave:
    """The slave with PDOs for process data its ENI gives only as sizes.

    An ENI may describe a slave's process image without its PDOs (``<ProcessData>`` with
    ``<Send>``/``<Recv>`` bit lengths, the PDOs assigned by CoE InitCmds writing
    0x1C12/0x1C13). A master that maps from the slave must still find that many bytes:
    the PDOs the InitCmds assign (else 0x1600/0x1A00), the first ones filled with
    unsigned entries of a manufacturer-specific object 0x5FFE (outputs) / 0x5FFF (inputs)
    up to the ENI's size, the others empty."""
    if slave.pdos:
        return slave
    pdos: list[Pdo] = []
    for direction, bits in (
        (Direction.OUTPUT, slave.outputs_bits),
        (Direction.INPUT, slave.inputs_bits),
    ):
        if bits <= 0:
            continue
        indexes = _coe_assigned(slave, ASSIGN_OBJECTS[direction]) or [DEFAULT_PDO[direction]]
        entries = _filler_entries(FILLER_OBJECT[direction], bits)
        sm = _process_sm(slave, direction)
        for index, chunk in _pdo_chunks(indexes, entries):
            name = f"{'Rx' if direction == Direction.OUTPUT else 'Tx'}PDO 0x{index:04X}"
            pdos.append(Pdo(index, name, direction, sm, tuple(chunk)))
    return replace(slave, pdos=tuple(pdos))


def _pdo_chunks(indexes: list[int], entries: list[PdoEntry]) -> list[tuple[int, list[PdoEntry]]]:
    """The filler entries spread over the PDOs: ENTRIES_PER_PDO each, the last PDO the
    rest, and where the rest is more than one mapping holds, the PDOs after it (0x1A00,
    0x1A01, ...) as many as it takes."""
    first = [
        (index, entries[k * ENTRIES_PER_PDO : (k + 1) * ENTRIES_PER_PDO])
        for k, index in enumerate(indexes[:-1])
    ]
    rest = entries[(len(indexes) - 1) * ENTRIES_PER_PDO :]
    used = set(indexes)
    index = indexes[-1]
    last = [(index, rest[:MAX_PDO_ENTRIES])]
    for at in range(MAX_PDO_ENTRIES, len(rest), MAX_PDO_ENTRIES):
        while index in used:
            index += 1
        used.add(index)
        last.append((index, rest[at : at + MAX_PDO_ENTRIES]))
    return first + last


def _filler_entries(index: int, bits: int) -> list[PdoEntry]:
    """Unsigned entries of ``bits`` in all; every MAX_PDO_ENTRIES of them fill one more
    filler object, 2 below the last (0x5FFE, 0x5FFC, ... for outputs; 0x5FFF, 0x5FFD, ...
    for inputs), whose sub-indexes are a byte."""
    out: list[PdoEntry] = []
    left = bits
    types = _WIDE_FILLER_TYPES if bits > _WIDE_FILLER_ABOVE_BITS else _FILLER_TYPES
    while left > 0:
        size, name = next(((b, n) for b, n in types if left >= b), (left, ""))
        n = len(out)
        block, sub = divmod(n, MAX_PDO_ENTRIES)
        out.append(PdoEntry(index - 2 * block, sub + 1, size, f"Process data {n + 1}", name))
        left -= size
    return out


def _process_sm(slave: Slave, direction: Direction) -> int | None:
    kind = "outputs" if direction == Direction.OUTPUT else "inputs"
    typed = next((m.index for m in slave.sync_managers if m.kind.lower() == kind), None)
    if typed is not None:
        return typed
    return 2 if direction == Direction.OUTPUT else 3


def _coe_assigned(slave: Slave, assign: int) -> list[int]:
    """The PDO indexes the slave's CoE InitCmds leave in ``assign`` (0x1C12/0x1C13), in
    order: complete-access writes of the whole object and single sub-index writes."""
    if slave.mailbox is None:
        return []
    entries: dict[int, int] = {}
    count = 0
    for cmd in slave.mailbox.coe_init_cmds:
        if cmd.index != assign or cmd.ccs != 1:
            continue
        count, entries = _apply_assign_write(cmd, count, entries)
    return [entries[n] for n in range(1, count + 1) if entries.get(n)]


def _apply_assign_write(
    cmd: CoeInitCmd, count: int, entries: dict[int, int]
) -> tuple[int, dict[int, int]]:
    data = cmd.data
    if cmd.complete_access and cmd.subindex == 0 and len(data) >= 2:
        n = data[0]
        values = [struct.unpack_from("<H", data, 2 + 2 * i)[0] for i in range((len(data) - 2) // 2)]
        return n, {i + 1: v for i, v in enumerate(values[:n])}
    if cmd.subindex == 0 and data:
        return data[0], entries
    if len(data) >= 2:
        return count, {**entries, cmd.subindex: struct.unpack_from("<H", data)[0]}
    return count, entries
