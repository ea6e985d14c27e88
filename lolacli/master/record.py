"""Recordings of a master's run: pcapng (every frame, both directions) and MCAP.

:class:`PcapngRecorder` is a transport tap: every frame the master sends and every frame
that comes back is one Enhanced Packet Block with a nanosecond timestamp, encoded by
:mod:`lolacli.capture.writer`. :class:`McapRecorder` writes MCAP through the ``mcap``
library: the JSON-schema channels of :mod:`lolacli.capture.mcap_channels` (the ones
``capture export --mcap`` writes): ``/frames`` (every frame, as a transport tap),
``/cycle`` (per-cycle timing, WKC, lost frames), ``/joints`` (per-joint target and actual
position), ``/dc`` (largest system time difference).

Timestamps are wall-clock time (:class:`WallClock`): the transport's clock (virtual in
simulation, monotonic on a live bus) plus the wall-clock time at the first frame or
message, so that tshark shows the day of the run, not 1 January 1970; the messages'
``t_ns`` fields keep the transport's clock.

A run stopped at any moment leaves files that open. A stop (Ctrl-C, SIGTERM) raises a
KeyboardInterrupt between two Python operations, which may be inside a write; so the
recorders note, in one assignment after each write, how many bytes of the file are whole
(pcapng blocks; MCAP records, which the mcap library writes a chunk at a time), and
closing cuts the file there (MCAP: then ends it with a Data End and a footer). Closing
goes on when a stop arrives during it, then raises that stop; and a recorder that was
not closed (a stop before the caller's ``close``) is closed when it is collected, at the
latest when the interpreter exits.
"""

from __future__ import annotations

import base64
import time
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from lolacli.capture import mcap_channels
from lolacli.capture.writer import epb, idb, shb
from lolacli.errors import UsageError


def open_output(path: str | Path) -> IO[bytes]:
    """Open ``path`` for writing; UsageError (exit 2, one line) when it cannot be."""
    try:
        return open(path, "wb")  # noqa: SIM115 - closed by the recorder
    except IsADirectoryError:
        raise UsageError(f"cannot write {path}: is a directory") from None
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None


class WallClock:
    """Wall-clock nanoseconds (since 1970) for a transport's clock: the transport time
    plus the offset between the two at the first reading. Share one between recorders
    so that their timestamps agree."""

    def __init__(self) -> None:
        self.offset_ns: int | None = None

    def __call__(self, t_ns: int) -> int:
        if self.offset_ns is None:
            self.offset_ns = time.time_ns() - t_ns
        return t_ns + self.offset_ns


def _despite_stops(action: Callable[[], None]) -> None:
    """Run ``action`` (idempotent) to its end: a KeyboardInterrupt raised inside it runs
    it again, and is raised once the action has completed."""
    stopped: KeyboardInterrupt | None = None
    while True:
        try:
            action()
        except KeyboardInterrupt as exc:
            stopped = stopped or exc
            continue
        break
    if stopped is not None:
        raise stopped


class _WholeFile:
    """A file written in whole pieces. ``whole`` is (bytes of the file that are whole,
    whether they end it, pieces in them), replaced in one assignment after each piece.
    :meth:`close` is idempotent, so that it can run again after a stop inside it: it cuts
    the file after its whole bytes (a piece a stop left half written goes), writes the
    head again when even that was not whole, then :meth:`end` (the ending the format
    needs)."""

    def __init__(self, head: bytes) -> None:
        self.head = head
        self.file: IO[bytes] | None = None
        self.whole: tuple[int, bool, int] = (0, False, 0)

    def open(self, path: str | Path) -> None:
        self.file = open_output(path)
        self.add(self.head)

    def add(self, data: bytes, last: bool = False) -> None:
        assert self.file is not None
        size, _, pieces = self.whole
        self.file.write(data)
        self.whole = (size + len(data), last, pieces + 1)

    def end(self) -> None:
        """Complete the file after its whole bytes (the pcapng has nothing to add)."""

    def close(self) -> None:
        _despite_stops(self._close)

    def _close(self) -> None:
        f = self.file
        if f is None or f.closed:
            return
        if not self.whole[1]:
            if self.whole[0] < len(self.head):  # stopped before the head was whole
                f.seek(0)
                f.truncate(0)
                f.write(self.head)
                self.whole = (len(self.head), False, 1)
            f.truncate(self.whole[0])  # (flushes first)
            f.seek(self.whole[0])
            self.end()
        f.flush()
        f.close()


class PcapngRecorder:
    """A transport tap writing pcapng (see the module docstring)."""

    def __init__(self, path: str | Path, clock: WallClock | None = None) -> None:
        self.path = str(path)
        self.clock = clock if clock is not None else WallClock()
        self._out = _WholeFile(shb() + idb(tsresol=9, snaplen=0))
        weakref.finalize(self, self._out.close)  # closed when collected, if not before
        self._out.open(path)

    def __call__(self, t_ns: int, frame: bytes, returned: bool) -> None:
        self._out.add(epb(self.clock(t_ns), frame))

    @property
    def frames(self) -> int:
        """Frames in the file: its packet blocks written whole."""
        return max(0, self._out.whole[2] - 1)

    def flush(self) -> None:
        if self._out.file is not None:
            self._out.file.flush()

    def close(self) -> None:
        """Flush and close, cutting off a block a stop left partly written."""
        self._out.close()


class _Sink:
    """What the mcap Writer writes to: held until the recorder moves it to the file."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.base = 0  # file offset of data[0]

    def write(self, data: bytes) -> int:
        self.data += data
        return len(data)

    def tell(self) -> int:
        return self.base + len(self.data)

    def flush(self) -> None:
        pass

    def take(self) -> bytes:
        data = bytes(self.data)
        self.base += len(data)
        self.data.clear()
        return data


class _McapFile(_WholeFile):
    """The MCAP file of a :class:`McapRecorder`: the mcap Writer writes into a
    :class:`_Sink`, and what it wrote in a call that completed (whole records: the
    header, a chunk and its indexes, the summary) goes to the file. After a stop inside
    a Writer call (``busy``) the Writer is in between: closing then ends the file after
    its last whole chunk with a Data End and a footer without summary (the messages of
    the unfinished chunk are lost; readers read the chunks in order). Else closing lets
    the Writer finish: the summary and its indexes."""

    def __init__(self, chunk_bytes: int) -> None:
        from mcap.data_stream import RecordBuilder
        from mcap.records import DataEnd, Footer, Header
        from mcap.writer import MCAP0_MAGIC, Writer

        head, tail = RecordBuilder(), RecordBuilder()
        Header(profile="", library="lolacli").write(head)
        DataEnd(data_section_crc=0).write(tail)
        Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(tail)
        super().__init__(MCAP0_MAGIC + head.end())  # type: ignore[no-untyped-call]
        self.tail = tail.end() + MCAP0_MAGIC  # type: ignore[no-untyped-call]
        self.sink = _Sink()
        self.busy = True  # inside a Writer call, or not started
        self.writer = Writer(self.sink, chunk_size=chunk_bytes)  # type: ignore[arg-type]
        self.channels: dict[str, int] = {}

    def open(self, path: str | Path) -> None:
        self.file = open_output(path)
        writer = self.writer
        writer.start(profile="", library="lolacli")  # the head
        self.channels = mcap_channels.register(writer)  # (into the first chunk)
        self.add(self.sink.take())
        self.busy = False

    def message(self, topic: str, at_ns: int, data: bytes) -> None:
        self.busy = True
        self.writer.add_message(
            channel_id=self.channels[topic], log_time=at_ns, publish_time=at_ns, data=data
        )
        if self.sink.data:
            self.add(self.sink.take())
        self.busy = False

    def _close(self) -> None:
        if self.file is not None and not self.file.closed and not self.busy:
            self.busy = True
            self.writer.finish()  # type: ignore[no-untyped-call]
            self.add(self.sink.take(), last=True)
        super()._close()

    def end(self) -> None:
        assert self.file is not None
        self.file.write(self.tail)
        size, _, pieces = self.whole
        self.whole = (size + len(self.tail), True, pieces + 1)


class McapRecorder:
    """MCAP with JSON channels (see the module docstring and :class:`_McapFile`)."""

    def __init__(self, path: str | Path, clock: WallClock | None = None,
                 chunk_bytes: int = 1 << 20) -> None:
        self.path = str(path)
        self.clock = clock if clock is not None else WallClock()
        self.messages = 0
        self.topics: dict[str, int] = dict.fromkeys(mcap_channels.SCHEMAS, 0)  # messages
        self.frames = 0
        self._out = _McapFile(chunk_bytes)
        weakref.finalize(self, self._out.close)  # closed when collected, if not before
        self._out.open(path)

    def write(self, topic: str, t_ns: int, message: dict[str, Any]) -> None:
        self._out.message(topic, self.clock(t_ns), mcap_channels.encode(message))
        self.messages += 1
        self.topics[topic] += 1

    def __call__(self, t_ns: int, frame: bytes, returned: bool) -> None:
        """A transport tap: every frame sent and received, on ``/frames``."""
        self.frames += 1
        self.write(mcap_channels.FRAMES, t_ns, {
            "frame": self.frames, "t_ns": t_ns, "length": len(frame), "returned": returned,
            "data": base64.b64encode(frame).decode("ascii"),
        })

    def close(self) -> None:
        """Finish the file, or end it after its last whole chunk (see :class:`_McapFile`)."""
        self._out.close()
