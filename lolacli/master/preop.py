"""Slaves to PREOP for mailbox access, one at a time: by an ENI, or by what the bus says.

SDO access needs a slave in PREOP with its mailbox sync managers set up, nothing more: no
process data, no distributed clocks, no other slave. Two ways there:

* :class:`PreopBus` over an ENI runs, for the slaves asked for only, the INIT → PREOP
  InitCmds the ENI gives them (station address, watchdog, SM0/SM1 mailbox, AL control,
  AL status checked) — the master's own IP InitCmds once before the first — through
  :class:`~lolacli.master.core.Master`, as ``Master.bring_up`` does for all of them.
  Distributed clocks are left out (an SDO does not need them; their start-up is a
  thousand frames).
* :func:`configure_from_sii`, for a bus without an ENI (SOEM's ``config_init``): counts the
  slaves (BRD of register 0x0000), gives them station addresses 0x1001, 0x1002, … in line
  order (SOEM's, so ``@0x1005`` names the same slave through either master), reads from
  each SII EEPROM the identity (words 0x08–0x0F), the standard mailbox (0x18–0x1B), the
  mailbox protocols (0x1C) and the name (STRINGS and GENERAL categories), and returns
  this as an ENI model whose slaves carry INIT → PREOP InitCmds built from the SII: request
  INIT (acknowledging an error), check it, SM0 mailbox out and SM1 mailbox in at the SII's
  offsets and sizes, request PREOP, check it. :class:`PreopBus` then runs them.

The SII is read for all slaves at once, a word address per slave per round: one frame
writes every slave's EEPROM read command (0x0502–0x0507), the next reads every slave's
status and data back (0x0502–0x050F), polled while a slave says busy (ETG.1000.4 §6.4).
A slave whose EEPROM its PDI holds is taken over first (0x0500) and handed back after.
"""

from __future__ import annotations

import struct
from collections.abc import Generator, Sequence
from dataclasses import dataclass, replace

from lolacli.eni.model import Eni, Identity, InitCmd, Mailbox, Slave
from lolacli.eni.model import Master as EniMaster
from lolacli.eni.model import ProcessImage as EniProcessImage
from lolacli.errors import TransportError
from lolacli.master.core import Master, MasterOptions
from lolacli.master.transport import Transport
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import (
    SII_COMMAND_SHIFT,
    AlState,
    Register,
    SiiCommand,
    SiiConfig,
    SiiStatus,
    SyncManager,
    encode_sync_manager,
    sync_manager_address,
)
from lolacli.wire.sii import SiiWords

#: SOEM's station addresses: 0x1001, 0x1002, … in line order (ecx_config_init)
FIRST_STATION = 0x1001

# SII header words (ETG.1000.6 Table 16)
SII_VENDOR_ID = 0x08
SII_RX_MAILBOX = 0x18  # offset, size; then the send mailbox's offset, size (0x1A, 0x1B)
SII_MAILBOX_PROTOCOL = 0x1C
SII_FIRST_CATEGORY = 0x40
SII_STRINGS = 10
SII_GENERAL = 30
SII_END = 0xFFFF
SII_MAX_WORDS = 0x4000  # stop walking categories here (32 KiB, beyond any real EEPROM)
#: mailbox protocol bits of SII word 0x1C (ETG.1000.6 Table 18), as the ENI names them
PROTOCOLS = (
    (0x01, "AoE"),
    (0x02, "EoE"),
    (0x04, "CoE"),
    (0x08, "FoE"),
    (0x10, "SoE"),
    (0x20, "VoE"),
)

#: EEPROM status bits that fail a read (0x0502; a checksum error too, as SOEM's error mask)
EEPROM_ERROR = SiiStatus.COMMAND_ERROR | SiiStatus.CHECKSUM_ERROR
EEPROM_POLLS = 100

# mailbox sync managers: control byte (mailbox mode, direction, interrupt), activate
SM_MAILBOX_OUT_CONTROL = 0x26
SM_MAILBOX_IN_CONTROL = 0x22
SM_ENABLE = 0x01
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_AL_MASK = b"\x1f\x00"  # state and error indicator


@dataclass(frozen=True, slots=True)
class SiiSlave:
    """What the SII of one slave says (``name`` empty when it has none)."""

    position: int
    station_address: int
    identity: Identity
    name: str
    rx_mailbox: tuple[int, int]  # master -> slave: offset, bytes
    tx_mailbox: tuple[int, int]  # slave -> master
    protocols: int


def _bare(eni: Eni) -> Eni:
    """The ENI without slaves, cyclic frames or process image: what the master needs to
    exchange frames and run its own InitCmds."""
    return replace(eni, slaves=(), cyclic=(), process_image=EniProcessImage(0, 0))


class PreopBus:
    """A master that brings the slaves of ``eni`` to PREOP when they are first asked for
    (see the module docstring); the other slaves stay as they are."""

    def __init__(
        self,
        eni: Eni,
        transport: Transport,
        options: MasterOptions | None = None,
        *,
        master: Master | None = None,
    ) -> None:
        self.eni = eni
        if master is None:
            master = Master(_bare(eni), transport, options=options)
        else:  # the master that read the configuration (its frame indexes go on)
            master.eni = _bare(eni)
        self.master = master
        self._master_done = False
        self._up: dict[int, Slave] = {}

    def bring_up(self, slave: Slave) -> Slave:
        """Run ``slave``'s INIT → PREOP InitCmds (the master's own first, once):
        TransitionRefusedError when the slave refuses, TransportError when the bus does
        not answer. The slave as brought up (without DC) is returned."""
        done = self._up.get(slave.position)
        if done is not None:
            return done
        base = self.master.eni
        own = base.master if not self._master_done else replace(base.master, init_cmds=())
        part = replace(slave, dc=None)
        self.master.eni = replace(base, master=own, slaves=(part,))
        try:
            self.master.transition("IP")
        finally:
            self.master.eni = base
        self._master_done = True
        self._up[slave.position] = part
        return part

    def close(self) -> None:
        self.master.transport.close()


# ----------------------------------------------------------------- a bus without an ENI
def count_slaves(master: Master, where: str = "") -> int:
    """The working counter of a broadcast read of register 0x0000; TransportError when
    no frame comes back or none is counted."""
    at = f" on {where}" if where else ""
    try:
        got = master.exchange_one(Datagram.physical(Command.BRD, 0, Register.TYPE, 1))
    except TransportError:
        raise TransportError(f"no slave answers{at} (no frame came back)") from None
    if got.wkc == 0:
        raise TransportError(f"no slave answers{at} (frames come back unprocessed)")
    return got.wkc


def configure_from_sii(
    transport: Transport, *, where: str = "", options: MasterOptions | None = None
) -> tuple[Eni, Master]:
    """The bus's configuration from its SII (see the module docstring) and the master
    that read it, which :class:`PreopBus` takes over (the station addresses are set)."""
    master = Master(
        Eni(EniMaster(), (), (), EniProcessImage(0, 0), source=where), transport, options=options
    )
    count = count_slaves(master, where)
    stations = [FIRST_STATION + k for k in range(count)]
    master.exchange_many(
        [
            Datagram.physical(Command.APWR, (-k) & 0xFFFF, Register.STATION_ADDRESS, _U16.pack(s))
            for k, s in enumerate(stations)
        ]
    )
    infos = read_sii(master, stations)
    slaves = tuple(_slave(info) for info in infos)
    return Eni(EniMaster(), slaves, (), EniProcessImage(0, 0), source=where or "the bus"), master


def _slave(info: SiiSlave) -> Slave:
    mailbox = None
    rx_start, rx_bytes = info.rx_mailbox
    tx_start, tx_bytes = info.tx_mailbox
    if rx_bytes and tx_bytes:
        names = tuple(name for bit, name in PROTOCOLS if info.protocols & bit)
        mailbox = Mailbox(rx_start, rx_bytes, tx_start, tx_bytes, protocols=names)
    return Slave(
        position=info.position,
        name=info.name,
        identity=info.identity,
        station_address=info.station_address,
        auto_inc_address=(-(info.position - 1)) & 0xFFFF,
        mailbox=mailbox,
        init_cmds=preop_init_cmds(info.station_address, mailbox),
    )


def preop_init_cmds(station: int, mailbox: Mailbox | None) -> tuple[InitCmd, ...]:
    """INIT → PREOP of one slave with its mailbox at ``mailbox`` (none: INIT only)."""

    def cmd(kind: int, ado: int, data: bytes, comment: str, **more: object) -> InitCmd:
        return InitCmd(("IP",), kind, station, ado, data, 1, comment, retries=3, **more)  # type: ignore[arg-type]

    def check(state: AlState, comment: str) -> InitCmd:
        return cmd(
            Command.FPRD,
            Register.AL_STATUS,
            bytes(2),
            comment,
            validate_data=_U16.pack(state),
            validate_mask=_AL_MASK,
            validate_timeout_ms=5000,
        )

    cmds = [
        cmd(
            Command.FPWR,
            Register.AL_CONTROL,
            _U16.pack(AlState.INIT | 0x10),
            "request INIT (acknowledge errors)",
        ),
        check(AlState.INIT, "check INIT"),
    ]
    if mailbox is None:
        return tuple(cmds)
    sm0 = encode_sync_manager(SyncManager(
        mailbox.out_start, mailbox.out_length_bytes, SM_MAILBOX_OUT_CONTROL, activate=SM_ENABLE
    ))
    sm1 = encode_sync_manager(SyncManager(
        mailbox.in_start, mailbox.in_length_bytes, SM_MAILBOX_IN_CONTROL, activate=SM_ENABLE
    ))
    cmds += [
        cmd(Command.FPWR, sync_manager_address(0), sm0, "SM0 mailbox out"),
        cmd(Command.FPWR, sync_manager_address(1), sm1, "SM1 mailbox in"),
        cmd(Command.FPWR, Register.AL_CONTROL, _U16.pack(AlState.PREOP), "request PREOP"),
        check(AlState.PREOP, "check PREOP"),
    ]
    return tuple(cmds)


# ------------------------------------------------------------------------------ SII
_Walk = Generator[int, bytes, None]


class _Sii(SiiWords):
    """One slave's SII as read so far, and what went wrong reading it."""

    def __init__(self, station: int) -> None:
        super().__init__()
        self.station = station
        self.error = ""


def _walk(sii: _Sii, out: dict[str, object]) -> _Walk:
    """Header words, then the categories up to STRINGS and GENERAL (or the end)."""
    out["identity"] = yield from sii.read(SII_VENDOR_ID, 8)
    out["mailbox"] = yield from sii.read(SII_RX_MAILBOX, 5)
    address = SII_FIRST_CATEGORY
    strings: bytes | None = None
    general: bytes | None = None
    while address < SII_MAX_WORDS and (strings is None or general is None):
        kind, length = struct.unpack("<HH", (yield from sii.read(address, 2)))
        if kind == SII_END or length == 0xFFFF:
            break
        if kind == SII_STRINGS and strings is None:
            strings = yield from sii.read(address + 2, length)
        elif kind == SII_GENERAL and general is None:
            general = yield from sii.read(address + 2, min(length, 2))
        address += 2 + length
    out["strings"], out["general"] = strings, general


def _strings(data: bytes | None) -> list[str]:
    if not data:
        return []
    out, pos = [], 1
    for _ in range(data[0]):
        if pos >= len(data):
            break
        n = data[pos]
        out.append(data[pos + 1 : pos + 1 + n].decode("latin-1"))
        pos += 1 + n
    return out


def read_sii(master: Master, stations: Sequence[int]) -> list[SiiSlave]:
    """Identity, mailbox, protocols and name of the slaves at ``stations`` (see the
    module docstring); TransportError naming the slave whose EEPROM does not answer."""
    configs = master.exchange_many(
        [Datagram.physical(Command.FPRD, s, Register.SII_CONFIG, 1) for s in stations]
    )
    held = [
        s
        for s, d in zip(stations, configs, strict=True)
        if d.wkc == 1 and d.data[0] & SiiConfig.PDI_OFFERED
    ]
    _eeprom_owner(master, held, to_pdi=False)
    try:
        found: dict[int, dict[str, object]] = {s: {} for s in stations}
        images = {s: _Sii(s) for s in stations}
        walks = {s: _walk(images[s], found[s]) for s in stations}
        pending = {s: next(walks[s]) for s in stations}
        while pending:
            for station, data in _read_words(master, list(pending.items())).items():
                try:
                    pending[station] = walks[station].send(data)
                except StopIteration:
                    del pending[station]
    finally:
        _eeprom_owner(master, held, to_pdi=True)
    out = []
    for position, station in enumerate(stations, start=1):
        f = found[station]
        vendor, product, revision, serial = struct.unpack("<4I", f["identity"])  # type: ignore[arg-type]
        rx_off, rx_len, tx_off, tx_len, protocols = struct.unpack("<5H", f["mailbox"])  # type: ignore[arg-type]
        strings = _strings(f.get("strings"))  # type: ignore[arg-type]
        general = f.get("general")
        name = ""
        if isinstance(general, bytes) and len(general) >= 4 and 0 < general[3] <= len(strings):
            name = strings[general[3] - 1]
        out.append(
            SiiSlave(
                position,
                station,
                Identity(vendor, product, revision, serial),
                name,
                (rx_off, rx_len),
                (tx_off, tx_len),
                protocols,
            )
        )
    return out


def _eeprom_owner(master: Master, stations: Sequence[int], *, to_pdi: bool) -> None:
    """Take the EEPROM from the PDI (force, then release the force bit), or give it back."""
    if not stations:
        return
    for value in [SiiConfig.PDI_OFFERED] if to_pdi else [SiiConfig.FORCE_ECAT, 0]:
        master.exchange_many(
            [
                Datagram.physical(Command.FPWR, s, Register.SII_CONFIG, bytes([value]))
                for s in stations
            ]
        )


def _read_words(master: Master, asks: Sequence[tuple[int, int]]) -> dict[int, bytes]:
    """One round: every slave (station) reads the words at its address (4 or 8 bytes)."""
    commands = master.exchange_many(
        [
            Datagram.physical(
                Command.FPWR,
                station,
                Register.SII_CONTROL_STATUS,
                _U16.pack(SiiCommand.READ << SII_COMMAND_SHIFT) + _U32.pack(address),
            )
            for station, address in asks
        ]
    )
    for (station, address), d in zip(asks, commands, strict=True):
        if d.wkc != 1:
            raise TransportError(
                f"station 0x{station:04X}: SII read of word 0x{address:X} not taken"
            )
    out: dict[int, bytes] = {}
    waiting = list(asks)
    for _ in range(EEPROM_POLLS):
        reads = [
            Datagram.physical(Command.FPRD, s, Register.SII_CONTROL_STATUS, 14) for s, _a in waiting
        ]
        still = []
        for (station, address), d in zip(waiting, master.exchange_many(reads), strict=True):
            status = _U16.unpack_from(d.data)[0] if d.wkc == 1 else SiiStatus.BUSY
            if status & SiiStatus.BUSY:
                still.append((station, address))
            elif status & EEPROM_ERROR:
                raise TransportError(
                    f"station 0x{station:04X}: SII read of word 0x{address:X} failed "
                    f"(EEPROM status 0x{status:04X})"
                )
            else:
                n = 8 if status & SiiStatus.READ_8_BYTES else 4
                out[station] = bytes(d.data[6 : 6 + n])
        waiting = still
        if not waiting:
            return out
        master.idle(master.options.poll_ns)
    station, address = waiting[0]
    raise TransportError(f"station 0x{station:04X}: SII EEPROM stays busy (word 0x{address:X})")


__all__ = [
    "FIRST_STATION",
    "PreopBus",
    "SiiSlave",
    "configure_from_sii",
    "count_slaves",
    "preop_init_cmds",
    "read_sii",
]
