"""What the ESC counts: the error counter registers (0x0300–0x0313) and, for status lines
and tests, datagrams, mailbox requests, cycles and refused transitions."""

from __future__ import annotations

from dataclasses import dataclass

from lolacli.emulator import registers as r


@dataclass(slots=True)
class EscCounters:
    """What happened, for status lines and tests."""

    datagrams: int = 0
    mailbox_requests: int = 0
    cycles: int = 0
    refused_transitions: int = 0


# Error counters cleared together by a write to any of them (ESC datasheet section II,
# 0x0300-0x0313): RX and forwarded RX errors, processing unit, PDI, lost links.
COUNTER_CLEAR_GROUPS = (
    (r.RX_ERROR_COUNTER, r.PROCESSING_UNIT_ERROR_COUNTER),
    (r.PROCESSING_UNIT_ERROR_COUNTER, r.PDI_ERROR_COUNTER),
    (r.PDI_ERROR_COUNTER, r.PDI_ERROR_COUNTER + 1),
    (r.LOST_LINK_COUNTER, r.ERROR_COUNTERS_END),
)


class ErrorCounters:
    """The error counter registers as the ports see errors (saturating at 0xFF)."""

    mem: bytearray

    def count_invalid_frame(self, port: int = 0) -> None:
        address = r.RX_ERROR_COUNTER + 2 * port
        self.mem[address] = min(0xFF, self.mem[address] + 1)

    def count_rx_error(self, port: int = 0) -> None:
        """0x0301 + 2·port: physical layer (symbol) errors inside a frame on ``port``."""
        address = r.RX_ERROR_COUNTER + 2 * port + 1
        self.mem[address] = min(0xFF, self.mem[address] + 1)

    def count_forwarded_error(self, port: int = 0) -> None:
        """0x0308 + port: a frame arrived on ``port`` marked bad by an earlier ESC."""
        address = r.FORWARDED_RX_ERROR_COUNTER + port
        self.mem[address] = min(0xFF, self.mem[address] + 1)

    def count_lost_link(self, port: int) -> None:
        """0x0310 + port: the link of ``port`` went down."""
        address = r.LOST_LINK_COUNTER + port
        self.mem[address] = min(0xFF, self.mem[address] + 1)
