"""The SII EEPROM interface (ETG.1000.4 §6.4, registers 0x0500–0x050F): reads, writes and
reloads of the slave's SII image (:mod:`lolacli.emulator.sii` builds and decodes it)."""

from __future__ import annotations

import struct

from lolacli.emulator import registers as r
from lolacli.emulator.esc.memory import EscMemory
from lolacli.emulator.sii import sii_layout
from lolacli.wire.registers import SII_COMMAND_MASK, SII_COMMAND_SHIFT, SiiCommand, SiiStatus

_U16 = struct.Struct("<H")
# wire's codes as plain ints (module constants are cheaper than enum members per access)
_READ = SiiCommand.READ << SII_COMMAND_SHIFT
_WRITE = SiiCommand.WRITE << SII_COMMAND_SHIFT
_RELOAD = SiiCommand.RELOAD << SII_COMMAND_SHIFT
_READ_8_BYTES = int(SiiStatus.READ_8_BYTES)
_COMMAND_ERROR = int(SiiStatus.COMMAND_ERROR)
_CLEARED = int(SII_COMMAND_MASK | SiiStatus.BUSY | SiiStatus.COMMAND_ERROR)


class SiiInterface(EscMemory):
    """EEPROM commands written by the master to 0x0502, run at once."""

    def _eeprom_command(self) -> None:
        control = self.u16(r.SII_CONTROL_STATUS)
        command = control & SII_COMMAND_MASK
        word = self.u32(r.SII_ADDRESS)
        status = control & ~_CLEARED
        if self.config.eeprom_8_byte_reads:
            status |= _READ_8_BYTES
        if command == _READ:
            chunk = 8 if self.config.eeprom_8_byte_reads else 4
            raw = bytes(self.sii[2 * word : 2 * word + chunk])
            self.mem[r.SII_DATA : r.SII_DATA + 8] = (raw + b"\xff" * 8)[:8]
        elif command == _WRITE:
            if 2 * word + 2 <= len(self.sii):
                self.sii[2 * word : 2 * word + 2] = self.mem[r.SII_DATA : r.SII_DATA + 2]
            else:
                status |= _COMMAND_ERROR
        elif command == _RELOAD:
            self.layout = sii_layout(bytes(self.sii))
            _U16.pack_into(self.mem, r.STATION_ALIAS, self.layout.station_alias)
            self.addressing[0] += 1  # the alias
            self.sii_version[0] += 1
        elif command:
            status |= _COMMAND_ERROR
        _U16.pack_into(self.mem, r.SII_CONTROL_STATUS, status & 0xFFFF)
