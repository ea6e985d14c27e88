"""Capture analysis: one streaming pass of the scanner, then statistics and verdicts.

:func:`analyze_file` maps the capture a window at a time (the C engine on a regular file)
or reads it in bounded chunks into one reusable buffer (:mod:`lolacli.capture.source`),
and lets :func:`lolacli.capture.scan.scan` (its C twin when built) walk the records.
The scanner pairs frames, counts commands, counts the working counters and AL states it
sees and tracks DC drift compensation as it goes; the rare mailbox datagrams and
configuration writes it flags are decoded here in Python (:mod:`lolacli.capture.sdo`,
:mod:`lolacli.capture.layout`). Verdicts are drawn once the whole file is read
(:mod:`lolacli.capture.wkc`, :mod:`lolacli.capture.verdict`), because their references
(median round trip, expected WKC) need all of it. Definitions follow docs/architecture.md
(Direction, Pairing, Cyclic stream, Expected WKC, Lost frame, WKC verdict, Timestamp
quality); the JSON shape is ``lolacli.capture/1``.

Passes: the first takes the direction from the link layer (packet type of Linux cooked
captures, else the source MAC). When that makes every frame go one way, a second pass
infers the direction from the frames themselves and is kept when it pairs any. Cyclic
stream: outgoing frames that carry a logical (LRD/LWR/LRW) datagram; when there are none,
the outgoing frames with the most frequent (command, address key) sequence, found by one
more pass.

A small capture (up to :data:`SMALL_BYTES`, not asked for its series) is analysed
without numpy: the C scanner's tables are ``array.array`` and the rows it drains Python
lists, which costs less than importing numpy (~100 ms of a short command's start-up);
a larger one drains into numpy arrays. Both give the same figures, to the last bit
(the statistics are exact integer sums and order statistics either way).
"""

from __future__ import annotations

import dataclasses
import os
import threading
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from itertools import compress
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from lolacli.capture import scan as S
from lolacli.capture.counters import CounterReads, CounterTracker
from lolacli.capture.fast import choose_engine, kernels
from lolacli.capture.layout import AlStatusRead, MasterLayout, last_al_status
from lolacli.capture.reader import (
    ANALYSED_LINK_TYPES,
    FORMAT_PCAP,
    PCAP_HEADER_BYTES,
    CaptureReader,
    Interface,
    parse_idb,
)
from lolacli.capture.source import CHUNK_BYTES, MappedSource, Source, open_source
from lolacli.capture.verdict import (
    FAILURE,
    INFO,
    MIN_TIMEOUT_NS,
    WARNING,
    FrameFate,
    fates,
    frame_findings,
    timeout_ns,
    timestamp_findings,
)
from lolacli.capture.wkc import WkcVerdict, eni_slaves_not_mapped, verdict
from lolacli.errors import CaptureError
from lolacli.findings import Finding, Findings, failed, first
from lolacli.findings import verdict as verdict_of
from lolacli.interrupt import never
from lolacli.text import plural, station
from lolacli.timing.stats import Summary, summarize_array, summarize_chunks
from lolacli.wire.commands import mnemonic

if TYPE_CHECKING:
    import numpy as np

    from lolacli.capture.sdo import SdoTracker
    from lolacli.eni.model import Eni

SCHEMA = "lolacli.capture/1"
#: bytes read at a time on the read path (pipes, the Python engine); a mapped file is
#: mapped WINDOW_BYTES at a time (lolacli.capture.source)
CHUNK_BYTES = CHUNK_BYTES
#: The scanner is called on at most this much of a chunk at a time, so that between two
#: calls (where a stop is polled and progress reported) no more than ~10 ms pass with the
#: compiled engine (1-4 GB/s on a mapped file) and ~50 ms with the Python engine (about
#: 5 MB/s).
SLICE_BYTES = 2 * 1024 * 1024
SLICE_BYTES_PYTHON = 256 * 1024
OUT_ROWS = 1 << 14  # > the kernel's minimum (CHECK_EVERY * (MAX_DGRAMS + 2) + ...)
PAIR_SLOTS = 1 << 10  # grows when half full
#: a small capture's (the C engine without numpy): its table of pending frames (DEPTH
#: rows a slot) is then 96 kB, not 384 kB, which a batch of small captures would
#: otherwise allocate and fault in twice a file (~20 us each time)
PAIR_SLOTS_SMALL = 1 << 8
STREAM_SLOTS = 1 << 10
OBS_SLOTS = 1 << 10
#: captures up to this size are analysed without numpy (see the module docstring): their
#: drained rows are at most a few 100,000 Python ints
SMALL_BYTES = 16 * 1024 * 1024

Progress = Callable[[int, int], None]


def _us(summary: Summary | None) -> dict[str, float | int] | None:
    """A summary of ns in the report's µs: ``ns / 1000``, not rounded."""
    return None if summary is None else summary.to_dict(divisor=1000.0, digits=None)


def _jitter(summary: Summary | None) -> dict[str, float] | None:
    """Cycle jitter: std and the largest deviation from the median (µs)."""
    return None if summary is None else summary.jitter(divisor=1000.0)


@dataclass(frozen=True, slots=True)
class CaptureReport:
    """Everything ``capture analyze`` reports; :meth:`to_dict` is ``lolacli.capture/1``."""

    path: str
    format: str
    engine: str
    counts: dict[str, int]
    datagrams_by_cmd: dict[str, int]
    round_trip_stats: Summary | None  # ns
    round_trip_cyclic_stats: Summary | None
    cycle_period_stats: Summary | None
    cyclic_stream: str
    direction_rule: str
    wkc_verdict: WkcVerdict
    fate: FrameFate
    findings: list[Finding]
    unusable_stats: list[str]
    al_status: list[AlStatusRead]
    layout: MasterLayout
    dc: dict[str, Any]
    sdo: SdoTracker
    time_span_ns: int
    interfaces: list[Interface] = field(default_factory=list)
    # stopped (should_stop) before the end of the file: the figures cover the first
    # read_bytes bytes
    interrupted: bool = False
    read_bytes: int | None = None
    # the series themselves, with keep_series (for plots): round trips in return order,
    # their return timestamps, cycle periods
    round_trip_ns: np.ndarray | None = None
    round_trip_at_ns: np.ndarray | None = None
    cycle_period_ns: np.ndarray | None = None
    # the rules of the pass the report is of (direction, cyclic-stream mode, signature):
    # :func:`stream_pairs` reads the file again with them
    rules: tuple[int, int, int] = (S.DIR_AUTO, S.MODE_LOGICAL, 0)
    # the ESC error counters the capture's reads of 0x0300 carry (None: no such reads)
    error_counters: CounterReads | None = None

    @property
    def lost_frames(self) -> int:
        return len(self.fate.lost)

    @property
    def wkc_mismatches(self) -> int:
        return self.wkc_verdict.mismatches

    @property
    def failed(self) -> bool:
        """Whether a finding is a failure (``capture analyze`` exits 1)."""
        return failed(self.findings)

    def to_dict(self) -> dict[str, Any]:
        c = self.counts
        aborts = self.sdo.aborts()
        return {
            "schema": SCHEMA,
            "file": self.path,
            "format": self.format,
            "engine": self.engine,
            "verdict": verdict_of(self.findings),
            "interrupted": self.interrupted,
            "frames_total": c["frames_total"],
            "ecat_frames": c["ecat_frames"],
            "non_ecat_frames": c["non_ecat_frames"],
            "malformed_frames": c["malformed_frames"],
            "datagrams_total": c["datagrams_total"],
            "datagrams_by_cmd": self.datagrams_by_cmd,
            "direction_rule": self.direction_rule,
            "outgoing_frames": c["outgoing_frames"],
            "returned_frames": c["returned_frames"],
            "pairs": c["pairs"],
            "unmatched_outgoing": c["outgoing_frames"] - c["pairs"],
            "unmatched_returned": c["unmatched_returned"],
            "round_trip_us": _us(self.round_trip_stats),
            "round_trip_cyclic_us": _us(self.round_trip_cyclic_stats),
            "cyclic_stream": self.cyclic_stream,
            "cyclic_frames": c["cyclic_frames"],
            # cyclic frames never answered at all (lost or still in flight at the end)
            "cyclic_unmatched": c["cyclic_frames"] - c["cyclic_pairs"],
            "cycle_period_us": _us(self.cycle_period_stats),
            "cycle_jitter_us": _jitter(self.cycle_period_stats),
            "unusable_stats": list(self.unusable_stats),
            "lost_frames": self.lost_frames,
            "late_frames": self.fate.late,
            "in_flight_at_end": len(self.fate.in_flight),
            "timeout_us": self.fate.timeout_ns / 1000.0,
            "timeout_source": self.fate.timeout_source,
            "wkc_mismatches": self.wkc_mismatches,
            "wkc_reference": self.wkc_verdict.reference,
            "wkc_checked": self.wkc_verdict.checked,
            "wkc": self.wkc_verdict.to_dict(),
            "al_status": [
                {"station": None if r.broadcast else r.station, "cmd": mnemonic(r.cmd),
                 "state": r.describe(), "status": r.status, "code": r.code,
                 "answered": r.answered, "last_frame": r.last_frame}
                for r in self.al_status
            ],
            "bus_seen": {
                # every slave increments a broadcast's WKC once: the slaves on the line
                "slaves": c["brd_wkc_max"] or None,
                "slaves_from": "the highest WKC of a BRD/BWR" if c["brd_wkc_max"] else None,
                "cyclic_frame_bytes": c["cyclic_frame_bytes"] or None,
            },
            "master_layout": {
                "stations_assigned": len(self.layout.stations),
                "fmmu_writes": len(self.layout.fmmu_writes),
                "slaves_mapped": len(self.layout.fmmus()),
                "al_requests": len(self.layout.al_requests),
            },
            "timestamp_findings": [f.to_dict() for f in self.findings
                                   if f.kind.startswith("timestamps-") or f.kind == "cut-short"],
            "findings": [f.to_dict() for f in self.findings],
            "sdo_transactions": len(self.sdo.transactions),
            "sdo_aborts": [
                {
                    "index": t.index,
                    "subindex": t.subindex,
                    "code": t.abort_code,
                    "code_hex": f"0x{t.abort_code or 0:08X}",
                    "text": t.to_dict()["abort_text"],
                    "slave": t.slave,
                    "frame": t.end_frame,
                }
                for t in aborts
            ],
            "sdo_transaction_list": [t.to_dict() for t in self.sdo.transactions],
            "mailbox": _mailbox_dict(self.sdo),
            "dc": self.dc,
            "time_span_us": self.time_span_ns / 1000.0,
            "error_counters": self.error_counters.to_dict() if self.error_counters else None,
            "other": {
                "vlan_frames": c["vlan_frames"],
                "udp_frames": c["udp_frames"],
                "non_command_ecat_frames": c["non_command_ecat_frames"],
                "snaplen_cut_frames": c["snaplen_cut_frames"],
                "non_ethernet_packets": c["non_ethernet_packets"],
                "skipped_blocks": c["skipped_blocks"],
            },
        }


def _mailbox_dict(tracker: SdoTracker) -> dict[str, Any]:
    s = tracker.stats
    return {
        "messages": s.messages,
        "repeats": s.repeats,
        "undecodable": s.undecodable,
        "by_type": dict(sorted(s.by_type.items())),
        "coe_by_service": dict(sorted(s.coe_by_service.items())),
        "sdo_info_messages": s.sdo_info_messages,
        "emergencies": s.emergencies,
    }


def analyze_file(
    path: str | Path,
    *,
    eni: Eni | None = None,
    progress: Progress | None = None,
    engine: str = "auto",
    keep_series: bool = False,
    chunk_bytes: int | None = None,
    timeout_ns: int | None = None,
    max_lost: int = 0,
    max_wkc_mismatches: int = 0,
    should_stop: Callable[[], bool] = never,
    mapped: bool = True,
) -> CaptureReport:
    """Analyse a pcap/pcapng file (streaming; bounded memory).

    The C engine maps a regular file a window at a time and reads in place only the
    bytes it analyses (``mapped``; :mod:`lolacli.capture.source`); pipes, other files
    that are not regular, ``mapped=False`` and the Python engine read it in chunks.
    ``chunk_bytes`` is the chunk or the window (default 8 MiB read, 64 MiB mapped).

    ``engine`` is ``"auto"`` (C when built, else Python), ``"c"`` or ``"python"``; both
    give identical results.
    ``progress(done_bytes, total_bytes)`` is called after every slice of the file
    (:data:`SLICE_BYTES`), and ``should_stop()`` polled there: when it says stop, the
    report covers the frames read so far (``interrupted``, a finding ``interrupted``).
    ``keep_series`` keeps the return timestamp of every pair (for plots).
    ``timeout_ns`` replaces the in-flight timeout (10 x the median round trip, >= 1 ms);
    ``max_lost`` and ``max_wkc_mismatches`` are how many lost frames and WKC mismatches
    are still no failure.
    A pipe, ``/dev/stdin`` or another file that is not regular is copied to a temporary
    file first: the analysis reads the file up to three times.
    Raises :class:`~lolacli.errors.CaptureError` for files that are not captures.
    """
    spool = spool_stream(path)
    if spool is not None:
        with spool:
            try:
                report = analyze_file(
                    spool.name, eni=eni, progress=progress, engine=engine,
                    keep_series=keep_series, chunk_bytes=chunk_bytes, timeout_ns=timeout_ns,
                    max_lost=max_lost, max_wkc_mismatches=max_wkc_mismatches,
                    should_stop=should_stop, mapped=mapped)
            except CaptureError as exc:
                raise CaptureError(exc.message, path=str(path), line=exc.line,
                                   offset=exc.offset) from None
        return dataclasses.replace(report, path=str(path))
    reader = CaptureReader(path)  # validates the file header
    eng = choose_engine(engine, os.path.getsize(reader.path))

    def scan_pass(dirmode: int, mode: int, sig: int) -> _Pass:
        p = _Pass(reader, eng, dirmode, mode, sig, keep_series, chunk_bytes, progress,
                  should_stop, mapped)
        p.run()
        if p.shrank:
            # the file shrank under the map: bytes past its new end may have been read as
            # the zeros of its last page. Read it again, as it is now, by read(): the
            # result of a file that changes while it is read is the read path's.
            p = _Pass(reader, eng, dirmode, mode, sig, keep_series, chunk_bytes, progress,
                      should_stop, mapped=False)
            p.run()
        return p

    # a later pass is the first one read again with other rules; once a pass was stopped
    # no other starts, and the stopped one is kept when its rules would be
    run = scan_pass(S.DIR_AUTO, S.MODE_LOGICAL, 0)
    stopped_at = run.stopped_by_signal_at
    st = run.st
    if stopped_at is None and st[S.S_ECAT] > 0 and (st[S.S_OUT] == 0 or st[S.S_RET] == 0):
        inferred = scan_pass(S.DIR_INFER, S.MODE_LOGICAL, 0)
        stopped_at = inferred.stopped_by_signal_at
        if inferred.st[S.S_PAIRS] > 0:
            run = inferred
    if stopped_at is None and run.st[S.S_LOGICAL_OUT] == 0 and run.st[S.S_OUT] > 0:
        run = scan_pass(int(run.st[S.S_DIRMODE]), S.MODE_SIGNATURE, run.top_stream())
        stopped_at = run.stopped_by_signal_at
    report = run.report(eni, timeout_ns, max_lost, max_wkc_mismatches, stopped_at)
    if stopped_at is None:
        report = _counter_findings(report, run.counters.result(eni))
    return report


def _counter_findings(report: CaptureReport, counters: CounterReads | None) -> CaptureReport:
    """The link where errors enter, from the counters the capture carries."""
    report = replace(report, error_counters=counters)
    link = counters.suspect if counters is not None else None
    if link is None:
        return report
    upstream = "the master" if link.upstream == 0 else f"slave {link.upstream}"
    extra = Findings()
    extra.add("bad-link", WARNING,
              f"errors enter the line between {upstream} and slave {link.downstream} "
              f"(slave {link.at} port {link.port}, from the error counters read in the "
              f"capture): {'; '.join(link.evidence)}", slave=link.downstream, count=1)
    return replace(report, findings=[*report.findings, *extra.ordered()])


#: ``on_pairs(frames_read, round_trip_ns, returned_at_ns, meta)`` of :func:`stream_pairs`:
#: the pairs found since the last call, in return order; ``meta`` is the outgoing frame's
#: number << 1 | 1 when it is cyclic; ``frames_read`` the frames scanned so far.
OnPairs = Callable[[int, "np.ndarray", "np.ndarray", "np.ndarray"], None]


def stream_pairs(report: CaptureReport, on_pairs: OnPairs, *, engine: str = "auto",
                 chunk_bytes: int = CHUNK_BYTES,
                 should_stop: Callable[[], bool] = never) -> None:
    """Read ``report``'s capture again with the rules of its pass and hand every pair
    (out/return) to ``on_pairs`` as it is found: the per-pair series of the analysis,
    streamed (bounded memory, unlike ``keep_series``)."""
    reader = CaptureReader(report.path)
    eng = choose_engine(engine, os.path.getsize(reader.path))
    dirmode, mode, sig = report.rules
    p = _Pass(reader, eng, dirmode, mode, sig, False, chunk_bytes, None, should_stop,
              on_pairs=on_pairs)
    p.run()


def spool_stream(path: str | Path) -> Any:
    """A temporary copy of a stream (pipe, character device, socket), None for a regular
    file or anything that cannot be opened (CaptureReader says why)."""
    import shutil
    import stat
    import tempfile

    try:
        if stat.S_ISREG(os.stat(path).st_mode) or os.path.isdir(path):
            return None
        src = open(path, "rb")  # noqa: SIM115
    except OSError:
        return None
    copy = tempfile.NamedTemporaryFile(prefix="lolacli-stream-", suffix=".capture")
    try:
        with src:
            shutil.copyfileobj(src, copy, 1 << 20)
        copy.flush()
    except BaseException:
        copy.close()
        raise
    return copy


def _zeros(n: int, kind: str) -> Any:
    """A zeroed scanner array: a list for the Python engine (``kind`` "list"), else
    int64 ``array`` ("array": the C engine on a small capture) or numpy ("numpy")."""
    if kind == "list":
        return [0] * n
    if kind == "array":
        return array("q", [0]) * n
    import numpy as np

    return np.zeros(n, np.int64)


def _np(values: Any) -> np.ndarray:
    """int64 numpy view of a scanner array (a copy only for the Python engine's lists)."""
    import numpy as np

    return np.asarray(values, dtype=np.int64)


def _rows(out: Any, n: int) -> np.ndarray:
    """A copy of the first ``n`` values of a scanner output array. The kernel writes the
    next rows from 0 again after each drain, so a view kept past it would be overwritten
    (the c engine's outputs are numpy arrays; the Python engine's lists copy
    anyway)."""
    import numpy as np

    return np.array(out[:n], dtype=np.int64)


_OUTPUTS = threading.local()

#: the scanner's output arrays and their rows' widths
_OUTPUT_COLS = {"o_rt": 1, "o_rtts": 1, "o_rtfr": 1, "o_period": 1, "o_burst": 1, "o_dc": 1,
                "o_mbx": S.MBX_COLS, "o_cfg": S.CFG_COLS, "o_evict": S.EVICT_COLS,
                "o_ctr": S.CTR_COLS}


def _outputs(kind: str) -> dict[str, Any]:
    """The scanner's output arrays (:data:`OUT_ROWS` rows, ~4 MB). The kernel writes a
    row before it is read and a pass drains them as it goes, so they need no zeroing and
    one set serves every pass of a thread, one after the other: a batch of small captures
    does not allocate (and fault in) them twice a file. The Python engine's lists are
    made a pass."""
    if kind == "list":
        return {name: _zeros(OUT_ROWS * cols, kind) for name, cols in _OUTPUT_COLS.items()}
    kept: dict[str, dict[str, Any]] = _OUTPUTS.__dict__.setdefault("by_kind", {})
    if kind not in kept:
        kept[kind] = {name: _zeros(OUT_ROWS * cols, kind) for name, cols in _OUTPUT_COLS.items()}
    return kept[kind]


def _plain(out: Any, n: int) -> list[int]:
    """The first ``n`` values of a scanner output array as a list (a copy)."""
    return out[:n] if isinstance(out, list) else out[:n].tolist()


class _Pass:
    """One scan of the file with fixed direction and cyclic-stream rules."""

    def __init__(
        self,
        reader: CaptureReader,
        engine: str,
        dirmode: int,
        mode: int,
        stream_sig: int,
        keep_series: bool,
        chunk_bytes: int | None,
        progress: Progress | None,
        should_stop: Callable[[], bool] = never,
        mapped: bool = True,
        on_pairs: OnPairs | None = None,
    ) -> None:
        from lolacli.capture.sdo import SdoTracker

        self.reader = reader
        self.engine = engine
        self.k = kernels(engine)
        self.py = engine == "python"
        self.keep_series = keep_series
        self.on_pairs = on_pairs
        # the rows drained into Python lists, not numpy (a small capture, no series)
        self.lite = (not keep_series and on_pairs is None
                     and os.path.getsize(reader.path) <= SMALL_BYTES)
        self.kind = "list" if self.py else "array" if self.lite else "numpy"
        self.chunk_bytes = None if chunk_bytes is None else max(chunk_bytes, 1 << 16)
        self.mapped = mapped
        self.mapped_read = False  # whether the pass read a mapped file
        self.shrank = False  # the mapped file shrank while it was read
        self.progress = progress
        self.should_stop = should_stop
        self.stopped_by_signal_at: int | None = None  # file offset where should_stop stopped
        py = self.kind
        self.st = _zeros(S.S_SIZE, py)
        self.st[S.S_MODE] = mode
        self.st[S.S_STREAM_SIG] = stream_sig
        self.st[S.S_DIRMODE] = dirmode
        self.cmd_counts = _zeros(256, py)
        self.dg = _zeros(S.MAX_DGRAMS, py)
        self._new_pair_table(PAIR_SLOTS_SMALL if self.kind == "array" else PAIR_SLOTS)
        self.sk, self.sc = _zeros(STREAM_SLOTS, py), _zeros(STREAM_SLOTS, py)
        self.wk, self.wn = _zeros(OBS_SLOTS, py), _zeros(OBS_SLOTS, py)
        self.wv = _zeros(OBS_SLOTS * S.OCOLS, py)
        out = _outputs(py)
        self.o_rt, self.o_rtts, self.o_rtfr = out["o_rt"], out["o_rtts"], out["o_rtfr"]
        self.o_period, self.o_burst, self.o_dc = out["o_period"], out["o_burst"], out["o_dc"]
        self.o_mbx, self.o_cfg = out["o_mbx"], out["o_cfg"]
        self.o_evict, self.o_ctr = out["o_evict"], out["o_ctr"]
        self.ifs = _zeros(5 * 64, py)
        self.n_if = 0
        self.interfaces: list[Interface] = []
        header = reader.header
        self.big = header.big_endian
        if header.format == FORMAT_PCAP:
            link = header.link_type if header.link_type in ANALYSED_LINK_TYPES else 0
            for j, v in enumerate((0, 1, 1, 0, link)):
                self.ifs[j] = v
            self.n_if = 1
        # the drained rows: numpy arrays, or lists in a lite pass
        self.rt_cyclic: list[Any] = []  # round trips of cyclic frames
        self.rt_other: list[Any] = []  # of all other pairs
        self.rt_series: list[np.ndarray] = []  # all, in order (keep_series)
        self.rt_ts: list[np.ndarray] = []
        self.odd_rt: list[Any] = []  # (frame, rt) of round trips <= 0 or >= 1 ms
        self.periods: list[Any] = []
        self.bursts: Any = [] if self.lite else _zeros(0, "numpy")  # bursts by size
        self.dc_values: list[Any] = []
        self.evicted: list[Any] = []  # (frame << 1 | cyclic, ts)
        self.layout = MasterLayout()
        self.sdo = SdoTracker()
        self.counters = CounterTracker()
        self.stopped_at: int | None = None
        self.cut_short = False

    # --- tables ----------------------------------------------------------------------
    def _new_pair_table(self, slots: int) -> None:
        py = self.kind
        self.pk, self.pn = _zeros(slots, py), _zeros(slots, py)
        self.pv = _zeros(slots * S.DEPTH * S.PCOLS, py)

    def _grow(self) -> None:
        st, py, k = self.st, self.kind, self.k
        if st[S.S_P_USED] * 2 > len(self.pk):
            pn = self.pn
            live = len(pn) - (pn.count(0) if py != "numpy" else int((pn == 0).sum()))
            slots = len(self.pk) * (2 if live * 4 > len(self.pk) else 1)
            old = (self.pk, self.pn, self.pv)
            self._new_pair_table(slots)
            st[S.S_P_USED] = k.rehash(*old, self.pk, self.pn, self.pv, False)
        if st[S.S_S_USED] * 2 > len(self.sk):
            nk, nn = _zeros(len(self.sk) * 2, py), _zeros(len(self.sk) * 2, py)
            empty = _zeros(0, py)
            st[S.S_S_USED] = k.rehash(self.sk, self.sc, empty, nk, nn, empty, True)
            self.sk, self.sc = nk, nn
        if st[S.S_W_USED] * 2 > len(self.wk):
            size = len(self.wk) * 2
            nk, nn, nv = _zeros(size, py), _zeros(size, py), _zeros(size * S.OCOLS, py)
            st[S.S_W_USED] = k.rehash(self.wk, self.wn, self.wv, nk, nn, nv, True)
            self.wk, self.wn, self.wv = nk, nn, nv

    def top_stream(self) -> int:
        if self.kind != "numpy":  # the first slot of the largest count, as argmax
            return int(self.sk[self.sc.index(max(self.sc))])
        return int(self.sk[int(self.sc.argmax())])

    # --- the pass ------------------------------------------------------------------------
    def run(self) -> None:
        path = self.reader.path
        total = os.path.getsize(path)
        fmt = self.reader.header.format
        slice_bytes = SLICE_BYTES_PYTHON if self.py else SLICE_BYTES
        with open_source(path, self.chunk_bytes, mapped=self.mapped and not self.py) as src:
            self.mapped_read = isinstance(src, MappedSource)
            pos = PCAP_HEADER_BYTES if fmt == FORMAT_PCAP else 0
            view: Any = None
            whole = False  # the next call gets the rest of the buffer (a record > a slice)
            while True:
                end, eof = src.end, src.eof
                if view is None:
                    view = src.bytes_at(0, end) if self.py else src.buf
                stop_at = end if whole else min(end, pos + slice_bytes)
                started = pos
                pos, status = self.k.scan(
                    view, pos, stop_at, eof and stop_at == end, fmt, self.big,
                    self.reader.header.nanoseconds,
                    self.ifs, self.n_if, self.st, self.cmd_counts, self.dg,
                    self.pk, self.pn, self.pv, self.sk, self.sc, self.wk, self.wn, self.wv,
                    self.o_rt, self.o_rtts, self.o_rtfr, self.o_period, self.o_burst,
                    self.o_dc, self.o_mbx, self.o_cfg, self.o_evict, self.o_ctr,
                )
                # the end of a slice within the buffer: the rows wait in the outputs (the
                # kernel says FLUSH before they fill) and the window stays mapped, so
                # they are drained with the next slice's (a drain per 2 MB slice cost the
                # LOLA capture ~0.05 s)
                slice_end = status == S.ST_NEED_MORE and stop_at < end
                if not slice_end:
                    self._drain(src)
                if self.progress is not None:
                    self.progress(min(src.base + pos, total), total)
                if status == S.ST_DONE:
                    break
                if self.should_stop():
                    self._drain(src)
                    self.stopped_by_signal_at = src.base + pos
                    break
                if status == S.ST_FAULT:  # the mapped file shrank under the scanner
                    self.shrank = True
                    break
                if status == S.ST_CORRUPT:
                    self._stop(src, pos)
                    break
                if status == S.ST_GROW:
                    self._grow()
                    continue
                if status == S.ST_BLOCK:
                    need = self._block(src, pos)
                    if need == 0:
                        pos = self._block_done
                        continue
                    if need < 0:
                        self._stop(src, pos)
                        break
                elif status == S.ST_FLUSH:
                    continue
                elif stop_at < end:  # the end of a slice, not of the buffer
                    whole = pos == started
                    continue
                # need more bytes: the record at pos runs past the buffer
                whole = False
                if eof:
                    break
                view = None  # (the window's last view goes before it is unmapped)
                pos = src.advance(pos)
            if isinstance(src, MappedSource) and self.stopped_by_signal_at is None:
                self.shrank = self.shrank or src.shrank()
        if self.shrank:
            return  # analyze_file reads the file again
        self.k.finish(self.st, self.o_burst)
        self._drain(None)
        if self.progress is not None and self.stopped_by_signal_at is None:
            self.progress(total, total)
        if self.interfaces and not any(i.analysed for i in self.interfaces):
            types = sorted({i.link_type for i in self.interfaces})
            raise CaptureError(
                f"no Ethernet or Linux cooked (SLL/SLL2) interface in the capture (link types "
                f"{types})", path=str(path)
            )

    def _stop(self, src: Source, pos: int) -> None:
        """A record the scanner cannot read: the file was cut short (the record runs past
        its end) or is damaged there."""
        self.st[S.S_MALFORMED] += 1
        self.stopped_at = src.base + pos
        self.cut_short = src.eof and _runs_past_end(src, pos, self.reader.header.format,
                                                    self.big)

    def _block(self, src: Source, pos: int) -> int:
        """A pcapng SHB or IDB at ``pos``: 0 handled, 1 need more bytes, -1 corrupt."""
        end, eof = src.end, src.eof
        if pos + 12 > end:
            return -1 if eof else 1
        head = src.bytes_at(pos, 12)
        if len(head) < 12:
            return -1  # the file shrank under a mapped read
        btype = int.from_bytes(head[0:4], "little")
        if btype == 0x0A0D0D0A:
            bom = head[8:12]
            if bom == b"\x4d\x3c\x2b\x1a":
                self.big = False
            elif bom == b"\x1a\x2b\x3c\x4d":
                self.big = True
            else:
                return -1
        total = int.from_bytes(head[4:8], "big" if self.big else "little")
        if total < 12 or total % 4 or total > S.MAX_RECORD:
            return -1
        if pos + total > end:
            return -1 if eof else 1
        if btype == 0x0A0D0D0A:
            self.n_if = 0
        else:
            try:
                iface = parse_idb(src.bytes_at(pos, total), self.big)
            except ValueError:
                return -1  # too short: a damaged block
            if abs(iface.ts_params()[3]) > S.TS_OFFSET_LIMIT_NS:
                return -1  # an absurd if_tsoffset: a damaged block
            self._add_interface(iface)
        self._block_done = pos + total
        return 0

    def _add_interface(self, iface: Interface) -> None:
        self.interfaces.append(iface)
        if self.n_if * 5 + 5 > len(self.ifs):
            grown = _zeros(len(self.ifs) * 2, self.kind)
            grown[: len(self.ifs)] = self.ifs[:]
            self.ifs = grown
        mode, a, b, off = iface.ts_params()
        base = self.n_if * 5
        for j, v in enumerate((mode, a, b, off, iface.link_type if iface.analysed else 0)):
            self.ifs[base + j] = v
        self.n_if += 1

    def _drain(self, src: Source | None) -> None:
        """Take the scanner's output rows; ``src`` holds the bytes of the datagrams they
        point at (None after the last call: no rows point at bytes then)."""
        st = self.st
        if self.lite:
            self._drain_lite()
        else:
            self._drain_numpy()
        n = int(st[S.S_N_CFG])
        for r in range(n):
            frame, q, cmd, adp, ado, ln = (int(v) for v in
                                           self.o_cfg[r * S.CFG_COLS:(r + 1) * S.CFG_COLS])
            assert src is not None
            self.layout.feed(frame, cmd, adp, ado, src.bytes_at(q + 10, ln))
        n = int(st[S.S_N_MBX])
        for r in range(n):
            row = [int(v) for v in self.o_mbx[r * S.MBX_COLS:(r + 1) * S.MBX_COLS]]
            frame, ts, q, cmd, address, ln = row[:6]
            assert src is not None
            data = src.bytes_at(q + 10, ln)
            self.sdo.feed(frame, ts, cmd, address, data)
        n = int(st[S.S_N_CTR])
        if n:
            assert src is not None
            flat = _plain(self.o_ctr, n * S.CTR_COLS)
            for r in range(0, len(flat), S.CTR_COLS):
                _, q, cmd, adp, index, place, wkc, _ = flat[r:r + S.CTR_COLS]
                self.counters.feed(cmd, adp, index, place, wkc,
                                   partial(src.bytes_at, q + 10, S.ERROR_COUNTER_BYTES))
        for i in (S.S_N_RT, S.S_N_PERIOD, S.S_N_BURST, S.S_N_DC, S.S_N_MBX, S.S_N_CFG,
                  S.S_N_EVICT, S.S_N_CTR):
            st[i] = 0

    def _drain_numpy(self) -> None:
        """The series rows into numpy arrays."""
        import numpy as np

        st = self.st
        # views of the C engine's rows (the Python engine's lists: copies); whatever is
        # kept below is a copy (boolean indexing, astype, _rows), taken before the kernel
        # writes the rows again
        view = (lambda out, n: out[:n]) if self.kind == "numpy" else _rows
        n = int(st[S.S_N_RT])
        if n:
            rt, meta = view(self.o_rt, n), view(self.o_rtfr, n)
            lo, hi = int(rt.min()), int(rt.max())
            packed = _compact(rt, lo, hi)
            cyc = (meta & 1) != 0
            self.rt_cyclic.append(packed[cyc])
            self.rt_other.append(packed[~cyc])
            if lo <= 0 or hi >= MIN_TIMEOUT_NS:
                odd = (rt <= 0) | (rt >= MIN_TIMEOUT_NS)
                self.odd_rt.append(np.stack([meta[odd] >> 1, rt[odd]], 1))
            if self.keep_series:
                self.rt_series.append(_rows(rt, n))
                self.rt_ts.append(_rows(self.o_rtts, n))
            if self.on_pairs is not None:
                self.on_pairs(int(st[S.S_FRAMES]), _rows(rt, n), _rows(self.o_rtts, n),
                              _rows(meta, n))
        n = int(st[S.S_N_PERIOD])
        if n:
            period = view(self.o_period, n)
            packed = _compact(period, int(period.min()), int(period.max()))
            self.periods.append(packed if packed is not period else _rows(period, n))
        n = int(st[S.S_N_BURST])
        if n:
            counts = np.bincount(_rows(self.o_burst, n))
            if counts.size > self.bursts.size:
                counts[: self.bursts.size] += self.bursts
                self.bursts = counts
            else:
                self.bursts[: counts.size] += counts
        n = int(st[S.S_N_DC])
        if n:
            self.dc_values.append(_rows(self.o_dc, n))
        n = int(st[S.S_N_EVICT])
        if n:
            self.evicted.append(_rows(self.o_evict, n * S.EVICT_COLS).reshape(n, S.EVICT_COLS))

    def _drain_lite(self) -> None:
        """The series rows into lists (a small capture: the same values, no numpy)."""
        st = self.st
        n = int(st[S.S_N_RT])
        if n:
            rt, meta = _plain(self.o_rt, n), _plain(self.o_rtfr, n)
            self.rt_cyclic.append([r for r, m in zip(rt, meta, strict=True) if m & 1])
            self.rt_other.append([r for r, m in zip(rt, meta, strict=True) if not m & 1])
            self.odd_rt.extend((m >> 1, r) for r, m in zip(rt, meta, strict=True)
                               if r <= 0 or r >= MIN_TIMEOUT_NS)
        n = int(st[S.S_N_PERIOD])
        if n:
            self.periods.append(_plain(self.o_period, n))
        n = int(st[S.S_N_BURST])
        if n:
            bursts = self.bursts
            for size in _plain(self.o_burst, n):
                if size >= len(bursts):
                    bursts.extend([0] * (size + 1 - len(bursts)))
                bursts[size] += 1
        n = int(st[S.S_N_DC])
        if n:
            self.dc_values.append(_plain(self.o_dc, n))
        n = int(st[S.S_N_EVICT])
        if n:
            flat = _plain(self.o_evict, n * S.EVICT_COLS)
            self.evicted.extend(zip(flat[0::S.EVICT_COLS], flat[1::S.EVICT_COLS],
                                    strict=True))

    # --- what the pass saw -------------------------------------------------------------
    def _pending(self) -> tuple[Any, Any, Any]:
        """(frame, ts, cyclic) of every outgoing frame left unanswered: numpy arrays, or
        lists in a lite pass."""
        if self.lite:
            pn, pv = self.pn, self.pv
            meta: list[int] = []
            stamps: list[int] = []
            width = S.DEPTH * S.PCOLS
            for slot in compress(range(len(pn)), pn):  # the slots holding frames
                for j in range(pn[slot]):
                    at = slot * width + j * S.PCOLS
                    stamps.append(pv[at])
                    meta.append(pv[at + 1])
            for m, t in self.evicted:
                meta.append(m)
                stamps.append(t)
            return [m >> 1 for m in meta], stamps, [bool(m & 1) for m in meta]
        import numpy as np

        pn = _np(self.pn)
        pv = _np(self.pv).reshape(pn.size, S.DEPTH, S.PCOLS)
        live = np.arange(S.DEPTH)[None, :] < pn[:, None]
        meta_a, ts = pv[..., 1][live], pv[..., 0][live]
        if self.evicted:
            rows = np.concatenate(self.evicted)
            meta_a, ts = np.concatenate([meta_a, rows[:, 0]]), np.concatenate([ts, rows[:, 1]])
        return meta_a >> 1, ts, (meta_a & 1) != 0

    def _observations(self, kind: int) -> list[tuple[int, ...]]:
        """Observation rows of one kind: the six fields after ``kind``... see scan.py."""
        wk, wn, wv = self.wk, self.wn, self.wv
        rows: list[tuple[int, ...]] = []
        for i in compress(range(len(wk)), wk):  # the slots in use
            v, n = [int(x) for x in wv[i * S.OCOLS:(i + 1) * S.OCOLS]], int(wn[i])
            if v[0] != kind:
                continue
            if kind == S.KIND_WKC:
                rows.append((v[1], v[2], v[3], v[4], n, v[6], v[7], v[8], v[9]))
            else:
                rows.append((v[1], v[2], v[3], v[4], v[5], n, v[6], v[9]))
        return rows

    # --- result ----------------------------------------------------------------------
    def report(self, eni: Eni | None, given_timeout_ns: int | None, max_lost: int,
               max_wkc: int, stopped_at: int | None = None) -> CaptureReport:
        st = [int(v) for v in self.st]
        if not self.lite:  # the drained chunks (thousands) as one array each
            self.rt_cyclic, self.rt_other, self.periods = (
                [_take(parts)] for parts in (self.rt_cyclic, self.rt_other, self.periods))
        by_cmd = {mnemonic(c): int(n) for c, n in enumerate(self.cmd_counts) if n}
        counts = {
            "frames_total": st[S.S_FRAMES],
            "ecat_frames": st[S.S_ECAT],
            "non_ecat_frames": st[S.S_NONECAT],
            "malformed_frames": st[S.S_MALFORMED],
            "datagrams_total": st[S.S_DGRAMS],
            "outgoing_frames": st[S.S_OUT],
            "returned_frames": st[S.S_RET],
            "pairs": st[S.S_PAIRS],
            "unmatched_returned": st[S.S_UNMATCHED_RET],
            "cyclic_frames": st[S.S_CYC_N],
            "vlan_frames": st[S.S_VLAN],
            "udp_frames": st[S.S_UDP],
            "non_command_ecat_frames": st[S.S_ECAT_OTHER],
            "snaplen_cut_frames": st[S.S_CUT],
            "non_ethernet_packets": st[S.S_NON_ETH],
            "skipped_blocks": st[S.S_SKIPPED],
            "cyclic_pairs": sum(len(c) for c in self.rt_cyclic),
            "brd_wkc_max": st[S.S_BRD_MAX],
            "cyclic_frame_bytes": st[S.S_CYC_BYTES],
        }
        keep = self.keep_series
        all_rt = self.rt_cyclic + self.rt_other
        rt_stats = summarize_chunks(all_rt)
        findings = Findings()
        fate = self._fate(all_rt, rt_stats, given_timeout_ns, st[S.S_END_TS])
        rule = self._direction_rule(st)
        if stopped_at is not None:
            total = os.path.getsize(self.reader.path)
            findings.add("interrupted", WARNING,
                         f"the analysis was stopped after {stopped_at:,} of {total:,} bytes "
                         f"({100 * stopped_at / max(total, 1):.0f} %): every figure covers "
                         f"the first {plural(st[S.S_FRAMES], 'frame')} only", count=1)
        frame_findings(findings, counts, fate, max_lost, rule)
        unusable = self._timestamps(findings, all_rt, st)
        self._file_findings(findings, st)
        wkc = verdict(self._observations(S.KIND_WKC), self.layout, eni)
        _wkc_findings(findings, wkc, max_wkc, eni, self.layout)
        _slave_count_finding(findings, eni, st[S.S_BRD_MAX])
        al = last_al_status(self._observations(S.KIND_AL_STATUS))
        _al_findings(findings, al, self.layout)
        self.sdo.describe(eni)  # each transaction's entry named, typed, its value decoded
        for t in self.sdo.aborts():
            findings.add("sdo-abort", WARNING,
                         f"SDO abort 0x{t.abort_code or 0:08X} ({t.to_dict()['abort_text']}) "
                         f"on 0x{t.index:04X}:{t.subindex:02X} of slave {station(t.slave)}",
                         [t.end_frame], 1)
        return CaptureReport(
            path=str(self.reader.path),
            format="pcap" if self.reader.header.format == FORMAT_PCAP else "pcapng",
            engine=self.engine,
            counts=counts,
            datagrams_by_cmd=by_cmd,
            round_trip_stats=rt_stats,
            round_trip_cyclic_stats=summarize_chunks(self.rt_cyclic),
            cycle_period_stats=summarize_chunks(self.periods),
            cyclic_stream="logical" if st[S.S_MODE] == S.MODE_LOGICAL else "signature",
            direction_rule=rule,
            wkc_verdict=wkc,
            fate=fate,
            findings=findings.ordered(),
            unusable_stats=unusable,
            al_status=al,
            layout=self.layout,
            dc=self._dc_dict(st),
            sdo=self.sdo,
            time_span_ns=st[S.S_END_TS] - st[S.S_FIRST_TS],
            interfaces=list(self.interfaces),
            interrupted=stopped_at is not None,
            read_bytes=stopped_at,
            round_trip_ns=_take(self.rt_series) if keep else None,
            round_trip_at_ns=_take(self.rt_ts) if keep else None,
            cycle_period_ns=_take(self.periods) if keep else None,
            rules=(st[S.S_DIRMODE], st[S.S_MODE], st[S.S_STREAM_SIG]),
        )

    def _direction_rule(self, st: list[int]) -> str:
        if st[S.S_DIRMODE] == S.DIR_INFER:
            return "inferred"
        if st[S.S_DIR_PT] == 0:
            return "mac"
        # (frames of other EtherCAT types count here too, not in S_ECAT)
        return "packet_type" if st[S.S_DIR_PT] >= st[S.S_ECAT] else "packet_type+mac"

    def _fate(self, all_rt: list[Any], rt_stats: Summary | None,
              given: int | None, end_ts: int) -> FrameFate:
        median = None if rt_stats is None else rt_stats.median
        limit = timeout_ns(median, given)
        late_count = _count(all_rt, lambda c: c > limit[0])
        late_frames = first(self._odd_frames(lambda rt: rt > limit[0]))
        frames, ts, cyc = self._pending()
        return fates(frames, ts, cyc, end_ts, limit, late_count, late_frames)

    def _odd_frames(self, keep: Callable[[Any], Any]) -> Any:
        """The frames of the odd round trips ``keep`` selects (an array, a list)."""
        if self.lite:
            return [frame for frame, rt in self.odd_rt if keep(rt)]
        import numpy as np

        odd = np.concatenate(self.odd_rt) if self.odd_rt else np.zeros((0, 2), np.int64)
        return odd[keep(odd[:, 1]), 0]

    def _timestamps(self, out: Findings, all_rt: list[Any], st: list[int]) -> list[str]:
        zero = _count(all_rt, lambda c: c == 0)
        negative = _count(all_rt, lambda c: c < 0)
        bad_frames = first(self._odd_frames(lambda rt: rt <= 0))
        back = st[S.S_BACKWARDS]
        back_frames = tuple(st[S.S_BACK_F0:S.S_BACK_F0 + min(back, S.BACK_KEEP)])
        periods_bad = _count(self.periods, lambda c: c <= 0)
        pairs = sum(len(c) for c in all_rt)
        return timestamp_findings(out, zero, negative, bad_frames, pairs, back, back_frames,
                                  periods_bad)

    def _file_findings(self, out: Findings, st: list[int]) -> None:
        total = os.path.getsize(self.reader.path)
        if self.stopped_at is not None:
            unread = total - self.stopped_at
            if self.cut_short:
                out.add("cut-short", WARNING,
                        f"the file ends inside a record at offset {self.stopped_at} (the "
                        f"capture was cut short); its last {plural(unread, 'byte')} are not "
                        "analysed",
                        count=1)
            else:
                out.add("unreadable", FAILURE,
                        f"the file is damaged at offset {self.stopped_at}: the "
                        f"{plural(unread, 'byte')} after it (of {total}) could not be read",
                        count=1)
        malformed = st[S.S_MALFORMED] - (1 if self.stopped_at is not None else 0)
        if malformed > 0:
            frames = st[S.S_MALF_F0:S.S_MALF_F0 + min(malformed, S.BACK_KEEP)]
            out.add("malformed", WARNING,
                    f"{plural(malformed, 'frame')} could not be decoded (truncated or "
                    "damaged)",
                    frames, malformed)

    def _dc_dict(self, st: list[int]) -> dict[str, Any]:
        values: Any
        if self.lite:
            sizes = summarize_array([k for k, c in enumerate(self.bursts) for _ in range(c)])
            values = [v for part in self.dc_values for v in part]
            biggest = max(map(abs, values)) if values else None
        else:
            import numpy as np

            sizes = summarize_array(np.repeat(np.arange(self.bursts.size), self.bursts))
            values = _cat(self.dc_values, np.int64)
            biggest = int(np.abs(values).max()) if values.size else None
        return {
            "drift_compensation_datagrams": st[S.S_DC_DGRAMS],
            "drift_compensation_bursts": 0 if sizes is None else sizes.count,
            "burst_size": None
            if sizes is None
            else {"min": int(sizes.min), "median": sizes.median, "max": int(sizes.max)},
            "burst_gap_us": S.BURST_GAP_NS / 1000.0,
            "system_time_difference_reads": len(values),
            "system_time_difference_max_abs_ns": biggest,
            "system_time_difference_last_ns": int(values[-1]) if len(values) else None,
        }


def _wkc_findings(out: Findings, wkc: WkcVerdict, max_wkc: int, eni: Eni | None,
                  layout: MasterLayout) -> None:
    total = wkc.mismatches
    for d in wkc.datagrams:
        counted = wkc.datagram_counts(d)
        if counted and d.mismatches:
            values = ", ".join(f"{o.wkc} ×{o.count}" for o in d.observed if o.wkc != d.expected)
            out.add("wkc-mismatch", FAILURE if total > max_wkc else WARNING,
                    f"{d.name()}: WKC differs from the expected {d.expected} in "
                    f"{d.mismatches} of {plural(d.returns, 'return')} (seen: {values}; "
                    "expected: "
                    f"{d.note})", d.mismatch_frames, d.mismatches)
        if counted and d.bring_up:
            out.add("wkc-bring-up", INFO,
                    f"{d.name()}: {plural(d.bring_up, 'return')} below {d.expected} before it"
                    " first "
                    "reached it (the bus coming up)", (), d.bring_up)
        if d.expected is None:
            out.add("wkc-unknown", WARNING, f"{d.name()}: {d.note}",
                    [o.frames[0] for o in d.observed], d.returns)
    if eni is None:
        return
    if wkc.checked == 0:
        if wkc.datagrams:
            reason = "; ".join(f"{d.name()}: {d.note}" for d in wkc.datagrams
                               if d.expected is None) or "no expected value from the ENI"
        else:
            reason = "no cyclic datagram came back"
        out.add("wkc-unverified", FAILURE,
                f"0 returns of cyclic datagrams could be checked against the ENI: {reason}")
    missing = eni_slaves_not_mapped(eni, layout)
    if missing:
        names = ", ".join(f"{s.position} {s.name}" for s in missing[:5])
        out.add("eni-slave-unmapped", FAILURE,
                f"{plural(len(missing), 'ENI slave')} with process data "
                f"{'has' if len(missing) == 1 else 'have'} no FMMU in the master's layout (not "
                f"in the bus, or not configured): {names}", (), len(missing))


def _slave_count_finding(out: Findings, eni: Eni | None, brd_wkc_max: int) -> None:
    """A bus whose broadcasts never counted the ENI's slaves is not the ENI's bus (each
    slave increments a BRD/BWR's WKC once, so the highest WKC is the slaves on the line)."""
    if eni is None or not brd_wkc_max or brd_wkc_max == len(eni.slaves):
        return
    fewer = brd_wkc_max < len(eni.slaves)
    out.add("eni-slave-count", FAILURE,
            f"the bus answered broadcasts with at most {plural(brd_wkc_max, 'slave')}, the "
            f"ENI has {len(eni.slaves)}" + (" (slaves missing, or a different bus)" if fewer
                                    else " (extra slaves, or a different ENI)"),
            (), abs(len(eni.slaves) - brd_wkc_max))


def _al_findings(out: Findings, reads: list[AlStatusRead], layout: MasterLayout) -> None:
    """Slaves not in OP after the master asked for OP, where the capture reads AL status."""
    for r in reads:
        request = layout.requested(None if r.broadcast else r.station)
        asked_op = request is not None and request.state == 8 and request.frame < r.last_frame
        who = "the bus (BRD)" if r.broadcast else f"slave {station(r.station)}"
        pos = None if r.broadcast else layout.position_of(r.station)
        if pos is not None:
            who += f" (position {pos + 1})"
        if asked_op and not r.in_op:
            out.add("not-op", FAILURE,
                    f"{who} is in {r.describe()} after the master requested OP "
                    f"(frame {request.frame if request else '?'})", [r.last_frame], 1)
        elif r.status & 0x10:
            out.add("al-error", WARNING, f"{who} reports {r.describe()}", [r.last_frame], 1)


def _runs_past_end(src: Source, pos: int, fmt: int, big: bool) -> bool:
    """Whether the record at ``pos`` is sane but longer than the bytes left (cut short)."""
    order: Literal["big", "little"] = "big" if big else "little"
    end = src.end
    if fmt == FORMAT_PCAP:
        if end - pos < 16:
            return True
        incl = int.from_bytes(src.bytes_at(pos + 8, 4), order)
        return incl <= S.MAX_RECORD and pos + 16 + incl > end
    if end - pos < 8:
        return True
    size = int.from_bytes(src.bytes_at(pos + 4, 4), order)
    return 12 <= size <= S.MAX_RECORD and size % 4 == 0 and pos + size > end


def _count(parts: list[Any], test: Callable[[Any], Any]) -> int:
    """How many values of the chunks ``parts`` (arrays, or lists) pass ``test``."""
    total = 0
    for c in parts:
        if isinstance(c, list):
            total += sum(1 for v in c if test(v))
        else:
            total += int(test(c).sum())
    return total


def _cat(parts: list[np.ndarray], dtype: Any) -> np.ndarray:
    import numpy as np

    if not parts:
        return np.zeros(0, dtype)
    return np.concatenate(parts).astype(dtype, copy=False)


def _take(parts: list[np.ndarray]) -> np.ndarray:
    """Concatenate drained chunks (numpy promotes mixed int32/int64 chunks to int64) and
    empty the list, so that the chunks are freed as soon as the whole is built."""
    import numpy as np

    if not parts:
        return np.zeros(0, np.int64)
    whole = np.concatenate(parts)
    parts.clear()
    return whole


def _compact(values: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """An int32 copy when the nanosecond values (from ``lo`` to ``hi``) fit (±2.1 s),
    halving the memory of long series; else ``values`` themselves."""
    if -(2**31) < lo and hi < 2**31:
        return values.astype("int32")
    return values
