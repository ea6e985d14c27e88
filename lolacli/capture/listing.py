"""``capture list``: one entry per EtherCAT frame and datagram, mailbox/CoE/SDO decoded.

Per-frame Python decoding (:func:`lolacli.wire.frame.decode_frame`) over the streaming
reader: meant for reading a capture, not for throughput (use ``capture analyze``).

Filter syntax (``--filter``): terms separated by spaces or commas, all of which must hold
for a datagram to be listed (frames with no listed datagram are left out):

* command mnemonics: ``LRW``; several, joined by ``|`` or as terms of their own
  (``fprd|fpwr``, ``fprd fpwr``), are one term: the datagram is any of them;
* ``adp=N``, ``ado=N`` (0..0xFFFF), ``lad=N`` (logical address, 0..0xFFFFFFFF), ``idx=N``
  (0..0xFF), ``wkc=N``, ``wkc!=N`` (0..0xFFFF), decimal or 0x hex; a value outside its
  field's range is a usage error;
* ``mailbox`` (any mailbox message), ``coe``, ``sdo`` (SDO and SDO Information);
* ``out`` or ``ret``: the frame's direction (one: ``out ret`` is a usage error).
"""


from __future__ import annotations

import textwrap
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lolacli.capture.reader import CaptureReader, link_header
from lolacli.errors import UsageError, WireError
from lolacli.text import station
from lolacli.wire.coe import CoeService, decode_coe_header
from lolacli.wire.commands import LOGICAL, Command, mnemonic
from lolacli.wire.frame import (
    ETHERTYPE_ECAT,
    Datagram,
    decode_ecat_payload,
)
from lolacli.wire.mailbox import MailboxType, decode_mailbox
from lolacli.wire.sdo import (
    SdoAbort,
    SdoDownloadRequest,
    SdoDownloadResponse,
    SdoDownloadSegmentRequest,
    SdoDownloadSegmentResponse,
    SdoInitiate,
    SdoSegment,
    SdoUploadRequest,
    SdoUploadResponse,
    SdoUploadSegmentRequest,
    SdoUploadSegmentResponse,
    abort_text,
    decode_sdo,
)

_MAILBOX_CMDS = (Command.APRD, Command.APWR, Command.FPRD, Command.FPWR)

_SDO_NAMES: dict[type, str] = {
    SdoUploadRequest: "upload req",
    SdoUploadResponse: "upload resp",
    SdoDownloadRequest: "download req",
    SdoDownloadResponse: "download resp",
    SdoUploadSegmentRequest: "upload segment req",
    SdoUploadSegmentResponse: "upload segment resp",
    SdoDownloadSegmentRequest: "download segment req",
    SdoDownloadSegmentResponse: "download segment resp",
}


@dataclass(frozen=True, slots=True)
class ListedDatagram:
    cmd: str
    index: int
    adp: int | None
    ado: int | None
    logical_address: int | None
    length_bytes: int
    wkc: int
    info: str  # mailbox/CoE/SDO summary, "" when none
    kind: str  # "", "mailbox", "coe", "sdo"

    def to_dict(self) -> dict[str, Any]:
        return {
            "cmd": self.cmd, "idx": self.index, "adp": self.adp, "ado": self.ado,
            "logical_address": self.logical_address, "length_bytes": self.length_bytes,
            "wkc": self.wkc, "info": self.info or None,
        }


@dataclass(frozen=True, slots=True)
class ListedFrame:
    number: int
    time_s: float  # since the first frame of the file
    direction: str  # "out" | "ret"
    datagrams: tuple[ListedDatagram, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "number": self.number, "time_s": self.time_s, "direction": self.direction,
            "datagrams": [d.to_dict() for d in self.datagrams],
        }


def describe_mailbox(data: bytes) -> tuple[str, str]:
    """``(summary, kind)`` of a mailbox message, or ``("", "")`` when it is none."""
    try:
        mailbox = decode_mailbox(data)
    except WireError:
        return "", ""
    mtype = mailbox.header.mailbox_type
    name = mtype.name if isinstance(mtype, MailboxType) else f"type {int(mtype)}"
    if mtype != MailboxType.CoE:
        return f"Mbx {name} {mailbox.header.length} B", "mailbox"
    try:
        service = decode_coe_header(mailbox.payload).service
    except WireError:
        return "CoE (truncated)", "coe"
    if service not in (CoeService.SDO_REQUEST, CoeService.SDO_RESPONSE, CoeService.SDO_INFO):
        sname = service.name if isinstance(service, CoeService) else str(int(service))
        return f"CoE {sname}", "coe"
    try:
        message = decode_sdo(mailbox.payload)
    except WireError as e:
        return f"CoE SDO ({e.message})", "sdo"
    return "CoE " + _describe_sdo(message), "sdo"


def _describe_sdo(message: object) -> str:
    if isinstance(message, SdoAbort):
        return (f"SDO abort 0x{message.index:04X}:{message.subindex:02X} "
                f"code 0x{message.code:08X} ({abort_text(message.code)})")
    name = _SDO_NAMES.get(type(message))
    if name is None:
        return f"SDO Info {type(message).__name__}"
    text = f"SDO {name}"
    index, subindex = getattr(message, "index", None), getattr(message, "subindex", 0)
    if index is not None:
        text += f" 0x{index:04X}:{subindex:02X}"
    if isinstance(message, SdoInitiate):
        if message.expedited:
            text += f" expedited {len(message.data)} B 0x{message.data.hex() or '0'}"
        elif isinstance(message, SdoUploadResponse | SdoDownloadRequest):
            text += f" size {message.complete_size} B"
    if isinstance(message, SdoSegment):
        text += f" {len(message.data)} B" + (" last" if message.last else "")
    return text


def _listed(d: Datagram, returned: bool) -> ListedDatagram:
    logical = d.cmd in LOGICAL
    info, kind = "", ""
    mailbox_like = d.cmd in _MAILBOX_CMDS and d.ado >= 0x1000 and len(d.data) >= 8
    readable = not (d.cmd in (Command.APRD, Command.FPRD) and (not returned or d.wkc == 0))
    if mailbox_like and readable:
        info, kind = describe_mailbox(d.data)
    return ListedDatagram(
        cmd=d.mnemonic, index=d.index, adp=None if logical else d.adp,
        ado=None if logical else d.ado, logical_address=d.address if logical else None,
        length_bytes=len(d.data), wkc=d.wkc, info=info, kind=kind,
    )


#: the filter's numeric fields and their largest values (the datagram header's widths)
FIELD_MAX = {"adp": 0xFFFF, "ado": 0xFFFF, "lad": 0xFFFF_FFFF, "idx": 0xFF, "wkc": 0xFFFF}


class DatagramFilter:
    """A parsed ``--filter`` expression (see the module docstring)."""

    def __init__(self, expr: str | None) -> None:
        self.cmds: set[str] | None = None
        self.fields: list[tuple[str, str, int]] = []
        self.kinds: set[str] = set()
        self.direction: str | None = None
        for term in (expr or "").replace(",", " ").split():
            self._term(term)

    def _term(self, term: str) -> None:
        low = term.lower()
        if low in ("out", "ret"):
            if self.direction not in (None, low):
                raise UsageError(f"filter terms {self.direction} and {low} contradict: a "
                                 "frame has one direction")
            self.direction = low
        elif low in ("mailbox", "coe", "sdo"):
            self.kinds.add(low)
        elif "!=" in low or "=" in low:
            op = "!=" if "!=" in low else "="
            name, _, value = low.partition(op)
            if name not in FIELD_MAX:
                raise UsageError(f"unknown filter field {name!r} (adp, ado, lad, idx, wkc)")
            try:
                number = int(value, 0)
            except ValueError as e:
                raise UsageError(f"bad number in filter term {term!r}") from e
            if not 0 <= number <= FIELD_MAX[name]:
                raise UsageError(f"filter term {term!r}: {name} is 0..0x{FIELD_MAX[name]:X}")
            self.fields.append((name, op, number))
        else:
            names = {n.upper() for n in low.split("|")}
            known = {c.name for c in Command}
            if not names <= known:
                raise UsageError(f"unknown filter term {term!r}: not a command mnemonic, "
                                 "field test or mailbox/coe/sdo/out/ret")
            self.cmds = (self.cmds or set()) | names

    def frame_ok(self, direction: str) -> bool:
        return self.direction is None or self.direction == direction

    def datagram_ok(self, d: ListedDatagram) -> bool:
        if self.cmds is not None and d.cmd not in self.cmds:
            return False
        if "mailbox" in self.kinds and not d.kind:
            return False
        if "coe" in self.kinds and d.kind not in ("coe", "sdo"):
            return False
        if "sdo" in self.kinds and d.kind != "sdo":
            return False
        values = {"adp": d.adp, "ado": d.ado, "lad": d.logical_address, "idx": d.index,
                  "wkc": d.wkc}
        for name, op, value in self.fields:
            if (values[name] == value) != (op == "="):
                return False
        return True


def list_frames(
    path: str | Path, *, count: int | None = None, expr: str | None = None
) -> Iterator[ListedFrame]:
    """The EtherCAT frames of a capture (at most ``count`` listed), filtered by ``expr``.
    A bad ``count`` or ``expr`` and a file that is no capture raise here, before the
    first frame is asked for."""
    if count is not None and count < 0:
        raise UsageError(f"count {count}: must be >= 0")
    return _frames(CaptureReader(path), DatagramFilter(expr), count)


def _frames(reader: CaptureReader, flt: DatagramFilter, count: int | None
            ) -> Iterator[ListedFrame]:
    shown = 0
    first_ns: int | None = None
    for frame in reader:
        if first_ns is None:
            first_ns = frame.timestamp_ns
        if count is not None and shown >= count:
            return
        try:
            link = link_header(frame)
            if link.ethertype != ETHERTYPE_ECAT:
                continue
            _, _, datagrams, _ = decode_ecat_payload(frame.data, link.payload)
        except (WireError, ValueError):
            continue
        direction = "ret" if link.returned else "out"
        if not datagrams or not flt.frame_ok(direction):
            continue
        listed = tuple(
            x for x in (_listed(d, link.returned) for d in datagrams) if flt.datagram_ok(x)
        )
        if listed:
            shown += 1
            yield ListedFrame(
                frame.number, (frame.timestamp_ns - first_ns) / 1e9, direction, listed
            )


_CONFIGURED = ("FPRD", "FPWR", "FPRW", "FRMW")  # adp is a station address
#: where a datagram's summary starts (after number, time and direction)
HEAD_COLUMNS = 24


def format_lines(frame: ListedFrame, d: ListedDatagram, first: bool, width: int = 80
                 ) -> list[str]:
    """The text of one datagram, like tshark's summary: number, time, direction (on the
    frame's first datagram), command, index, address, length, WKC; then the mailbox
    summary, on the same line when it fits in ``width`` columns, else on lines of its own
    below, wrapped between words."""
    head = (f"{frame.number:>7} {frame.time_s:>10.6f} s {frame.direction:<3}" if first
            else " " * HEAD_COLUMNS)
    if d.logical_address is not None:
        where = f"lad=0x{d.logical_address:08X}"
    elif d.cmd in _CONFIGURED:
        where = f"adp={station(d.adp or 0)} ado=0x{d.ado or 0:04X}"
    else:
        where = f"adp=0x{d.adp or 0:04X} ado=0x{d.ado or 0:04X}"
    text = f"{head} {d.cmd:<4} idx=0x{d.index:02X} {where} {d.length_bytes:>4} B wkc={d.wkc}"
    if not d.info:
        return [text]
    if len(text) + 2 + len(d.info) <= width:
        return [f"{text}  {d.info}"]
    indent = " " * (HEAD_COLUMNS + 1)
    return [text, *textwrap.wrap(d.info, max(width, len(indent) + 20), initial_indent=indent,
                                 subsequent_indent=indent, break_long_words=False,
                                 break_on_hyphens=False)]


__all__ = ["DatagramFilter", "ListedFrame", "describe_mailbox", "format_lines", "list_frames",
           "mnemonic"]
