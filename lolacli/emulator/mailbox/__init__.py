"""The protocols behind an emulated slave's mailbox: one handler per mailbox type.

The ESC (:mod:`lolacli.emulator.esc.mailbox`) moves whole mailbox messages between its
two sync managers and the slave's firmware; it knows no protocol. The firmware's side is
a :class:`MailboxDispatcher`: it reads the type in the mailbox header and hands the
message to the :class:`MailboxHandler` registered for it, in the AL states the handler
is served in; anything else gets the mailbox error reply of ETG.1000.4 Table 30 (type 0:
unsupported protocol, a header too short). It also numbers the answers with the slave's
own mailbox counter (1..7, ETG.1000.4 Table 29), whichever handler wrote them.

:mod:`.coe` CoE: the SDO server (:mod:`.sdo_server`) as a handler
:mod:`.foe` FoE: file read and write in BOOT, a slave's files kept across state changes

A new protocol (EoE, SoE, …) is a class with ``mailbox_type``, ``states`` and
``handle(request, context)``, registered with :meth:`MailboxDispatcher.register`; neither
the ESC nor the other handlers change.
"""

from __future__ import annotations

from lolacli.emulator.mailbox.dispatch import (
    MailboxContext,
    MailboxDispatcher,
    MailboxHandler,
    mailbox_error,
)

__all__ = ["MailboxContext", "MailboxDispatcher", "MailboxHandler", "mailbox_error"]
