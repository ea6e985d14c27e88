"""The compiled engines against the plain-Python reference on damaged real captures.

Each corpus capture (its first 48 KiB) is mutated many times: bytes flipped anywhere after
the file header, records cut short, lengths overwritten. Whatever the damage, the C
scanner must report exactly what scan.py reports, or fail with the same error.
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


def _datagram(cmd: int, address: int, data: bytes, more: bool, wkc: int) -> bytes:
    import struct

    head = struct.pack("<BBIHH", cmd, 0, address, len(data) | (0x8000 if more else 0), 0)
    return head + data + struct.pack("<H", wkc)


def _wide_frame(first_address: int, ret: bool) -> bytes:
    """An LRW and 127 FPRDs to distinct stations: 128 datagrams, 128 new WKC keys."""
    import struct

    dgs = [(12, 0x10000, bytes(8))]
    dgs += [(4, ((first_address + j) << 16) | 0x130, bytes(1)) for j in range(127)]
    body = b"".join(_datagram(c, a, d, j < len(dgs) - 1, 1 if ret else 0)
                    for j, (c, a, d) in enumerate(dgs))
    src = b"\x02" * 6 if ret else b"\x00" * 6
    ecat_header = struct.pack("<H", 0x1000 | len(body))
    return b"\xff" * 6 + src + struct.pack(">H", 0x88A4) + ecat_header + body


@pytest.mark.timeout(120)
def test_many_new_wkc_keys_in_a_few_frames_do_not_hang(tmp_path, fast):
    """Each returned cyclic frame may add MAX_DGRAMS keys to the WKC table (256 slots):
    four such frames between two table checks used to fill it, and the open-addressing
    lookup then looped forever (every engine). The table is now checked every record."""
    from lolacli.capture import writer as w

    frames = []
    for k in range(4):
        frames += [_wide_frame(k * 1000, False), _wide_frame(k * 1000, True)]
    path = tmp_path / "wide.pcap"
    path.write_bytes(w.pcap_header() + b"".join(
        w.pcap_record(i * 1000, f) for i, f in enumerate(frames)))
    got = _outcome(path, fast)
    assert got == _outcome(path, "python")
    assert got["wkc"]["checked_datagrams"] == 4 * 128 and got["pairs"] == 4


def test_c_kernel_refuses_state_it_would_index_out_of_bounds_with():
    """Besides array sizes, the wrapper checks the values the C code indexes with or
    divides by: output row counters, pairing stack depths, interface parameters."""
    import numpy as np

    from lolacli.capture import scan as S
    from lolacli.capture.cengine import CKernels, c_available

    if not c_available():
        pytest.skip("the C kernel is not built")
    k = CKernels()
    z = lambda n: np.zeros(n, np.int64)  # noqa: E731
    rows, slots = 1 << 14, 256
    ifs = np.array([0, 1, 1, 0, 1], np.int64)  # one Ethernet interface, ns resolution

    def call(st=None, pn=None, ifs=ifs, n_if=1):
        st = z(S.S_SIZE) if st is None else st
        pn = z(slots) if pn is None else pn
        obs = 2 * slots
        return k.scan(np.zeros(8, np.uint8), 0, 8, True, 1, False, False, ifs, n_if, st,
                      z(256), z(S.MAX_DGRAMS), z(slots), pn, z(slots * S.DEPTH * S.PCOLS),
                      z(slots), z(slots), z(obs), z(obs), z(obs * S.OCOLS), z(rows),
                      z(rows), z(rows), z(rows), z(rows), z(rows), z(rows * S.MBX_COLS),
                      z(rows * S.CFG_COLS), z(rows * S.EVICT_COLS), z(rows * S.CTR_COLS))

    assert call()[1] == S.ST_CORRUPT  # 8 zero bytes: a block of length 0
    negative_row = z(S.S_SIZE)
    negative_row[S.S_N_DC] = -1
    negative_counts = [z(S.S_SIZE) for _ in range(3)]
    negative_counts.append(z(S.S_SIZE))
    for st, i in zip(negative_counts, (S.S_N_CFG, S.S_BACKWARDS, S.S_MALFORMED, S.S_N_CTR),
                     strict=True):
        st[i] = -1  # these index st and the output rows
    deep = z(slots)
    deep[7] = S.DEPTH + 1
    for bad in (dict(st=negative_row), *(dict(st=st) for st in negative_counts), dict(pn=deep),
                dict(n_if=-1),
                dict(ifs=np.array([0, 1, 0, 0, 1], np.int64)),        # divisor 0
                dict(ifs=np.array([1, -3, 0, 0, 1], np.int64)),       # negative shift
                dict(ifs=np.array([0, 1, 1, 1 << 62, 1], np.int64))):  # offset overflows
        with pytest.raises(ValueError):
            call(**bad)
    with pytest.raises(ValueError):
        k.finish(negative_row * 0 - 1, z(4))


def test_time_span_starts_at_the_first_analysed_frame(tmp_path, fast):
    """A first packet that is not analysed (here on a raw-IP interface) is counted as a
    frame but has no time: the span used to start at 0 ns (54 years, not 5 µs)."""
    from lolacli.capture import writer as w

    t0 = 1_700_000_000 * 10**9
    body = w.shb() + w.idb(link_type=101) + w.idb()
    body += w.epb(t0, b"\x45" + bytes(40), interface=0)
    body += w.epb(t0 + 1000, _lrw(False), interface=1) + w.epb(t0 + 6000, _lrw(True), interface=1)
    path = tmp_path / "span.pcapng"
    path.write_bytes(body)
    got = _outcome(path, fast)
    assert got == _outcome(path, "python")
    assert got["frames_total"] == 3 and got["time_span_us"] == 5.0


def test_engines_hash_frames_alike_in_signature_mode(tmp_path, fast):
    """Without logical traffic the cyclic stream is the most frequent frame signature; on
    a tie the table order of the hashed signatures decides. numba (LLVM; that engine is
    gone, the rule holds for C) once dropped the
    63-bit mask after the hash's wrapping multiply (signed overflow is undefined there):
    its keys, and so its stream, differed from Python's. Addresses with bit 31 set and
    40 frame kinds, one round trip each (kind k: k+1 µs), so a key difference shows."""
    import struct

    from lolacli.capture import writer as w

    def kind(k: int, ret: bool) -> bytes:
        dgs = [(4, (0x8000 + 0x111 * k) << 16 | (0x1000 + k), bytes(2)),
               (5, (0xC000 + k) << 16 | 0x7, bytes(4))][: 1 + k % 2]
        body = b"".join(_datagram(c, a, d, j < len(dgs) - 1, 1 if ret else 0)
                        for j, (c, a, d) in enumerate(dgs))
        src = b"\x02" * 6 if ret else b"\x00" * 6
        return (b"\xff" * 6 + src + struct.pack(">H", 0x88A4)
                + struct.pack("<H", 0x1000 | len(body)) + body)

    records = []
    for k in range(40):
        t = k * 1_000_000
        records += [w.pcap_record(t, kind(k, False), ns=True),
                    w.pcap_record(t + (k + 1) * 1000, kind(k, True), ns=True)]
    path = tmp_path / "tie.pcap"
    path.write_bytes(w.pcap_header(ns=True) + b"".join(records))
    got = _outcome(path, fast)
    assert got == _outcome(path, "python")
    assert got["cyclic_stream"] == "signature" and got["cyclic_frames"] == 1


def _rich_capture(cooked: bool) -> bytes:
    """Every path of the scanner in one file: a master whose MAC has the locally
    administered bit (direction inferred), a resent lost frame, FMMU, station-address and
    AL-control writes, AL status reads, WKC changes, a backward timestamp; as Ethernet, or
    as Linux cooked v2 (then the packet type tells the direction) beside an Ethernet
    interface."""
    import struct

    from lolacli.capture import writer as w
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    mac = bytes.fromhex("cadecadedeff")
    t = [1_700_000_000 * 10**9]
    out: list[bytes] = []

    def emit(datagrams, ret: bool, dt: int = 30_000) -> None:  # noqa: ANN001
        eth = encode_frame(make_frame(datagrams, src=mac), pad=True)
        t[0] += dt
        if cooked:
            head = struct.pack(">HHIHBB8s", 0x88A4, 0, 2, 1, 0 if ret else 4, 6,
                               mac.ljust(8, b"\0"))
            out.append(w.epb(t[0], head + eth[14:], interface=1))
        else:
            out.append(w.epb(t[0], eth))

    P = Datagram.physical  # noqa: N806
    for k in range(3):
        station = 0x1001 + k
        for ret in (False, True):
            emit([P(Command.APWR, (-k) & 0xFFFF if not ret else 3 - k, 0x0010,
                    struct.pack("<H", station), index=k, wkc=int(ret))], ret)
        fmmu = struct.pack("<IHBBHBBB3x", k * 4, 4, 0, 7, 0x1000, 0, 3, 1)
        for ret in (False, True):
            emit([P(Command.FPWR, station, 0x0600, fmmu, index=k + 8, wkc=int(ret))], ret)
    for ret in (False, True):
        emit([P(Command.BWR, 3 if ret else 0, 0x0120, b"\x08\x00", index=20, wkc=3 * ret)], ret)
    # the error counters (0x0300, 20 bytes) read twice, three APRDs in one frame: slave 2
    # counts invalid frames on port 0 in between (errors enter between slaves 1 and 2);
    # an FPRD of station 0x1003, once unanswered (WKC 0 back), then answered
    for rise in (0, 5):
        for ret in (False, True):
            emit([P(Command.APRD, -k + 3 * ret, 0x0300,
                    bytes([rise if k == 1 else 0]) + bytes(19) if ret else 20,
                    index=24, wkc=int(ret)) for k in range(3)], ret)
    emit([P(Command.FPRD, 0x1003, 0x0300, 20, index=25)], False)
    emit([P(Command.FPRD, 0x1003, 0x0300, 20, index=25)], True)
    emit([P(Command.FPRD, 0x1003, 0x0300, 20, index=25)], False, 40_000_000)
    emit([P(Command.FPRD, 0x1003, 0x0300, bytes(20), index=25, wkc=1)], True)
    lost = P(Command.FPRD, 0x1002, 0x0130, 2, index=21)
    emit([lost], False)
    emit([lost], False, 40_000_000)  # resent 40 ms later, answered
    emit([P(Command.FPRD, 0x1002, 0x0130, struct.pack("<HHH", 0x14, 0, 0x1B)[:2], index=21,
            wkc=1)], True)
    for i in range(60):
        wkc = 9 if i < 40 else 6
        lrw = [Datagram.logical(Command.LRW, 0, 12, index=i, wkc=0),
               P(Command.BRD, 0, 0x0130, 2, index=i)]
        emit(lrw, False, 1_000_000)
        emit([Datagram.logical(Command.LRW, 0, 12, index=i, wkc=wkc),
              P(Command.BRD, 3, 0x0130, b"\x08\x00", index=i, wkc=3)], True)
        if i == 30:
            t[0] -= 2_500_000  # the clock steps back
    head = w.shb() + (w.idb(link_type=1) + w.idb(link_type=276) if cooked else w.idb())
    return head + b"".join(out)


@pytest.mark.parametrize("cooked", [False, True], ids=["inferred", "sll2"])
def test_engines_agree_on_every_path_and_its_damage(tmp_path, fast, cooked):
    data = _rich_capture(cooked)
    path = tmp_path / "rich.pcapng"
    path.write_bytes(data)
    whole = _outcome(path, fast)
    assert whole == _outcome(path, "python")
    assert whole["direction_rule"] == ("packet_type" if cooked else "inferred")
    kinds = [f["kind"] for f in whole["findings"]]
    assert {"lost", "wkc-mismatch", "not-op", "timestamps-backwards"} <= set(kinds), kinds
    lrw = [g for g in whole["wkc"]["datagrams"] if g["cmd"] == "LRW"]
    assert lrw[0]["expected"] == 9  # 3 slaves x (2 + 1), from the FMMU writes
    # the scanner's rows of the error counter reads (o_ctr), decoded by the driver
    counters = whole["error_counters"]
    assert counters["reads"] == 7 and counters["positions_from"] == "station order"
    link = counters["suspect_link"]
    assert (link["upstream"], link["downstream"], link["port"]) == (1, 2, 0)
    assert "bad-link" in kinds
    rnd = random.Random(7 + cooked)
    for k in range(VARIANTS * 2):
        damaged = tmp_path / f"{k}.pcapng"
        damaged.write_bytes(_mutate(data, rnd))
        assert _outcome(damaged, fast) == _outcome(damaged, "python"), k


def test_counter_reads_of_a_far_position_do_not_recurse(tmp_path, fast):
    """An APRD of 0x0300 whose address says position 40,000 (damage, or a long line): the
    line's frame path is built without recursion, and both engines name the same link."""
    import struct

    from lolacli.capture import writer as w
    from lolacli.capture.counters import line_path
    from lolacli.wire.error_counters import frame_path

    assert all(line_path(n) == frame_path(list(range(n))) for n in range(60))
    far = (-(40_000 - 1)) & 0xFFFF
    frames = []
    for rise in (0, 3):
        for ret in (False, True):
            data = (bytes([rise]) + bytes(19)) if ret else bytes(20)
            frames.append(b"\xff" * 6 + (b"\x02" if ret else b"\x00") * 6
                          + struct.pack(">H", 0x88A4) + struct.pack("<H", 0x1000 | 32)
                          + _datagram(1, (0x0300 << 16) | far, data, False, int(ret)))
    path = tmp_path / "far.pcap"
    path.write_bytes(w.pcap_header() + b"".join(
        w.pcap_record(i * 1000, f) for i, f in enumerate(frames)))
    got = _outcome(path, fast)
    assert got == _outcome(path, "python")
    assert got["error_counters"]["reads"] == 2
    link = got["error_counters"]["suspect_link"]
    assert (link["upstream"], link["downstream"], link["port"]) == (39_999, 40_000, 0)
