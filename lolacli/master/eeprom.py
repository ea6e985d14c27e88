"""What slaves' SII EEPROMs say, read through their ESCs' EEPROM interface, all at once.

One reader for `bus scan` (slaves by auto-increment position: nothing configured yet, or
someone else's configuration left alone) and for the PREOP bring-up without an ENI
(slaves by the station addresses it gave them). Each slave walks
:func:`lolacli.wire.sii.read_sii` (the header words a master needs, then the categories
up to STRINGS and GENERAL); a round asks every slave for the word its walk waits for:

* one frame writes every slave's read command and word address (0x0502-0x0507),
* the next reads every slave's status and data back (0x0502-0x050F), again after
  ``master.options.poll_ns`` while a slave says busy, :data:`POLLS` times at most
  (ETG.1000.4 §6.4; an ESC answers 4 or 8 bytes a read, as its status says).

A slave whose EEPROM its PDI holds (0x0500 bit 0 set) is taken over first (force, then
release the force bit) and handed back after, also when a read fails.

A read fails for the slave on a missing working counter, on the command error bit
(missing EEPROM acknowledge or invalid command), on an EEPROM still busy after the polls,
or on an image the walk cannot decode. The checksum error bit is not a read failure: it
says the ESC found its configuration area's CRC wrong at power-up, and the words still
read; the header's own ``checksum_ok`` reports it. SOEM clears and retries on either.
"""

from __future__ import annotations

import struct
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field

from lolacli.errors import TransportError, WireError
from lolacli.master.core import Master
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import SII_COMMAND_SHIFT, Register, SiiCommand, SiiConfig, SiiStatus
from lolacli.wire.sii import (
    CATEGORY_END,
    HEADER_WORDS,
    MAX_WORDS,
    SiiInfo,
    SiiWords,
    decode_category_header,
    read_sii_header,
    read_sii_names,
)

#: status bits at 0x0502 that fail a read
READ_ERROR = SiiStatus.COMMAND_ERROR
#: status reads of a busy EEPROM before it counts as not answering
POLLS = 100
#: bytes read back per poll: control/status, address, data (0x0502-0x050F)
_STATUS_AND_DATA = 14

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")


@dataclass(slots=True)
class SiiRead:
    """What was read of one slave's SII: ``info`` has the header as soon as it is read
    (strings and GENERAL once the walk got that far); ``error`` says why the read
    stopped short, else ``None``."""

    info: SiiInfo | None = None
    error: str | None = None
    #: the data of every category (by type, the first of each), where asked for
    categories: dict[int, bytes] = field(default_factory=dict)


_Walk = Generator[int, bytes, None]


def _walk(result: SiiRead, words: SiiWords) -> _Walk:
    result.info = SiiInfo((yield from read_sii_header(words)))
    strings, general, categories = yield from read_sii_names(words)
    result.info = SiiInfo(result.info.header, strings, general, categories)


def _whole_walk(result: SiiRead, words: SiiWords) -> _Walk:
    """:func:`_walk`, then every category's data up to the end marker (FMMU, SYNCM,
    TXPDO, RXPDO, DC, …: what a master configuring from the SII needs)."""
    yield from _walk(result, words)
    address = HEADER_WORDS
    while address < MAX_WORDS:
        kind, length = decode_category_header((yield from words.read(address, 2)))
        if kind == CATEGORY_END or length == 0xFFFF:
            break
        data = yield from words.read(address + 2, length)
        result.categories.setdefault(kind, data)
        address += 2 + length


def read_sii(
    master: Master, addresses: Sequence[int], *, auto_increment: bool, categories: bool = False
) -> list[SiiRead]:
    """The SII of the slaves at ``addresses`` (auto-increment ADPs ``0, 0xFFFF, ...`` or
    station addresses), in their order; with ``categories`` every category's data too
    (:attr:`SiiRead.categories`). Errors are per slave (:class:`SiiRead`); only the
    transport's own failures raise."""
    write, read = _commands(auto_increment)
    configs = master.exchange_many(
        [Datagram.physical(read, a, Register.SII_CONFIG, 1) for a in addresses]
    )
    held = [
        a
        for a, d in zip(addresses, configs, strict=True)
        if d.wkc == 1 and d.data[0] & SiiConfig.PDI_OFFERED
    ]
    results = [SiiRead() for _ in addresses]
    _owner(master, write, held, to_pdi=False)
    try:
        walk = _whole_walk if categories else _walk
        walks = {i: walk(results[i], SiiWords()) for i in range(len(addresses))}
        pending = {i: next(walk) for i, walk in walks.items()}
        while pending:
            asks = [(i, addresses[i], word) for i, word in pending.items()]
            for i, got in _read_words(master, write, read, asks).items():
                if isinstance(got, str):
                    results[i].error = got
                    del pending[i]
                    continue
                try:
                    pending[i] = walks[i].send(got)
                except StopIteration:
                    del pending[i]
                except WireError as exc:
                    results[i].error = f"SII not readable: {exc}"
                    del pending[i]
    finally:
        _owner(master, write, held, to_pdi=True)
    return results


def _owner(master: Master, write: Command, addresses: Sequence[int], *, to_pdi: bool) -> None:
    """Take the EEPROM from the PDI (force, then release the force bit), or give it back."""
    if not addresses:
        return
    for value in [SiiConfig.PDI_OFFERED] if to_pdi else [SiiConfig.FORCE_ECAT, 0]:
        master.exchange_many(
            [Datagram.physical(write, a, Register.SII_CONFIG, bytes([value])) for a in addresses]
        )


def _read_words(
    master: Master, write: Command, read: Command, asks: Sequence[tuple[int, int, int]]
) -> dict[int, bytes | str]:
    """One round: every slave ``(key, address, word)`` reads at its word; the 4 or 8
    bytes read, or why not, by key."""
    out: dict[int, bytes | str] = {}
    commands = [
        Datagram.physical(
            write,
            address,
            Register.SII_CONTROL_STATUS,
            _U16.pack(SiiCommand.READ << SII_COMMAND_SHIFT) + _U32.pack(word),
        )
        for _key, address, word in asks
    ]
    for (key, _address, word), d in zip(asks, master.exchange_many(commands), strict=True):
        if d.wkc != 1:
            out[key] = f"SII read of word 0x{word:X} not taken"
    waiting = [ask for ask in asks if ask[0] not in out]
    for poll in range(POLLS):
        if not waiting:
            break
        if poll:
            master.idle(master.options.poll_ns)
        reads = [
            Datagram.physical(read, address, Register.SII_CONTROL_STATUS, _STATUS_AND_DATA)
            for _key, address, _word in waiting
        ]
        still = []
        for ask, d in zip(waiting, master.exchange_many(reads), strict=True):
            key, _address, word = ask
            status = _U16.unpack_from(d.data)[0] if d.wkc == 1 else SiiStatus.BUSY
            if status & SiiStatus.BUSY:
                still.append(ask)
            elif status & READ_ERROR:
                out[key] = f"SII read of word 0x{word:X}: EEPROM error (status 0x{status:04X})"
            else:
                n = 8 if status & SiiStatus.READ_8_BYTES else 4
                out[key] = bytes(d.data[6 : 6 + n])
        waiting = still
    for key, _address, word in waiting:
        out[key] = f"SII read of word 0x{word:X}: EEPROM stays busy"
    return out


# ------------------------------------------------------------ one slave's whole image
def _image_walk(words: SiiWords) -> Generator[int, bytes, bytes]:
    """The header (64 words), then category after category up to and with the 0xFFFF end
    word (or :data:`~lolacli.wire.sii.MAX_WORDS`): the image as a tool saves it."""
    yield from words.read(0, HEADER_WORDS)
    address = HEADER_WORDS
    while address < MAX_WORDS:
        head = yield from words.read(address, 1)
        if _U16.unpack(head)[0] == CATEGORY_END:
            address += 1
            break
        length = _U16.unpack((yield from words.read(address + 1, 1)))[0]
        yield from words.read(address + 2, length)
        address += 2 + length
    return b"".join(words.words.get(a, b"\xff\xff") for a in range(min(address, MAX_WORDS)))


def read_images(
    master: Master, addresses: Sequence[int], *, auto_increment: bool
) -> list[bytes | str]:
    """Whole SII images (header and categories up to the end marker) of the slaves at
    ``addresses``, all at once as :func:`read_sii` reads; per slave the image or why it
    does not read."""
    write, read = _commands(auto_increment)
    configs = master.exchange_many(
        [Datagram.physical(read, a, Register.SII_CONFIG, 1) for a in addresses]
    )
    held = [
        a
        for a, d in zip(addresses, configs, strict=True)
        if d.wkc == 1 and d.data[0] & SiiConfig.PDI_OFFERED
    ]
    out: list[bytes | str] = ["not read"] * len(addresses)
    _owner(master, write, held, to_pdi=False)
    try:
        walks = {i: _image_walk(SiiWords()) for i in range(len(addresses))}
        pending = {i: next(walk) for i, walk in walks.items()}
        while pending:
            asks = [(i, addresses[i], word) for i, word in pending.items()]
            for i, got in _read_words(master, write, read, asks).items():
                if isinstance(got, str):
                    out[i] = got
                    del pending[i]
                    continue
                try:
                    pending[i] = walks[i].send(got)
                except StopIteration as done:
                    out[i] = bytes(done.value)
                    del pending[i]
    finally:
        _owner(master, write, held, to_pdi=True)
    return out


def read_image(master: Master, address: int, *, auto_increment: bool) -> bytes:
    """One slave's whole SII image; TransportError when the EEPROM does not read."""
    got = read_images(master, [address], auto_increment=auto_increment)[0]
    if isinstance(got, str):
        raise TransportError(got)
    return got


def read_words(
    master: Master, address: int, first_word: int, count: int, *, auto_increment: bool
) -> bytes:
    """``count`` words of one slave's EEPROM from ``first_word``; TransportError when they
    do not read."""

    def walk(words: SiiWords) -> Generator[int, bytes, bytes]:
        return (yield from words.read(first_word, count))

    write, read = _commands(auto_increment)
    held = _held(master, read, address)
    _owner(master, write, held, to_pdi=False)
    try:
        gen = walk(SiiWords())
        word = next(gen)
        while True:
            got = _read_words(master, write, read, [(0, address, word)])[0]
            if isinstance(got, str):
                raise TransportError(got)
            try:
                word = gen.send(got)
            except StopIteration as done:
                return bytes(done.value)
    finally:
        _owner(master, write, held, to_pdi=True)


def write_words(
    master: Master, address: int, first_word: int, data: bytes, *, auto_increment: bool
) -> None:
    """Write ``data`` (whole words) to the EEPROM from word ``first_word``, one word per
    command: the data to 0x0508, then write enable and the write command with the word
    address to 0x0502 in one access (ETG.1000.4 §6.4), polled until not busy.
    TransportError on a missing working counter, a write or command error, or an EEPROM
    that stays busy."""
    if len(data) % 2:
        raise ValueError("SII data is written in whole words")
    write, read = _commands(auto_increment)
    held = _held(master, read, address)
    _owner(master, write, held, to_pdi=False)
    try:
        for i in range(len(data) // 2):
            word = first_word + i
            command = _U16.pack(SiiStatus.WRITE_ENABLE | SiiCommand.WRITE << SII_COMMAND_SHIFT)
            frames = [
                Datagram.physical(write, address, Register.SII_DATA, data[2 * i : 2 * i + 2]),
                Datagram.physical(
                    write, address, Register.SII_CONTROL_STATUS, command + _U32.pack(word)
                ),
            ]
            for d in master.exchange(frames):
                if d.wkc != 1:
                    raise TransportError(f"SII write of word 0x{word:X} not taken")
            _wait(master, read, address, f"SII write of word 0x{word:X}", WRITE_ERROR)
    finally:
        _owner(master, write, held, to_pdi=True)


def reload(master: Master, address: int, *, auto_increment: bool) -> None:
    """Have the ESC reload its configuration area (station alias, PDI configuration) from
    the EEPROM, as at power-up; TransportError when it fails."""
    write, read = _commands(auto_increment)
    held = _held(master, read, address)
    _owner(master, write, held, to_pdi=False)
    try:
        command = _U16.pack(SiiCommand.RELOAD << SII_COMMAND_SHIFT)
        got = master.exchange_one(
            Datagram.physical(write, address, Register.SII_CONTROL_STATUS, command)
        )
        if got.wkc != 1:
            raise TransportError("SII reload not taken")
        _wait(master, read, address, "SII reload", READ_ERROR)
    finally:
        _owner(master, write, held, to_pdi=True)


#: status bits at 0x0502 that fail a write
WRITE_ERROR = SiiStatus.COMMAND_ERROR | SiiStatus.WRITE_ERROR


def _commands(auto_increment: bool) -> tuple[Command, Command]:
    return (Command.APWR, Command.APRD) if auto_increment else (Command.FPWR, Command.FPRD)


def _held(master: Master, read: Command, address: int) -> list[int]:
    got = master.exchange_one(Datagram.physical(read, address, Register.SII_CONFIG, 1))
    if got.wkc != 1:
        raise TransportError("the slave does not answer (SII configuration 0x0500)")
    return [address] if got.data[0] & SiiConfig.PDI_OFFERED else []


def _wait(master: Master, read: Command, address: int, what: str, errors: int) -> None:
    for poll in range(POLLS):
        if poll:
            master.idle(master.options.poll_ns)
        got = master.exchange_one(
            Datagram.physical(read, address, Register.SII_CONTROL_STATUS, 2)
        )
        status = _U16.unpack_from(got.data)[0] if got.wkc == 1 else SiiStatus.BUSY
        if status & SiiStatus.BUSY:
            continue
        if status & errors:
            raise TransportError(f"{what}: EEPROM error (status 0x{status:04X})")
        return
    raise TransportError(f"{what}: EEPROM stays busy")


__all__ = [
    "POLLS",
    "READ_ERROR",
    "WRITE_ERROR",
    "SiiRead",
    "read_image",
    "read_images",
    "read_words",
    "read_sii",
    "reload",
    "write_words",
]
