"""Capture analysis: one streaming pass of the scanner, then numpy statistics.

:func:`analyze_file` reads the capture in bounded chunks into one reusable buffer and lets
:func:`lolacli.capture.scan.scan` (its C twin, or numba-compiled, when available) walk the
records. The scanner pairs frames, counts commands, checks working counters and tracks DC drift
compensation as it goes; the rare mailbox datagrams it flags are decoded here in Python
(:mod:`lolacli.capture.sdo`). Definitions follow DESIGN.md (Direction, Pairing, Cyclic
stream, Expected WKC, Lost frame); the JSON shape is ``lolacli.capture/1``.

Cyclic stream: outgoing frames that carry a logical (LRD/LWR/LRW) datagram; when there
are none, the outgoing frames with the most frequent (command, address key) sequence,
found by a second pass.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from lolacli.capture import scan as S
from lolacli.capture.fast import choose_engine, kernels
from lolacli.capture.reader import (
    FORMAT_PCAP,
    PCAP_HEADER_BYTES,
    CaptureReader,
    Interface,
    parse_idb,
)
from lolacli.capture.sdo import SdoTracker
from lolacli.capture.stats import summary_us
from lolacli.errors import CaptureError
from lolacli.wire.commands import mnemonic

if TYPE_CHECKING:
    from lolacli.eni.model import Eni

SCHEMA = "lolacli.capture/1"
CHUNK_BYTES = 8 * 1024 * 1024
OUT_ROWS = 1 << 16
PAIR_SLOTS = 1 << 12
STREAM_SLOTS = 1 << 10
WKC_SLOTS = 1 << 8
WKC_DETAIL_ROWS = 200

Progress = Callable[[int, int], None]


def stats_us(values_ns: np.ndarray) -> dict[str, float | int] | None:
    """``{count, min, mean, median, std, p99, max}`` in µs of integer nanoseconds."""
    return summary_us([np.asarray(values_ns, np.int64)])


def _jitter(stats: dict[str, float | int] | None) -> dict[str, float] | None:
    """Cycle jitter: std and the largest deviation from the median (µs)."""
    if stats is None:
        return None
    med = float(stats["median"])
    deviation = max(abs(float(stats["min"]) - med), abs(float(stats["max"]) - med))
    return {"std": float(stats["std"]), "max_deviation": deviation}


@dataclass(frozen=True, slots=True)
class CaptureReport:
    """Everything ``capture analyze`` reports; :meth:`to_dict` is ``lolacli.capture/1``."""

    path: str
    format: str
    engine: str
    counts: dict[str, int]
    datagrams_by_cmd: dict[str, int]
    round_trip_stats: dict[str, Any] | None
    round_trip_cyclic_stats: dict[str, Any] | None
    cycle_period_stats: dict[str, Any] | None
    cyclic_stream: str
    wkc: dict[str, Any]
    dc: dict[str, Any]
    sdo: SdoTracker
    time_span_ns: int
    interfaces: list[Interface] = field(default_factory=list)
    # the series themselves, with keep_series (for plots): round trips in return order,
    # their return timestamps, cycle periods
    round_trip_ns: np.ndarray | None = None
    round_trip_at_ns: np.ndarray | None = None
    cycle_period_ns: np.ndarray | None = None

    @property
    def lost_frames(self) -> int:
        return self.counts["lost_frames"]

    @property
    def wkc_mismatches(self) -> int:
        return int(self.wkc["mismatches"])

    def to_dict(self) -> dict[str, Any]:
        c = self.counts
        aborts = self.sdo.aborts()
        return {
            "schema": SCHEMA,
            "file": self.path,
            "format": self.format,
            "engine": self.engine,
            "frames_total": c["frames_total"],
            "ecat_frames": c["ecat_frames"],
            "non_ecat_frames": c["non_ecat_frames"],
            "malformed_frames": c["malformed_frames"],
            "datagrams_total": c["datagrams_total"],
            "datagrams_by_cmd": self.datagrams_by_cmd,
            "outgoing_frames": c["outgoing_frames"],
            "returned_frames": c["returned_frames"],
            "pairs": c["pairs"],
            "unmatched_outgoing": c["outgoing_frames"] - c["pairs"],
            "unmatched_returned": c["unmatched_returned"],
            "round_trip_us": self.round_trip_stats,
            "round_trip_cyclic_us": self.round_trip_cyclic_stats,
            "cyclic_stream": self.cyclic_stream,
            "cyclic_frames": c["cyclic_frames"],
            # cyclic frames never answered at all (lost_frames also counts late answers)
            "cyclic_unmatched": c["cyclic_frames"] - c["cyclic_pairs"],
            "cycle_period_us": self.cycle_period_stats,
            "cycle_jitter_us": _jitter(self.cycle_period_stats),
            "wkc_mismatches": self.wkc_mismatches,
            "wkc": self.wkc,
            "lost_frames": c["lost_frames"],
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
    chunk_bytes: int = CHUNK_BYTES,
) -> CaptureReport:
    """Analyse a pcap/pcapng file (streaming; bounded memory).

    ``engine`` is ``"auto"`` (C when built, else numba when installed, except for files
    under 2 MB), ``"c"``, ``"numba"`` or ``"python"``; all give identical results.
    ``progress(done_bytes, total_bytes)`` is called once per chunk.
    ``keep_series`` keeps the return timestamp of every pair (for plots).
    Raises :class:`~lolacli.errors.CaptureError` for files that are not captures.
    """
    reader = CaptureReader(path)  # validates the file header
    eng = choose_engine(engine, os.path.getsize(reader.path))
    run = _Pass(reader, eng, eni, S.MODE_LOGICAL, 0, keep_series, chunk_bytes, progress)
    run.run()
    if run.st[S.S_LOGICAL_OUT] == 0 and run.st[S.S_OUT] > 0:
        sig = run.top_stream()
        run = _Pass(reader, eng, eni, S.MODE_SIGNATURE, sig, keep_series, chunk_bytes, progress)
        run.run()
    return run.report()


def _zeros(n: int, py: bool) -> Any:
    return [0] * n if py else np.zeros(n, np.int64)


class _Pass:
    """One scan of the file with fixed cyclic-stream rules."""

    def __init__(
        self,
        reader: CaptureReader,
        engine: str,
        eni: Eni | None,
        mode: int,
        stream_sig: int,
        keep_series: bool,
        chunk_bytes: int,
        progress: Progress | None,
    ) -> None:
        self.reader = reader
        self.engine = engine
        self.k = kernels(engine)
        self.py = engine == "python"
        self.keep_series = keep_series
        self.chunk_bytes = max(chunk_bytes, 1 << 16)
        self.progress = progress
        py = self.py
        self.st = _zeros(S.S_SIZE, py)
        self.st[S.S_MODE] = mode
        self.st[S.S_STREAM_SIG] = stream_sig
        self.cmd_counts = _zeros(256, py)
        self.dg = _zeros(S.MAX_DGRAMS, py)
        self._new_pair_table(PAIR_SLOTS)
        self.sk, self.sc = _zeros(STREAM_SLOTS, py), _zeros(STREAM_SLOTS, py)
        self.wk, self.wv = _zeros(WKC_SLOTS, py), _zeros(WKC_SLOTS, py)
        self.o_rt = _zeros(OUT_ROWS, py)
        self.o_rtts = _zeros(OUT_ROWS, py)
        self.o_rtcyc = _zeros(OUT_ROWS, py)
        self.o_period = _zeros(OUT_ROWS, py)
        self.o_burst = _zeros(OUT_ROWS, py)
        self.o_dc = _zeros(OUT_ROWS, py)
        self.o_mbx = _zeros(OUT_ROWS * S.MBX_COLS, py)
        self.o_wkc = _zeros(OUT_ROWS * S.WKC_COLS, py)
        self.ifs = _zeros(5 * 64, py)
        self.n_if = 0
        self.interfaces: list[Interface] = []
        self.big = reader.header.big_endian
        self.rt_cyclic: list[np.ndarray] = []  # round trips of cyclic frames
        self.rt_other: list[np.ndarray] = []  # of all other pairs
        self.rt_series: list[np.ndarray] = []  # all, in order (keep_series)
        self.rt_ts: list[np.ndarray] = []
        self.periods: list[np.ndarray] = []
        self.bursts = np.zeros(0, np.int64)
        self.dc_values: list[np.ndarray] = []
        self.wkc_rows: list[list[int]] = []
        self.sdo = SdoTracker()
        self.stopped_at: int | None = None
        if eni is not None:
            self._load_eni(eni)

    # --- tables ----------------------------------------------------------------------
    def _new_pair_table(self, slots: int) -> None:
        py = self.py
        self.pk, self.pn = _zeros(slots, py), _zeros(slots, py)
        self.pts, self.pmeta = _zeros(slots * S.DEPTH, py), _zeros(slots * S.DEPTH, py)

    def _grow(self) -> None:
        st, py, k = self.st, self.py, self.k
        if st[S.S_P_USED] * 2 > len(self.pk):
            live = sum(1 for n in self.pn if n) if py else int(np.count_nonzero(self.pn))
            slots = len(self.pk) * (2 if live * 4 > len(self.pk) else 1)
            old = (self.pk, self.pn, self.pts, self.pmeta)
            self._new_pair_table(slots)
            st[S.S_P_USED] = k.rehash(*old, self.pk, self.pn, self.pts, self.pmeta, False)
        if st[S.S_S_USED] * 2 > len(self.sk):
            self.sk, self.sc, st[S.S_S_USED] = self._grow_kv(self.sk, self.sc)
        if st[S.S_W_USED] * 2 > len(self.wk):
            self.wk, self.wv, st[S.S_W_USED] = self._grow_kv(self.wk, self.wv)

    def _grow_kv(self, keys: Any, vals: Any) -> tuple[Any, Any, int]:
        nk, nv = _zeros(len(keys) * 2, self.py), _zeros(len(keys) * 2, self.py)
        empty = _zeros(0, self.py)
        used = self.k.rehash(keys, vals, empty, empty, nk, nv, empty, empty, True)
        return nk, nv, used

    def _load_eni(self, eni: Eni) -> None:
        """Expected WKC per cyclic command from the ENI's ``<Cnt>`` (lookup only)."""
        entries: dict[int, int] = {}
        for cyclic in eni.cyclic:
            for frame in cyclic.frames:
                for c in frame.commands:
                    if c.expected_wkc is None:
                        continue
                    if c.logical_address is not None:
                        address = c.logical_address
                    else:
                        address = ((c.ado or 0) << 16) | (c.adp or 0)
                    akey = S._addr_key(c.cmd, address & 0xFFFFFFFF)
                    key = S._key(S._mix(S._mix(S._mix(S.SEED_WKC, c.cmd), akey),
                                        c.data_length_bytes))
                    entries[key] = c.expected_wkc
        while len(entries) * 2 > len(self.wk):
            self.wk, self.wv = _zeros(len(self.wk) * 2, self.py), _zeros(len(self.wk) * 2, self.py)
        for key, value in entries.items():
            i = S._slot(self.wk, key)
            self.wk[i] = key
            self.wv[i] = value
        self.st[S.S_W_USED] = len(entries)
        self.st[S.S_WKC_FIXED] = 1
        self.eni_commands = len(entries)

    def top_stream(self) -> int:
        if self.py:
            best = max(range(len(self.sk)), key=lambda i: self.sc[i])
            return int(self.sk[best])
        return int(self.sk[int(np.argmax(self.sc))])

    # --- the pass ------------------------------------------------------------------------
    def run(self) -> None:
        path = self.reader.path
        total = os.path.getsize(path)
        buf = np.empty(self.chunk_bytes, np.uint8)
        fmt = self.reader.header.format
        with open(path, "rb") as f:
            base = 0  # file offset of buf[0]
            pos = PCAP_HEADER_BYTES if fmt == FORMAT_PCAP else 0
            end, eof = 0, False
            f.seek(0)
            end, eof = _fill(f, buf, 0)
            while True:
                view = buf[:end].tobytes() if self.py else buf
                pos, status = self.k.scan(
                    view, pos, end, eof, fmt, self.big, self.reader.header.nanoseconds,
                    self.ifs, self.n_if, self.st, self.cmd_counts, self.dg,
                    self.pk, self.pn, self.pts, self.pmeta, self.sk, self.sc, self.wk, self.wv,
                    self.o_rt, self.o_rtts, self.o_rtcyc, self.o_period, self.o_burst,
                    self.o_dc, self.o_mbx, self.o_wkc,
                )
                self._drain(view)
                if status == S.ST_DONE:
                    break
                if status == S.ST_CORRUPT:
                    self.st[S.S_MALFORMED] += 1
                    self.stopped_at = base + pos
                    break
                if status == S.ST_GROW:
                    self._grow()
                    continue
                if status == S.ST_BLOCK:
                    need = self._block(buf, pos, end, eof, base)
                    if need == 0:
                        pos = self._block_done
                        continue
                    if need < 0:
                        self.st[S.S_MALFORMED] += 1
                        self.stopped_at = base + pos
                        break
                elif status == S.ST_FLUSH:
                    continue
                # need more bytes: keep the unread tail, read behind it
                if eof:
                    break
                buf, end, eof = _shift_and_fill(f, buf, pos, end)
                base += pos
                pos = 0
                if self.progress is not None:
                    self.progress(min(base, total), total)
        self.k.finish(self.st, self.o_burst)
        self._drain(b"")
        if self.progress is not None:
            self.progress(total, total)
        if self.interfaces and not any(i.is_ethernet for i in self.interfaces):
            types = sorted({i.link_type for i in self.interfaces})
            raise CaptureError(
                f"no Ethernet interface in the capture (link types {types})", path=str(path)
            )

    def _block(self, buf: np.ndarray, pos: int, end: int, eof: bool, base: int) -> int:
        """A pcapng SHB or IDB at ``pos``: 0 handled, 1 need more bytes, -1 corrupt."""
        if pos + 12 > end:
            return -1 if eof else 1
        head = buf[pos : pos + 12].tobytes()
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
                iface = parse_idb(buf[pos : pos + total].tobytes(), self.big)
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
            grown = _zeros(len(self.ifs) * 2, self.py)
            grown[: len(self.ifs)] = self.ifs[:]
            self.ifs = grown
        mode, a, b, off = iface.ts_params()
        base = self.n_if * 5
        for j, v in enumerate((mode, a, b, off, 1 if iface.is_ethernet else 0)):
            self.ifs[base + j] = v
        self.n_if += 1

    def _drain(self, view: Any) -> None:
        st = self.st
        n = int(st[S.S_N_RT])
        if n:
            rt = np.array(self.o_rt[:n], np.int64)
            cyc = np.array(self.o_rtcyc[:n], np.int64) != 0
            self.rt_cyclic.append(_compact(rt[cyc]))
            self.rt_other.append(_compact(rt[~cyc]))
            if self.keep_series:
                self.rt_series.append(rt)
                self.rt_ts.append(np.array(self.o_rtts[:n], np.int64))
        n = int(st[S.S_N_PERIOD])
        if n:
            self.periods.append(_compact(np.array(self.o_period[:n], np.int64)))
        n = int(st[S.S_N_BURST])
        if n:
            counts = np.bincount(np.array(self.o_burst[:n], np.int64))
            if counts.size > self.bursts.size:
                counts[: self.bursts.size] += self.bursts
                self.bursts = counts
            else:
                self.bursts[: counts.size] += counts
        n = int(st[S.S_N_DC])
        if n:
            self.dc_values.append(np.array(self.o_dc[:n], np.int64))
        n = int(st[S.S_N_WKCBAD])
        for r in range(min(n, WKC_DETAIL_ROWS - len(self.wkc_rows))):
            self.wkc_rows.append([int(v) for v in self.o_wkc[r * S.WKC_COLS:(r + 1) * S.WKC_COLS]])
        n = int(st[S.S_N_MBX])
        for r in range(n):
            row = [int(v) for v in self.o_mbx[r * S.MBX_COLS:(r + 1) * S.MBX_COLS]]
            frame, ts, q, cmd, address, ln = row[:6]
            data = bytes(view[q + 10 : q + 10 + ln])
            self.sdo.feed(frame, ts, cmd, address, data)
        for i in (S.S_N_RT, S.S_N_PERIOD, S.S_N_BURST, S.S_N_DC, S.S_N_WKCBAD, S.S_N_MBX):
            st[i] = 0

    # --- result ----------------------------------------------------------------------
    def report(self) -> CaptureReport:
        st = [int(v) for v in self.st]
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
            "lost_frames": st[S.S_LOST],
            "vlan_frames": st[S.S_VLAN],
            "udp_frames": st[S.S_UDP],
            "non_command_ecat_frames": st[S.S_ECAT_OTHER],
            "snaplen_cut_frames": st[S.S_CUT],
            "non_ethernet_packets": st[S.S_NON_ETH],
            "skipped_blocks": st[S.S_SKIPPED],
        }
        keep = self.keep_series
        keep = self.keep_series
        counts["cyclic_pairs"] = sum(int(c.size) for c in self.rt_cyclic)
        rt_cyclic_stats = summary_us(self.rt_cyclic)
        rt_stats = summary_us(self.rt_cyclic + self.rt_other)
        period_stats = summary_us(self.periods)
        mode = "logical" if st[S.S_MODE] == S.MODE_LOGICAL else "signature"
        return CaptureReport(
            path=str(self.reader.path),
            format="pcap" if self.reader.header.format == FORMAT_PCAP else "pcapng",
            engine=self.engine,
            counts=counts,
            datagrams_by_cmd=by_cmd,
            round_trip_stats=rt_stats,
            round_trip_cyclic_stats=rt_cyclic_stats,
            cycle_period_stats=period_stats,
            cyclic_stream=mode,
            wkc=self._wkc_dict(st),
            dc=self._dc_dict(st),
            sdo=self.sdo,
            time_span_ns=st[S.S_END_TS] - st[S.S_FIRST_TS],
            interfaces=list(self.interfaces),
            round_trip_ns=_take(self.rt_series) if keep else None,
            round_trip_at_ns=_take(self.rt_ts) if keep else None,
            cycle_period_ns=_take(self.periods) if keep else None,
        )

    def _wkc_dict(self, st: list[int]) -> dict[str, Any]:
        return {
            "reference": "eni" if st[S.S_WKC_FIXED] else "first-seen",
            "checked_datagrams": st[S.S_WKC_CHECKED],
            "mismatches": st[S.S_WKC_MISMATCH],
            "first_mismatches": [
                {"frame": r[0], "cmd": mnemonic(r[1]), "address": f"0x{r[2]:08X}",
                 "expected": r[3], "received": r[4]}
                for r in self.wkc_rows[:20]
            ],
        }

    def _dc_dict(self, st: list[int]) -> dict[str, Any]:
        sizes = np.repeat(np.arange(self.bursts.size), self.bursts)
        values = _cat(self.dc_values, np.int64)
        return {
            "drift_compensation_datagrams": st[S.S_DC_DGRAMS],
            "drift_compensation_bursts": int(sizes.size),
            "burst_size": None
            if sizes.size == 0
            else {"min": int(sizes.min()), "median": float(np.median(sizes)),
                  "max": int(sizes.max())},
            "burst_gap_us": S.BURST_GAP_NS / 1000.0,
            "system_time_difference_reads": int(values.size),
            "system_time_difference_max_abs_ns": int(np.abs(values).max()) if values.size else None,
            "system_time_difference_last_ns": int(values[-1]) if values.size else None,
        }


def _cat(parts: list[np.ndarray], dtype: Any) -> np.ndarray:
    if not parts:
        return np.zeros(0, dtype)
    return np.concatenate(parts).astype(dtype, copy=False)


def _take(parts: list[np.ndarray]) -> np.ndarray:
    """Concatenate drained chunks (numpy promotes mixed int32/int64 chunks to int64) and
    empty the list, so that the chunks are freed as soon as the whole is built."""
    if not parts:
        return np.zeros(0, np.int64)
    whole = np.concatenate(parts)
    parts.clear()
    return whole


def _compact(values: np.ndarray) -> np.ndarray:
    """int32 when the nanosecond values fit (±2.1 s), halving the memory of long series."""
    if values.size and -(2**31) < values.min() and values.max() < 2**31:
        return values.astype(np.int32)
    return values


def _fill(f: Any, buf: np.ndarray, start: int) -> tuple[int, bool]:
    """Read into ``buf[start:]``; returns (end, eof)."""
    view = buf.data[start:]
    got = 0
    while got < len(view):
        n = f.readinto(view[got:])
        if not n:
            return start + got, True
        got += n
    return start + got, False


def _shift_and_fill(f: Any, buf: np.ndarray, pos: int, end: int) -> tuple[np.ndarray, int, bool]:
    """Move the unread tail to the front (growing the buffer for a large block) and read."""
    tail = end - pos
    if tail * 2 > buf.size:
        grown = np.empty(buf.size * 2, np.uint8)
        grown[:tail] = buf[pos:end]
        buf = grown
    else:
        buf[:tail] = buf[pos:end]
    end, eof = _fill(f, buf, tail)
    return buf, end, eof
