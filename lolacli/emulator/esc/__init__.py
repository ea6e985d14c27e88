"""One EtherCAT slave controller (ESC), a module per concept (as ethercrab lays out its own).

Pure: datagram bytes in, datagram bytes out; time comes in as integer nanoseconds. The model
follows ETG.1000.4 (data link layer: addressing, FMMU, sync managers, DC, SII interface,
error counters) and ETG.1000.6 (AL state machine, AL status codes). The application behind
the ESC (a device with its object dictionary and mailbox server) is an
:class:`EscApplication`; the ESC calls it on mailbox requests, state changes and
process-data cycles.

:mod:`.memory` registers and process RAM (what a write stores and sets off), the PDI
:mod:`.counters` the error counters and what the ESC counts for status lines
:mod:`.sm` sync managers: registers, buffer events, the decoded SM/FMMU configuration
:mod:`.fmmu` logical addressing through the FMMUs
:mod:`.mailbox` the mailbox over its two sync managers (ETG.1000.4 §6.7)
:mod:`.al` the AL state machine (ETG.1000.6 §5.3)
:mod:`.watchdog` the process-data watchdog
:mod:`.eeprom` the SII EEPROM interface (the image itself is :mod:`lolacli.emulator.sii`)
:mod:`.dc` distributed clocks: local clock, receive times, the time control loop
:mod:`.controller` :class:`Esc` composed of them: datagram dispatch, physical access,
the application cycle
"""

from __future__ import annotations

from lolacli.emulator.esc.controller import (
    Esc,
    broadcast_of_registers,
    broadcast_read,
    broadcast_write,
)
from lolacli.emulator.esc.counters import EscCounters
from lolacli.emulator.esc.dc import MAX_CORRECTION_NS, DcClock, PortTimes, system_time_loop
from lolacli.emulator.esc.fmmu import byte_aligned
from lolacli.emulator.esc.memory import PLAN_FREE_REGISTERS, EscApplication, EscConfig
from lolacli.emulator.esc.sm import Configuration, SmView

__all__ = [
    "MAX_CORRECTION_NS",
    "PLAN_FREE_REGISTERS",
    "Configuration",
    "DcClock",
    "Esc",
    "EscApplication",
    "EscConfig",
    "EscCounters",
    "PortTimes",
    "SmView",
    "broadcast_of_registers",
    "broadcast_read",
    "broadcast_write",
    "byte_aligned",
    "system_time_loop",
]
