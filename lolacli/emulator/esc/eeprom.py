"""The SII EEPROM interface (ETG.1000.4 §6.4, registers 0x0500–0x050F): reads, writes and
reloads of the slave's SII image (:mod:`lolacli.emulator.sii` builds and decodes it)."""

from __future__ import annotations

import struct

from lolacli.emulator import registers as r
from lolacli.emulator.esc.memory import EscMemory
from lolacli.emulator.sii import sii_layout

_U16 = struct.Struct("<H")


class SiiInterface(EscMemory):
    """EEPROM commands written by the master to 0x0502, run at once."""

    def _eeprom_command(self) -> None:
        control = self.u16(r.EEPROM_CONTROL)
        command = control & r.EEPROM_COMMAND_MASK
        word = self.u32(r.EEPROM_ADDRESS)
        status = control & ~(r.EEPROM_COMMAND_MASK | r.EEPROM_STATUS_BUSY | r.EEPROM_ERROR_COMMAND)
        if self.config.eeprom_8_byte_reads:
            status |= r.EEPROM_STATUS_READ_8_BYTES
        if command == r.EEPROM_COMMAND_READ:
            chunk = 8 if self.config.eeprom_8_byte_reads else 4
            raw = bytes(self.sii[2 * word : 2 * word + chunk])
            self.mem[r.EEPROM_DATA : r.EEPROM_DATA + 8] = (raw + b"\xff" * 8)[:8]
        elif command == r.EEPROM_COMMAND_WRITE:
            if 2 * word + 2 <= len(self.sii):
                self.sii[2 * word : 2 * word + 2] = self.mem[r.EEPROM_DATA : r.EEPROM_DATA + 2]
            else:
                status |= r.EEPROM_ERROR_COMMAND
        elif command == r.EEPROM_COMMAND_RELOAD:
            self.layout = sii_layout(bytes(self.sii))
            _U16.pack_into(self.mem, r.STATION_ALIAS, self.layout.station_alias)
        elif command:
            status |= r.EEPROM_ERROR_COMMAND
        _U16.pack_into(self.mem, r.EEPROM_CONTROL, status & 0xFFFF)
