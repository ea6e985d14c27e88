"""The dispatcher of mailbox messages to protocol handlers (see the package docstring)."""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import Protocol

from lolacli.wire.mailbox import (
    MAILBOX_HEADER_BYTES,
    MailboxError,
    MailboxErrorDetail,
    MailboxType,
    encode_mailbox_error,
    encode_mailbox_message,
    next_counter,
)

_COUNTER_MASK = 0x70


@dataclass(frozen=True, slots=True)
class MailboxContext:
    """What a handler may need besides the message: the slave's AL state and the sizes
    of its mailbox buffers as the master set them up (write: master → slave)."""

    al_state: int
    write_bytes: int
    read_bytes: int


class MailboxHandler(Protocol):
    """One mailbox protocol of a slave."""

    @property
    def mailbox_type(self) -> int:
        """The mailbox type it serves (:class:`lolacli.wire.mailbox.MailboxType`)."""
        ...

    @property
    def states(self) -> Collection[int]:
        """The AL states it is served in; in the others its type gets the mailbox error
        "unsupported protocol" (a bootloader speaks no CoE …)."""
        ...

    def handle(self, request: bytes, context: MailboxContext) -> list[bytes]:
        """A whole mailbox message (header, payload, the buffer's padding) in, the
        mailbox messages to answer with out (their counters are the dispatcher's)."""
        ...

    def state_changed(self, state: int) -> None:
        """The slave entered ``state`` (a transfer under way may end with it)."""
        ...


def mailbox_error(detail: int) -> bytes:
    """The mailbox error reply (type 0) with ``detail`` (ETG.1000.4 Table 30)."""
    body = encode_mailbox_error(MailboxError(detail))
    return encode_mailbox_message(MailboxType.ERR, body, 0, MAILBOX_HEADER_BYTES + len(body))


class MailboxDispatcher:
    """The slave firmware's mailbox: messages to handlers by type (package docstring)."""

    def __init__(self, handlers: Collection[MailboxHandler] = ()) -> None:
        self.handlers: dict[int, MailboxHandler] = {}
        self.al_state = 1
        self.counter = 0
        self.errors = 0  # mailbox error replies sent
        for handler in handlers:
            self.register(handler)

    def register(self, handler: MailboxHandler) -> None:
        self.handlers[int(handler.mailbox_type)] = handler

    def handle(self, request: bytes, read_bytes: int) -> list[bytes]:
        """A mailbox message from the master (its write buffer as the ESC holds it) ->
        the messages to post in the read mailbox of ``read_bytes``."""
        if len(request) < MAILBOX_HEADER_BYTES:
            return self._numbered([self._error(MailboxErrorDetail.SYNTAX)])
        length = request[0] | request[1] << 8
        if MAILBOX_HEADER_BYTES + length > len(request):
            return self._numbered([self._error(MailboxErrorDetail.INVALID_SIZE)])
        handler = self.handlers.get(request[5] & 0x0F)
        if handler is None or self.al_state not in handler.states:
            return self._numbered([self._error(MailboxErrorDetail.UNSUPPORTED_PROTOCOL)])
        context = MailboxContext(self.al_state, len(request), read_bytes)
        return self._numbered(handler.handle(request, context))

    def state_changed(self, state: int) -> None:
        self.al_state = state
        for handler in self.handlers.values():
            handler.state_changed(state)

    def _error(self, detail: int) -> bytes:
        self.errors += 1
        return mailbox_error(detail)

    def numbered(self, message: bytes) -> bytes:
        """``message`` with the slave's next counter (whatever its writer put there): the
        answers of every handler and the messages posted unasked count on one counter."""
        self.counter = next_counter(self.counter)
        head = bytearray(message[:MAILBOX_HEADER_BYTES])
        head[5] = (head[5] & ~_COUNTER_MASK & 0xFF) | self.counter << 4
        return bytes(head) + message[MAILBOX_HEADER_BYTES:]

    def _numbered(self, messages: list[bytes]) -> list[bytes]:
        return [self.numbered(m) for m in messages]
