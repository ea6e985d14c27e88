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
  each SII EEPROM the header (identity, standard mailbox and its protocols: words
  ``wire.sii.MASTER_HEADER_WORDS``) and the name (STRINGS and GENERAL categories), returns
  this as an ENI model whose slaves carry INIT → PREOP InitCmds built from the SII: request
  INIT (acknowledging an error), check it, SM0 mailbox out and SM1 mailbox in at the SII's
  offsets and sizes, request PREOP, check it. :class:`PreopBus` then runs them.

The SII is read for all slaves at once by :mod:`lolacli.master.eeprom`, the reader
`bus scan` uses too.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, replace

from lolacli.eni.model import Eni, Identity, InitCmd, Mailbox, Slave
from lolacli.eni.model import Master as EniMaster
from lolacli.eni.model import ProcessImage as EniProcessImage
from lolacli.errors import TransportError
from lolacli.master import eeprom
from lolacli.master.core import Master, MasterOptions
from lolacli.master.transport import Transport
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import (
    SM_ACTIVATE_ENABLE,
    SM_CONTROL_MAILBOX_IN,
    SM_CONTROL_MAILBOX_OUT,
    AlState,
    Register,
    SyncManager,
    encode_sync_manager,
    sync_manager_address,
)
from lolacli.wire.sii import SiiInfo, protocol_names

#: SOEM's station addresses: 0x1001, 0x1002, … in line order (ecx_config_init)
FIRST_STATION = 0x1001

_U16 = struct.Struct("<H")
_AL_MASK = b"\x1f\x00"  # state and error indicator


@dataclass(frozen=True, slots=True)
class SiiSlave:
    """A slave found on the bus: where it is and what its SII says."""

    position: int
    station_address: int
    sii: SiiInfo


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
    h = info.sii.header
    if h.rx_mailbox_bytes and h.tx_mailbox_bytes:
        names = protocol_names(h.mailbox_protocols)
        mailbox = Mailbox(
            h.rx_mailbox_offset,
            h.rx_mailbox_bytes,
            h.tx_mailbox_offset,
            h.tx_mailbox_bytes,
            protocols=names,
        )
    return Slave(
        position=info.position,
        name=info.sii.name or "",
        identity=Identity(h.vendor_id, h.product_code, h.revision, h.serial),
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
    out, inn = SM_CONTROL_MAILBOX_OUT, SM_CONTROL_MAILBOX_IN
    on = SM_ACTIVATE_ENABLE
    sm0 = encode_sync_manager(
        SyncManager(mailbox.out_start, mailbox.out_length_bytes, out, activate=on)
    )
    sm1 = encode_sync_manager(
        SyncManager(mailbox.in_start, mailbox.in_length_bytes, inn, activate=on)
    )
    cmds += [
        cmd(Command.FPWR, sync_manager_address(0), sm0, "SM0 mailbox out"),
        cmd(Command.FPWR, sync_manager_address(1), sm1, "SM1 mailbox in"),
        cmd(Command.FPWR, Register.AL_CONTROL, _U16.pack(AlState.PREOP), "request PREOP"),
        check(AlState.PREOP, "check PREOP"),
    ]
    return tuple(cmds)


# ------------------------------------------------------------------------------ SII
def read_sii(master: Master, stations: Sequence[int]) -> list[SiiSlave]:
    """Identity, mailbox, protocols and name of the slaves at ``stations``, all at once
    (:mod:`lolacli.master.eeprom`); TransportError naming the first slave whose EEPROM
    does not read."""
    found = eeprom.read_sii(master, stations, auto_increment=False)
    for station, got in zip(stations, found, strict=True):
        if got.error is not None or got.info is None:
            raise TransportError(f"station 0x{station:04X}: {got.error or 'no SII'}")
    return [
        SiiSlave(k, station, got.info)
        for k, (station, got) in enumerate(zip(stations, found, strict=True), start=1)
        if got.info is not None
    ]


__all__ = [
    "FIRST_STATION",
    "PreopBus",
    "SiiSlave",
    "configure_from_sii",
    "count_slaves",
    "preop_init_cmds",
    "read_sii",
]
