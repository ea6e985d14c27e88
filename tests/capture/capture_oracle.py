"""tshark as the decoding oracle for capture tests, and an independent pairing.

Everything here is written from tshark's field output and DESIGN.md, without using
lolacli's scanner, so that the tests compare two separate implementations.
"""

from __future__ import annotations

import functools
import shutil
import subprocess
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

MNEMONICS = [
    "NOP", "APRD", "APWR", "APRW", "FPRD", "FPWR", "FPRW", "BRD", "BWR", "BRW",
    "LRD", "LWR", "LRW", "ARMW", "FRMW",
]
LOGICAL = {10, 11, 12}
ADP_INCREMENTED = {1, 2, 3, 13, 7, 8, 9}  # auto-increment and broadcast

FIELDS = ["frame.number", "frame.time_epoch", "eth.src", "ecat.cmd", "ecat.idx",
          "ecat.adp", "ecat.ado", "ecat.lad", "ecat.cnt"]


@dataclass(frozen=True)
class OracleFrame:
    number: int
    ts_ns: int
    returned: bool
    datagrams: tuple[tuple[int, int, int], ...]  # (cmd, idx, address key)
    wkcs: tuple[int, ...]

    @property
    def pair_key(self) -> tuple[tuple[int, int, int], ...]:
        return self.datagrams


def tshark_available() -> bool:
    return shutil.which("tshark") is not None


def _ns(epoch: str) -> int:
    sec, _, frac = epoch.partition(".")
    return int(sec) * 1_000_000_000 + int((frac + "000000000")[:9])


def _ints(field: str) -> list[int]:
    return [int(v, 0) for v in field.split(",")] if field else []


@functools.cache
def tshark_frames(path: Path) -> tuple[OracleFrame, ...]:
    """Every frame tshark decodes as EtherCAT commands (``ecat``), in file order."""
    cmd = ["tshark", "-r", str(path), "-Y", "ecat", "-T", "fields", "-E", "separator=\t"]
    for f in FIELDS:
        cmd += ["-e", f]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    frames = []
    for line in out.splitlines():
        cols = line.split("\t")
        number, epoch, src = int(cols[0]), cols[1], cols[2]
        cmds, idxs = _ints(cols[3]), _ints(cols[4])
        adps, ados, lads, wkcs = _ints(cols[5]), _ints(cols[6]), _ints(cols[7]), _ints(cols[8])
        datagrams = []
        for c, i in zip(cmds, idxs, strict=True):
            if c in LOGICAL:
                key = lads.pop(0)
            else:
                adp, ado = adps.pop(0), ados.pop(0)
                key = (ado << 16) if c in ADP_INCREMENTED else (ado << 16) | adp
            datagrams.append((c, i, key))
        returned = bool(int(src.split(":")[0], 16) & 0x02)
        frames.append(OracleFrame(number, _ns(epoch), returned, tuple(datagrams), tuple(wkcs)))
    return tuple(frames)


def datagrams_by_cmd(frames: tuple[OracleFrame, ...]) -> dict[str, int]:
    counts: Counter[str] = Counter()
    for fr in frames:
        for c, _, _ in fr.datagrams:
            counts[MNEMONICS[c] if c < len(MNEMONICS) else f"CMD{c}"] += 1
    return dict(counts)


def pair(frames: tuple[OracleFrame, ...]) -> list[int]:
    """DESIGN.md Pairing: each returned frame takes the most recent unmatched outgoing
    frame with the same (command, index, address) sequence. Round trips in ns."""
    return [rt for _, rt in pair_series(frames)]


def pair_series(frames: tuple[OracleFrame, ...]) -> list[tuple[int, int]]:
    """(return timestamp, round trip) of every pair, in the order the returns were
    captured, both in ns (the pairing of :func:`pair`)."""
    pending: dict[tuple, list[int]] = {}
    pairs = []
    for fr in frames:
        if not fr.returned:
            pending.setdefault(fr.pair_key, []).append(fr.ts_ns)
        elif pending.get(fr.pair_key):
            pairs.append((fr.ts_ns, fr.ts_ns - pending[fr.pair_key].pop()))
    return pairs


def cyclic_periods(frames: tuple[OracleFrame, ...]) -> list[int]:
    """Periods of outgoing frames that carry a logical datagram."""
    ts = [f.ts_ns for f in frames
          if not f.returned and any(c in LOGICAL for c, _, _ in f.datagrams)]
    return [b - a for a, b in zip(ts, ts[1:], strict=False)]


def percentile(values: list[float], q: float) -> float:
    """Linear-interpolation percentile (numpy's default), written out."""
    s = sorted(values)
    pos = (len(s) - 1) * q / 100.0
    lo = int(pos)
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


@functools.cache
def last_packet_ns(path: Path) -> int:
    """Timestamp of the capture's last packet (any protocol), per tshark."""
    out = subprocess.run(["tshark", "-r", str(path), "-T", "fields", "-e", "frame.time_epoch"],
                         capture_output=True, text=True, check=True).stdout.split()
    return _ns(out[-1])


@dataclass(frozen=True)
class Fates:
    timeout_ns: int
    lost: tuple[int, ...]  # outgoing frame numbers
    in_flight: tuple[int, ...]
    late: tuple[int, ...]  # outgoing frame numbers of pairs answered after the timeout


def fates(frames: tuple[OracleFrame, ...], end_ns: int) -> Fates:
    """DESIGN.md "Lost frame", written out: pair as DESIGN.md "Pairing" says; an outgoing
    frame left unpaired is lost, unless sent within the last timeout of the capture (10 x
    the median round trip, at least 1 ms); a pair answered after the timeout is late."""
    pending: dict[tuple, list[OracleFrame]] = {}
    pairs: list[tuple[int, int]] = []  # (round trip, outgoing frame number)
    for fr in frames:
        if not fr.returned:
            pending.setdefault(fr.pair_key, []).append(fr)
        elif pending.get(fr.pair_key):
            out = pending[fr.pair_key].pop()
            pairs.append((fr.ts_ns - out.ts_ns, out.number))
    rts = sorted(rt for rt, _ in pairs)
    if rts:
        n = len(rts)
        timeout = max(5 * (rts[(n - 1) // 2] + rts[n // 2]), 1_000_000)  # 10 x median
    else:
        timeout = 1_000_000
    left = sorted((f for v in pending.values() for f in v), key=lambda f: f.number)
    return Fates(
        timeout,
        tuple(f.number for f in left if f.ts_ns <= end_ns - timeout),
        tuple(f.number for f in left if f.ts_ns > end_ns - timeout),
        tuple(sorted(n for rt, n in pairs if rt > timeout)),
    )
