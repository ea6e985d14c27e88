"""CoE in the mailbox: the SDO server (:class:`~lolacli.emulator.mailbox.sdo_server.SdoServer`,
SDO up/download and SDO Information) as a :class:`~lolacli.emulator.mailbox.MailboxHandler`.
Served in PREOP, SAFEOP and OP; a bootloader in BOOT speaks no CoE. Without a server
(``server`` None) requests are taken and never answered, as by a firmware that hangs."""

from __future__ import annotations

from lolacli.emulator.mailbox.dispatch import MailboxContext
from lolacli.emulator.mailbox.sdo_server import SdoServer
from lolacli.wire.mailbox import MailboxType
from lolacli.wire.registers import AlState

COE_STATES = frozenset({AlState.PREOP, AlState.SAFEOP, AlState.OP})


class CoeHandler:
    mailbox_type = MailboxType.CoE
    states = COE_STATES

    def __init__(self, server: SdoServer | None) -> None:
        self.server = server

    def handle(self, request: bytes, context: MailboxContext) -> list[bytes]:
        return self.server.handle(request) if self.server is not None else []

    def state_changed(self, state: int) -> None:
        """An SDO transfer is one request at a time: nothing to end."""
