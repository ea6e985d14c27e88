"""The mailbox (ETG.1000.4 §6.7.1–6.7.2) over its two sync managers: a write taken once
per counter, answers queued for the read mailbox, the master's repeat request."""

from __future__ import annotations

from lolacli.emulator.esc.sm import SmView, SyncManagers
from lolacli.wire.mailbox import MAILBOX_HEADER_BYTES, decode_mailbox_header


class Mailbox(SyncManagers):
    """The slave's side of the mailbox: its firmware serves the write mailbox through the
    application and posts the answers."""

    _mailbox_queue: list[bytes]
    _mailbox_write_counter: int  # counter of the last mailbox service taken
    _mailbox_pending: bool  # the write mailbox waits for the firmware
    _last_mailbox_in: bytes | None

    def _forget_mailbox(self) -> None:
        """No message waiting either way, no counter known (power-on, INIT)."""
        self._mailbox_queue.clear()
        self._mailbox_write_counter = 0
        self._mailbox_pending = False

    def _write_mailbox_disabled(self) -> None:
        self._mailbox_pending = False

    def _mailbox_read(self) -> None:
        self._post_next_mailbox()
        if self._mailbox_pending:
            self.hand_to_firmware(self._take_mailbox)

    def _repeat_request(self, base: int) -> None:
        """Mailbox repeat (ETG.1000.4 §6.7.2): the master toggled activate bit 1 after a
        lost mailbox read; post the last message again and acknowledge in PDI bit 1."""
        requested = self.mem[base + 6] & 0x02
        if requested == self.mem[base + 7] & 0x02:
            return
        if self._last_mailbox_in is not None:
            index = self.layout.mailbox_in_sm
            if self._sm_full(index):  # a newer message is waiting: it goes back in line
                sm = self.sync_manager(index)
                self._mailbox_queue.insert(0, bytes(self.mem[sm.start : sm.start + sm.length]))
                self._set_sm_full(index, False)
            self._mailbox_queue.insert(0, self._last_mailbox_in)
            self._post_next_mailbox()
        self.mem[base + 7] = (self.mem[base + 7] & ~0x02) | requested

    def _mailbox_written(self, sm: SmView) -> None:
        """The master wrote the last byte of the write mailbox: it is full until the
        firmware reads it (a second write meanwhile gets WKC 0 and is lost)."""
        self._set_sm_full(sm.index, True)
        self._mailbox_pending = True
        self.hand_to_firmware(self._take_mailbox)

    def _take_mailbox(self) -> None:
        """Firmware: read the write mailbox and serve it, once the read mailbox has room
        for the answer (the slave stack reads it only then). A write with the counter of
        the service taken last is the master's repeat of a write whose answer it lost:
        dropped, so the service runs once (counter 0: a master without counters)."""
        if not self._mailbox_pending:
            return
        if self._mailbox_queue or self._sm_full(self.layout.mailbox_in_sm):
            return  # again when the master has read the read mailbox
        index = self.layout.mailbox_out_sm
        sm = self.sync_manager(index)
        request = bytes(self.mem[sm.start : sm.start + sm.length])
        self._mailbox_pending = False
        self._set_sm_full(index, False)  # the PDI has read it
        counter = 0
        if len(request) >= MAILBOX_HEADER_BYTES:
            counter = decode_mailbox_header(request).counter
        if counter and counter == self._mailbox_write_counter:
            return
        self._mailbox_write_counter = counter
        self.counters.mailbox_requests += 1
        if self.app is not None:
            read_bytes = self.sync_manager(self.layout.mailbox_in_sm).length
            self._mailbox_queue.extend(self.app.mailbox_request(request, read_bytes))
        self._post_next_mailbox()

    def _post_next_mailbox(self) -> None:
        index = self.layout.mailbox_in_sm
        sm = self.sync_manager(index)
        if not self._mailbox_queue or self._sm_full(index) or not sm.enabled:
            return
        message = self._mailbox_queue.pop(0)[: sm.length]
        self._store(sm.start, message + bytes(sm.length - len(message)))
        self._last_mailbox_in = message
        self._set_sm_full(index, True)

    def post_mailbox(self, message: bytes) -> None:
        """Queue an unsolicited mailbox message (e.g. an emergency) for the master, with
        the counter the firmware gives it."""
        if self.app is not None:
            message = self.app.mailbox_posted(message)
        self._mailbox_queue.append(message)
        self._post_next_mailbox()
