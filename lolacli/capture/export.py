"""``capture export --mcap``: a capture as MCAP, the channels of
:mod:`lolacli.capture.mcap_channels` (the ones ``bus simulate --mcap`` writes).

Messages: ``/frames`` one per frame of the file (our reader's frames: Ethernet and Linux
cooked), ``/cycle`` one per answered cyclic frame (round trip and cycle number from the
analysis's pairing, :func:`lolacli.capture.analyze.stream_pairs`; period = time since the
previous answered cyclic frame left; the WKC of each datagram of the returned frame),
``/dc`` one per read of the DC system-time difference (0x092C) answered by a slave. Log
time = the capture timestamp (ns). One read of the file for the frames and one for the
pairs, side by side: memory stays bounded whatever the file's size.

The file is written to a temporary file beside the target and renamed over it at the
end: a failure or a stop leaves nothing (the temporary file is removed).
"""

from __future__ import annotations

import base64
import contextlib
import os
import tempfile
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

from lolacli.capture import mcap_channels as ch
from lolacli.capture.reader import CapturedFrame, CaptureReader, link_header
from lolacli.errors import InputError
from lolacli.interrupt import never

if TYPE_CHECKING:
    from lolacli.capture.analyze import CaptureReport

SCHEMA = "lolacli.capture-export/1"
ETHERTYPE_ECAT = 0x88A4
REG_DC_SYSTIME_DIFF = 0x092C
#: frames remembered for the WKC of a returned frame found later by the pairing
WKC_WINDOW = 1 << 16
#: frames after an outgoing one searched for its answer (timestamps may go backwards)
LOOK_AHEAD = 1024
TOPICS = (ch.FRAMES, ch.CYCLE, ch.DC)


class Stopped(KeyboardInterrupt):
    """The export was stopped (``should_stop``); nothing was written."""


@dataclass(slots=True)
class ExportResult:
    """What was written; :meth:`to_dict` is ``lolacli.capture-export/1``."""

    path: str
    capture: str
    frames: int = 0
    messages: dict[str, int] = field(default_factory=dict)
    bytes: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "mcap": self.path,
            "capture": self.capture,
            "bytes": self.bytes,
            "frames": self.frames,
            "channels": [
                {"topic": t, "schema": ch.SCHEMAS[t]["title"], "messages": n}
                for t, n in self.messages.items()
            ],
            "messages": sum(self.messages.values()),
        }


Datagrams = list[tuple[int, int, int, bytes, int]]


def _decode(frame: CapturedFrame) -> tuple[bool | None, Datagrams]:
    """(returned by the link layer, (cmd, address, wkc, data, index) of each datagram); no
    datagrams for frames that are not EtherCAT or do not decode."""
    from lolacli.errors import WireError
    from lolacli.wire.frame import decode_ecat_payload

    try:
        link = link_header(frame)
    except ValueError:
        return None, []
    if link.ethertype != ETHERTYPE_ECAT:
        return link.returned, []
    try:
        _, _, datagrams, _ = decode_ecat_payload(frame.data, link.payload)
    except WireError:
        return link.returned, []
    return link.returned, [(d.cmd, d.address, d.wkc, d.data, d.index) for d in datagrams]


def _dc_reads(datagrams: Datagrams) -> Iterator[tuple[int, int | None]]:
    """(signed difference ns, station) of each answered APRD/FPRD of 0x092C (the rule of
    the analysis's scanner)."""
    for cmd, address, wkc, data, _ in datagrams:
        ado = address >> 16
        if cmd in (1, 4) and wkc >= 1 and ado <= REG_DC_SYSTIME_DIFF <= ado + len(data) - 4:
            at = REG_DC_SYSTIME_DIFF - ado
            v = int.from_bytes(data[at : at + 4], "little")
            mag = v & 0x7FFFFFFF
            yield (-mag if v & 0x80000000 else mag), (address & 0xFFFF if cmd == 4 else None)


class _Export:
    def __init__(self, report: CaptureReport, out: IO[bytes], result: ExportResult,
                 should_stop: Callable[[], bool]) -> None:
        from mcap.writer import Writer

        self.writer = Writer(out, chunk_size=1 << 20)
        self.writer.start(profile="", library="lolacli")
        self.channels = ch.register(self.writer, TOPICS)
        self.result = result
        self.counts = dict.fromkeys(TOPICS, 0)
        self.frames = iter(CaptureReader(report.path))
        self.should_stop = should_stop
        # frame number -> (timestamp, returned, datagram shape, WKCs) of recent frames
        self.recent: OrderedDict[int, tuple[int, bool | None, tuple[int, ...], list[int]]] = (
            OrderedDict())
        self.cycle = 0
        self.last_sent: int | None = None

    def write(self, topic: str, at_ns: int, message: dict[str, Any]) -> None:
        self.writer.add_message(channel_id=self.channels[topic], log_time=at_ns,
                                publish_time=at_ns, data=ch.encode(message))
        self.counts[topic] += 1

    def frames_until(self, number: int | None) -> None:
        """Write the frames up to frame ``number`` (all when None)."""
        for frame in self.frames:
            returned, datagrams = _decode(frame)
            t = frame.timestamp_ns
            self.write(ch.FRAMES, t, {
                "frame": frame.number, "t_ns": t, "length": frame.original_length,
                "returned": returned, "data": base64.b64encode(frame.data).decode("ascii"),
            })
            if datagrams:
                shape = tuple(d[0] << 24 | d[4] << 16 | len(d[3]) for d in datagrams)
                self.recent[frame.number] = (t, returned, shape, [d[2] for d in datagrams])
                if len(self.recent) > WKC_WINDOW:
                    self.recent.popitem(last=False)
            for error, slave in _dc_reads(datagrams):
                self.write(ch.DC, t, {"t_ns": t, "max_error_ns": abs(error), "error_ns": error,
                                      "station": slave})
            if number is not None and frame.number >= number:
                return
            if frame.number % 4096 == 0 and self.should_stop():
                raise Stopped

    def pairs(self, frames_read: int, rt: np.ndarray, at: np.ndarray, meta: np.ndarray) -> None:
        self.frames_until(frames_read)
        for r, t, m in zip(rt.tolist(), at.tolist(), meta.tolist(), strict=True):
            if not m & 1:
                continue
            sent, out_frame = t - r, m >> 1
            period = None if self.last_sent is None else sent - self.last_sent
            wkc = self._returned_wkc(out_frame, t)
            self.write(ch.CYCLE, t, {
                "cycle": self.cycle, "t_ns": sent, "frame": out_frame, "round_trip_ns": r,
                "period_ns": period, "wkc": wkc,
            })
            self.cycle += 1
            self.last_sent = sent

    def _returned_wkc(self, out_frame: int, at_ns: int) -> list[int] | None:
        """The WKCs of the frame that answered frame ``out_frame`` at ``at_ns``: the first
        frame after it at that time with its datagrams (commands, lengths), one the link
        layer says returned first."""
        sent = self.recent.get(out_frame)
        if sent is None:
            return None
        found = None
        for n in range(out_frame + 1, out_frame + 1 + LOOK_AHEAD):
            got = self.recent.get(n)
            if got is None:  # not EtherCAT, or not read yet
                continue
            if got[0] == at_ns and got[2] == sent[2]:
                if got[1] is not False:
                    return got[3]
                found = found or got[3]
        return found

    def finish(self) -> None:
        self.frames_until(None)
        self.writer.finish()  # type: ignore[no-untyped-call]
        self.result.messages = self.counts
        self.result.frames = self.counts[ch.FRAMES]


def _temporary(path: Path) -> tuple[IO[bytes], str]:
    """A new file beside ``path`` to write it into; InputError (exit 3) when the folder
    cannot take it or ``path`` is a folder."""
    if path.is_dir():
        raise InputError("is a directory", path=str(path))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part",
                                   dir=path.parent if str(path.parent) else ".")
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", path=str(path)) from None
    return os.fdopen(fd, "wb"), tmp


def check_target(path: str | Path) -> None:
    """InputError (exit 3) when ``path`` cannot be written (tried with a temporary file
    beside it, removed at once)."""
    out, tmp = _temporary(Path(path))
    out.close()
    os.unlink(tmp)


def export_mcap(report: CaptureReport, path: str | Path, *, engine: str = "auto",
                should_stop: Callable[[], bool] = never) -> ExportResult:
    """Write ``report``'s capture to ``path`` as MCAP (see the module docstring).
    ``should_stop()`` is polled while the file is read; when it says stop, nothing is left
    behind and :class:`Stopped` is raised. InputError (exit 3) when ``path`` cannot be
    written."""
    from lolacli.capture.analyze import stream_pairs

    target = Path(path)
    result = ExportResult(path=str(target), capture=report.path)
    out, tmp = _temporary(target)
    try:
        with out:
            export = _Export(report, out, result, should_stop)
            stream_pairs(report, export.pairs, engine=engine, should_stop=should_stop)
            if should_stop():
                raise Stopped
            export.finish()
            out.flush()
            os.fsync(out.fileno())
        result.bytes = os.path.getsize(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise InputError(f"cannot write: {exc.strerror or exc}", path=str(target)) from None
        raise
    return result


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


__all__ = ["SCHEMA", "ExportResult", "Stopped", "check_target", "export_mcap"]
