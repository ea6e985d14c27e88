"""The emulator's reply times, seen from the master's side of the veth pair.

A real master's own verdict mixes two things: whether the slaves answered in time, and
whether the master's process was running when they did. KickCAT, for one, polls its
socket with a 20 µs sleep and gives up when a sleep ends past its deadline, without a last
look at the socket; on a loaded host such a sleep can last milliseconds while the answer
waits in the socket buffer. :class:`MasterCapture` records the master's side with dumpcap
(kernel timestamps, CLOCK_REALTIME; Linux cooked v2, so the kernel's packet type tells each
frame's direction, which a master's MAC may not) so a test can judge the emulator strictly
on its own (every frame answered once, each within the master's deadline, the latency
percentiles) and tell a master's time-out from a late answer
(:meth:`CaptureReport.late_in`).
"""

from __future__ import annotations

import itertools
import os
import re
import shutil
import struct
import subprocess
import tempfile
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ETHERTYPE_ECAT = 0x88A4  # lolacli.wire.frame's, without importing lolacli here
_SLL2_IFINDEX = struct.Struct(">I")  # Linux cooked v2: the interface index at byte 4


@dataclass(frozen=True, slots=True)
class Exchange:
    sent_ns: int  # the master's frame on the wire (kernel timestamp, CLOCK_REALTIME)
    reply_ns: int | None  # its answer, None: none came
    kind: str  # the frame's commands, e.g. "FPRD" or "FRMW+LRW"

    @property
    def latency_ns(self) -> int | None:
        return None if self.reply_ns is None else self.reply_ns - self.sent_ns


@dataclass(slots=True)
class CaptureReport:
    exchanges: list[Exchange] = field(default_factory=list)
    #: answers (frames that came back to the master) with no request of theirs pending:
    #: kernel timestamps. Told only in a capture whose link layer gives the direction.
    orphans: list[int] = field(default_factory=list)

    def between(self, start_ns: int, end_ns: int) -> list[Exchange]:
        return [e for e in self.exchanges if start_ns <= e.sent_ns <= end_ns]

    def unanswered(self) -> list[Exchange]:
        return [e for e in self.exchanges if e.reply_ns is None]

    def late_in(self, start_ns: int, end_ns: int, deadline_ns: int) -> list[Exchange]:
        """Frames sent in the window whose answer did not come within ``deadline_ns``."""
        return [
            e
            for e in self.between(start_ns, end_ns)
            if e.latency_ns is None or e.latency_ns > deadline_ns
        ]

    def longest_silence_ns(self, start_ns: int, end_ns: int) -> int:
        """The longest time between two frames the master sent in the window."""
        sent = [e.sent_ns for e in self.between(start_ns, end_ns)]
        return max((b - a for a, b in itertools.pairwise(sent)), default=0)

    def percentile_ns(self, p: float, exchanges: list[Exchange] | None = None) -> int:
        values = sorted(
            e.latency_ns for e in (exchanges or self.exchanges) if e.latency_ns is not None
        )
        return values[min(len(values) - 1, int(p * len(values)))] if values else 0

    def summary(self) -> str:
        by_kind: dict[str, list[Exchange]] = {}
        for e in self.exchanges:
            by_kind.setdefault(e.kind, []).append(e)
        parts = []
        for kind, group in sorted(by_kind.items(), key=lambda kv: -len(kv[1])):
            parts.append(
                f"{kind} n={len(group)} p50={self.percentile_ns(0.5, group) / 1000:.0f} "
                f"p99={self.percentile_ns(0.99, group) / 1000:.0f} "
                f"max={self.percentile_ns(1.0, group) / 1000:.0f} µs"
            )
        return "; ".join(parts)


def read_exchanges(path: Path, ifindex: int | None = None) -> list[Exchange]:
    """The request/answer pairs of a master-side capture (:func:`read_capture`)."""
    return read_capture(path, ifindex).exchanges


def read_capture(path: Path, ifindex: int | None = None) -> CaptureReport:
    """Request/answer pairs of a master-side capture.

    Linux cooked v2 (what :class:`MasterCapture` records): the kernel's packet type tells
    a frame the master sent from one that came back, and ``ifindex`` keeps the master's
    interface. A frame that comes back answers the oldest pending one with the same
    command/index/length sequence; a frame sent again while its first copy waits is a
    copy of its own (a master that re-sends, as SOEM after its time-out, gets the late
    answer paired with the first); an answer with nothing pending is an orphan.

    Ethernet: the direction is guessed. The answer to a pending frame is the next one
    with the same command/index/length sequence whose source MAC's local bit, a working
    counter or an ADP differs (a master whose own MAC has the local bit set, as
    KickCAT's, is told by the WKC/ADP an ESC changes); an identical frame is the master
    sending again, the first copy unanswered."""
    from lolacli.capture.reader import (
        LINKTYPE_ETHERNET,
        LINKTYPE_LINUX_SLL2,
        iter_frames,
        link_header,
    )
    from lolacli.errors import WireError
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import decode_ecat_payload

    def kind_of(datagrams: tuple[Any, ...]) -> str:
        names: list[str] = []
        for d in datagrams:
            try:
                name = Command(d.cmd).name
            except ValueError:
                name = f"0x{d.cmd:02X}"
            if name not in names:
                names.append(name)
        return "+".join(sorted(names))

    guessed: dict[tuple[tuple[int, int, int], ...], tuple[int, bytes, tuple[int, ...], str]] = {}
    waiting: dict[tuple[tuple[int, int, int], ...], deque[tuple[int, str]]] = {}
    report = CaptureReport()
    out = report.exchanges
    for frame in iter_frames(path):
        if frame.link_type not in (LINKTYPE_ETHERNET, LINKTYPE_LINUX_SLL2):
            continue
        try:
            link = link_header(frame)
            if link.ethertype != ETHERTYPE_ECAT:
                continue
            datagrams = decode_ecat_payload(frame.data, link.payload)[2]
        except (ValueError, WireError):
            continue
        key = tuple((d.cmd, d.index, len(d.data)) for d in datagrams)
        if frame.link_type == LINKTYPE_LINUX_SLL2:
            if ifindex is not None and _SLL2_IFINDEX.unpack_from(frame.data, 4)[0] != ifindex:
                continue
            if link.returned:
                queue = waiting.get(key)
                if not queue:
                    report.orphans.append(frame.timestamp_ns)
                    continue
                sent_ns, kind = queue.popleft()
                out.append(Exchange(sent_ns, frame.timestamp_ns, kind))
            else:
                waiting.setdefault(key, deque()).append((frame.timestamp_ns, kind_of(datagrams)))
            continue
        fields = tuple(v for d in datagrams for v in (d.wkc, d.adp))
        first = guessed.get(key)
        if first is not None:
            if (frame.data[6] ^ first[1][6]) & 0x02 or fields != first[2]:
                del guessed[key]
                out.append(Exchange(first[0], frame.timestamp_ns, first[3]))
                continue
            out.append(Exchange(first[0], None, first[3]))  # sent again
        guessed[key] = (frame.timestamp_ns, frame.data[:12], fields, kind_of(datagrams))
    out += [Exchange(t, None, kind) for t, _mac, _fields, kind in guessed.values()]
    out += [Exchange(t, None, kind) for queue in waiting.values() for t, kind in queue]
    out.sort(key=lambda e: e.sent_ns)
    return report


class MasterCapture:
    """dumpcap on the master's interface while the block runs; ``report()`` afterwards.
    Skips (``available``: False) where dumpcap is missing."""

    def __init__(self, iface: str) -> None:
        self.iface = iface
        self.available = shutil.which("dumpcap") is not None
        self._folder = tempfile.TemporaryDirectory(prefix="lolacli-master-capture-")
        self.path = Path(self._folder.name) / "master.pcapng"
        self._proc: subprocess.Popen[bytes] | None = None
        #: packets the capture itself lost (dumpcap's count at the end; None: not told)
        self.dropped: int | None = None
        self.ifindex: int | None = None  # the master's interface (known once capturing)

    def __enter__(self) -> MasterCapture:
        if not self.available:
            return self
        # counts at the end go to a file (-q would hide the drops; a pipe could fill);
        # a 32 MiB kernel buffer so a starved dumpcap loses nothing
        self._log = open(Path(self._folder.name) / "dumpcap.log", "wb")  # noqa: SIM115
        # Linux cooked v2 on "any": the kernel's packet type gives each frame's direction
        # (a master's MAC may have the local bit set, as KickCAT's); the filter keeps the
        # master's interface (its peer may be in this namespace too)
        self.ifindex = int(Path(f"/sys/class/net/{self.iface}/ifindex").read_text())
        only = f"ifindex {self.ifindex} and ether proto 0x{ETHERTYPE_ECAT:04x}"
        self._proc = subprocess.Popen(
            ["dumpcap", "-B", "32", "-i", "any", "-y", "LINUX_SLL2", "-f", only]
            + ["-w", str(self.path)],
            stdout=subprocess.DEVNULL,
            stderr=self._log,
        )
        deadline = time.monotonic() + 10
        # capturing once the file holds its section header and interface description
        while time.monotonic() < deadline:
            if self.path.exists() and self.path.stat().st_size > 0:
                break
            if self._proc.poll() is not None:
                break
            time.sleep(0.02)
        time.sleep(0.3)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._proc is not None:
            time.sleep(0.2)  # the last answers reach the capture
            self._proc.terminate()
            self._proc.wait(timeout=20)
            self._proc = None
            self._log.close()
            text = (Path(self._folder.name) / "dumpcap.log").read_text(errors="replace")
            found = re.search(r"received/dropped on interface '[^']*': (\d+)/(\d+)", text)
            self.dropped = int(found.group(2)) if found else None

    def report(self) -> CaptureReport:
        if not self.available or not self.path.exists():
            return CaptureReport()
        return read_capture(self.path, self.ifindex)

    def close(self) -> None:
        """dumpcap stopped (when the block was left early) and the capture removed; kept
        first, with dumpcap's counts, in ``$LOLACLI_KEEP_CAPTURES`` where that is set (a
        loop of runs keeps them to look into a failed verdict afterwards)."""
        self.__exit__()
        keep = os.environ.get("LOLACLI_KEEP_CAPTURES")
        if keep and self.path.exists():
            test = os.environ.get("PYTEST_CURRENT_TEST", "capture").split(" ")[0]
            stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", test.split("::")[-1])
            folder = Path(keep)
            folder.mkdir(parents=True, exist_ok=True)
            stamp = time.strftime("%H%M%S")
            shutil.copy(self.path, folder / f"{stem}-{stamp}.pcapng")
            log = Path(self._folder.name) / "dumpcap.log"
            if log.exists():
                shutil.copy(log, folder / f"{stem}-{stamp}.dumpcap.log")
        self._folder.cleanup()


def realtime_ns() -> int:
    """The capture's clock (kernel packet timestamps are CLOCK_REALTIME)."""
    return time.time_ns()
