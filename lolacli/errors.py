"""The error tree of lolacli.

Every error the library raises on purpose is a :class:`LolaError`. Each class carries the
fields a caller needs to act on it, and the process exit code the CLI maps it to (see the
exit codes in README.md): 1 check failed, 2 usage, 3 bad input, 4 bus or transport.
"""

from __future__ import annotations


class LolaError(Exception):
    """Base of every error lolacli raises on purpose."""

    exit_code: int = 1


class UsageError(LolaError):
    """The caller asked for something that cannot be done as asked (exit 2)."""

    exit_code = 2


class InputError(LolaError):
    """An input file or byte string is unreadable or invalid (exit 3).

    ``path`` names the file where there is one; ``line`` (1-based) or ``offset`` (bytes)
    say where in it, when known.
    """

    exit_code = 3

    def __init__(
        self,
        message: str,
        *,
        path: str | None = None,
        line: int | None = None,
        offset: int | None = None,
    ) -> None:
        self.message = message
        self.path = path
        self.line = line
        self.offset = offset
        super().__init__(self.one_line())

    def one_line(self) -> str:
        where = ""
        if self.path is not None:
            where = self.path
            if self.line is not None:
                where += f":{self.line}"
            elif self.offset is not None:
                where += f"@{self.offset}"
            where += ": "
        elif self.offset is not None:
            where = f"offset {self.offset}: "
        return where + " ".join(self.message.split())


class WireError(InputError):
    """Bytes that are not a well-formed EtherCAT frame, datagram, mailbox or CoE message."""


class EniError(InputError):
    """An ENI file that cannot be read or is not an ENI."""


class CaptureError(InputError):
    """A capture file that cannot be read at all (bad magic, not a capture)."""


class TransportError(LolaError):
    """A bus or transport failure: no interface, no permission, timeout, no answer (exit 4)."""

    exit_code = 4


class SdoAbortError(LolaError):
    """An SDO transfer ended with an abort (CiA 301 abort code)."""

    def __init__(self, index: int, subindex: int, code: int, message: str = "") -> None:
        self.index = index
        self.subindex = subindex
        self.code = code
        self.text = message
        super().__init__(
            f"SDO 0x{index:04X}:{subindex:02X} aborted 0x{code:08X}"
            + (f": {message}" if message else "")
        )


class FoeError(LolaError):
    """A slave answered an FoE transfer with an FoE error (ETG.1000.6 Table 92; exit 1).

    ``code`` is the error code (0x8000…; ``None`` where the master does not tell it, as
    SOEM), ``text`` its meaning and ``slave_text`` what the slave wrote with it."""

    def __init__(self, where: str, code: int | None, text: str, slave_text: str = "") -> None:
        self.where = where
        self.code = code
        self.text = text
        self.slave_text = slave_text
        said = f" ({slave_text})" if slave_text and slave_text != text else ""
        number = f" 0x{code:04X}" if code is not None else ""
        super().__init__(f"{where}: FoE error{number}: {text}{said}")


class TransitionRefusedError(LolaError):
    """A slave refused an AL state transition (or did not reach the state in time).

    ``al_status_code`` is the slave's register 0x0134 (ETG.1000.6 Table 11) and ``text``
    its meaning; ``transition`` is the ENI's name for it ("IP", "PS", "SO", ...).
    """

    def __init__(
        self,
        slave: str,
        position: int,
        transition: str,
        al_status_code: int | None,
        text: str,
        detail: str = "",
    ) -> None:
        self.slave = slave
        self.position = position
        self.transition = transition
        self.al_status_code = al_status_code
        self.text = text
        self.detail = detail
        code = "" if al_status_code is None else f": AL status code 0x{al_status_code:04X}"
        super().__init__(
            f"slave {position} ({slave}) refused {transition}{code} {text}"
            + (f" ({detail})" if detail else "")
        )


class LinkError(UsageError):
    """A Bus Variable cannot be linked to a process-image variable: unknown name, wrong
    type or size, wrong direction (exit 2). ``name`` is the variable's ENI name."""

    def __init__(self, name: str, message: str) -> None:
        self.name = name
        super().__init__(f"bus variable {name!r}: {message}")
