"""The compiled engines against the plain-Python reference on damaged real captures.

Each corpus capture (its first 48 KiB) is mutated many times: bytes flipped anywhere after
the file header, records cut short, lengths overwritten. Whatever the damage, the C (and
numba) scanner must report exactly what scan.py reports, or fail with the same error.
"""

from __future__ import annotations

import random

import pytest
from conftest import corpus_files, corpus_ids

from lolacli.capture.analyze import analyze_file
from lolacli.errors import CaptureError

CAPTURES = corpus_files("pcap")
HEAD_BYTES = 48 * 1024
VARIANTS = 12


def _outcome(path, engine):
    try:
        rep = analyze_file(path, engine=engine).to_dict()
    except CaptureError as exc:
        return ("error", str(exc))
    rep.pop("engine")
    return rep


def _mutate(data: bytes, rnd: random.Random) -> bytes:
    b = bytearray(data)
    kind = rnd.randrange(3)
    if kind == 0:      # flip bytes
        for _ in range(rnd.randrange(1, 40)):
            b[rnd.randrange(24, len(b))] = rnd.randrange(256)
    elif kind == 1:    # overwrite a 32-bit word with a large or odd length
        p = rnd.randrange(24, len(b) - 4)
        b[p:p + 4] = rnd.choice([0xFFFFFFFF, 0x7FFFFFFF, 13, 0, 0x1000000]).to_bytes(4, "little")
    else:              # cut the file somewhere
        del b[rnd.randrange(24, len(b)):]
    return bytes(b)


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_engines_agree_on_damaged_captures(path, fast, tmp_path):
    data = path.read_bytes()[:HEAD_BYTES]
    rnd = random.Random(path.name)
    for k in range(VARIANTS):
        damaged = tmp_path / f"{k}{path.suffix}"
        damaged.write_bytes(_mutate(data, rnd))
        assert _outcome(damaged, fast) == _outcome(damaged, "python"), (path.name, k)


def _lrw(ret: bool) -> bytes:
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    d = Datagram.logical(Command.LRW, 0x10000, 8, index=1, wkc=3 if ret else 0)
    return encode_frame(make_frame([d], src=b"\x02" * 6 if ret else b"\x00" * 6), pad=True)


@pytest.mark.parametrize(
    "tsresol, tsoffset_s, units, malformed",
    [
        (9, 0, 1 << 63, 2),                 # raw timestamp with the top bit set
        (9, 0, (1 << 62) + 5, 2),           # beyond 2^62 ns (year 2116)
        (0, 0, 5_000_000_000, 2),           # 5e9 seconds at 10^0 resolution: too late
        (0x7F, 0, 123_456_789, 0),          # 10^-127 s: every timestamp is 0 ns
        (0x80 | 127, 0, 1 << 62, 0),        # 2^-127 s
        (0x80 | 64, 0, (1 << 63) - 1, 0),   # 2^-64 s: a fraction of a second
        (9, -(10**9), 1_000, 0),            # a negative offset (-31.7 years)
        (9, 10**10, 1_000, 1),              # an offset of 317 years: a damaged IDB
    ],
)
def test_engines_agree_on_extreme_timestamps(tmp_path, fast, tsresol, tsoffset_s, units,
                                             malformed):
    from lolacli.capture import writer as w

    body = w.shb() + w.idb(tsresol=tsresol, tsoffset_s=tsoffset_s)
    body += w.epb(units, _lrw(False)) + w.epb(units, _lrw(True))
    path = tmp_path / "extreme.pcapng"
    path.write_bytes(body)
    got = _outcome(path, fast)
    assert got == _outcome(path, "python")
    assert got["malformed_frames"] == malformed


def test_interface_block_too_short_is_damage_not_a_crash(tmp_path, fast, cli):
    import struct

    from lolacli.capture import writer as w
    from lolacli.capture.reader import CaptureReader

    path = tmp_path / "short-idb.pcapng"
    path.write_bytes(w.shb() + struct.pack("<III", 1, 12, 12) + w.idb() + w.epb(1, _lrw(False)))
    got = _outcome(path, fast)
    assert got == _outcome(path, "python")
    assert got["malformed_frames"] == 1 and got["frames_total"] == 0
    reader = CaptureReader(path)
    assert list(reader) == [] and reader.stats.malformed_records == 1
    code, _, err = cli("capture", "list", str(path))
    assert code == 0 and "Traceback" not in err
