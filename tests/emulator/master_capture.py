"""The emulator's reply times, seen from the master's side of the veth pair.

A real master's own verdict mixes two things: whether the slaves answered in time, and
whether the master's process was running when they did. KickCAT, for one, polls its
socket with a 20 µs sleep and gives up when a sleep ends past its deadline, without a last
look at the socket; on a loaded host such a sleep can last milliseconds while the answer
waits in the socket buffer. :class:`MasterCapture` records the master's side with dumpcap
(kernel timestamps, CLOCK_REALTIME) so a test can judge the emulator strictly on its own
(every frame answered, each within the master's deadline, the latency percentiles) and
tell a master's time-out from a late answer (:meth:`CaptureReport.late_in`).
"""

from __future__ import annotations

import itertools
import os
import re
import shutil
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from tests.live import on_all_cpus

MARKER_ETHERTYPE = b"\x88\xb5"  # IEEE 802 local experimental ethertype 1


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


def read_exchanges(path: Path) -> list[Exchange]:
    """Request/answer pairs of a master-side capture. The answer to a pending frame is the
    next one with the same command/index/length sequence whose source MAC's local bit,
    a working counter or an ADP differs (a master whose own MAC has the local bit set,
    as KickCAT's, is told by the WKC/ADP an ESC changes); an identical frame is the
    master sending again, the first copy unanswered."""
    from lolacli.capture.reader import iter_frames
    from lolacli.errors import WireError
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import decode_frame

    pending: dict[tuple[tuple[int, int, int], ...], tuple[int, bytes, tuple[int, ...], str]] = {}
    out: list[Exchange] = []
    for frame in iter_frames(path):
        try:
            datagrams = decode_frame(frame.data).datagrams
        except WireError:
            continue
        key = tuple((d.cmd, d.index, len(d.data)) for d in datagrams)
        fields = tuple(v for d in datagrams for v in (d.wkc, d.adp))
        first = pending.get(key)
        if first is not None:
            if (frame.data[6] ^ first[1][6]) & 0x02 or fields != first[2]:
                del pending[key]
                out.append(Exchange(first[0], frame.timestamp_ns, first[3]))
                continue
            out.append(Exchange(first[0], None, first[3]))  # sent again
        names: list[str] = []
        for d in datagrams:
            try:
                name = Command(d.cmd).name
            except ValueError:
                name = f"0x{d.cmd:02X}"
            if name not in names:
                names.append(name)
        pending[key] = (frame.timestamp_ns, frame.data[:12], fields, "+".join(sorted(names)))
    out += [Exchange(t, None, kind) for t, _mac, _fields, kind in pending.values()]
    out.sort(key=lambda e: e.sent_ns)
    return out


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

    def __enter__(self) -> MasterCapture:
        if not self.available:
            return self
        # counts at the end go to a file (-q would hide the drops; a pipe could fill);
        # a 32 MiB kernel buffer so a starved dumpcap loses nothing
        self._log = open(Path(self._folder.name) / "dumpcap.log", "wb")  # noqa: SIM115
        self._proc = subprocess.Popen(
            ["dumpcap", "-B", "32", "-i", self.iface, "-w", str(self.path)],
            stdout=subprocess.DEVNULL,
            stderr=self._log,
            preexec_fn=on_all_cpus,  # not on the master's core
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
            self._flush()
            self._proc.terminate()
            self._proc.wait(timeout=20)
            self._proc = None
            self._log.close()
            text = (Path(self._folder.name) / "dumpcap.log").read_text(errors="replace")
            found = re.search(r"received/dropped on interface '[^']*': (\d+)/(\d+)", text)
            self.dropped = int(found.group(2)) if found else None

    def _flush(self, timeout_s: float = 10.0) -> None:
        """Wait until everything the interface carried so far is in the file: a marker
        frame (a local experimental ethertype, which no EtherCAT socket takes) sent last
        and seen in the file. dumpcap stopped soon after the traffic loses what the kernel
        has not handed it yet (600 frames on a veth: none kept when stopped at once,
        256-342 when 300 frames came over 300 ms and it stopped 0-20 ms after the last);
        the fixed 0.2 s wait this replaces lost the answer to KickCAT's last frame in a
        loop run of the whole file. Where the marker cannot be sent (the interface gone),
        the fixed wait again."""
        marker = os.urandom(16)
        frame = b"\xff" * 6 + b"\x02\x00\x00\x00\x00\x01" + MARKER_ETHERTYPE + marker
        try:
            with socket.socket(socket.AF_PACKET, socket.SOCK_RAW) as sock:
                sock.bind((self.iface, 0))
                sock.send(frame.ljust(60, b"\0"))
        except OSError:
            time.sleep(0.2)
            return
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and self._proc is not None:
            time.sleep(0.05)
            if not self.path.exists():
                continue
            size = self.path.stat().st_size
            with open(self.path, "rb") as f:
                f.seek(max(0, size - (1 << 20)))
                if marker in f.read():
                    return

    def report(self) -> CaptureReport:
        if not self.available or not self.path.exists():
            return CaptureReport()
        return CaptureReport(read_exchanges(self.path))

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
