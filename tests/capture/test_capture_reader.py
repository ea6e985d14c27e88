"""Reader unit tests on synthetic files: byte orders, resolutions, sections, damage."""

from __future__ import annotations

import json
import os

import pytest

from lolacli.capture import writer as w
from lolacli.capture.analyze import analyze_file
from lolacli.capture.reader import CaptureReader, ts_params, ts_to_ns
from lolacli.errors import CaptureError, UsageError
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram, encode_frame, make_frame

OUT_MAC = b"\x10\x10\x10\x10\x10\x10"
RET_MAC = b"\x12\x10\x10\x10\x10\x10"


def ecat(cmd: int, idx: int, wkc: int = 0, ret: bool = False, adp: int = 0, ado: int = 0x130,
         n: int = 2) -> bytes:
    d = Datagram.physical(cmd, adp, ado, n, index=idx, wkc=wkc)
    return encode_frame(make_frame([d], src=RET_MAC if ret else OUT_MAC), pad=True)


def lrw(idx: int, wkc: int = 0, ret: bool = False) -> bytes:
    d = Datagram.logical(Command.LRW, 0x10000, 8, index=idx, wkc=wkc)
    return encode_frame(make_frame([d], src=RET_MAC if ret else OUT_MAC), pad=True)


def cyclic(n: int, period_ns: int = 500_000, rt_ns: int = 40_000,
           t0: int = 1_700_000_000_000_000_000):
    """(ts_ns, frame) pairs of n LRW out/return pairs."""
    out = []
    for i in range(n):
        t = t0 + i * period_ns
        out.append((t, lrw(i & 0xFF)))
        out.append((t + rt_ns, lrw(i & 0xFF, wkc=3, ret=True)))
    return out


def write_pcap(path, frames, *, big=False, ns=False):
    body = w.pcap_header(big=big, ns=ns)
    body += b"".join(w.pcap_record(t, f, big=big, ns=ns) for t, f in frames)
    path.write_bytes(body)
    return path


def write_pcapng(path, frames, *, big=False, tsresol=9, units=None):
    body = w.shb(big=big) + w.idb(tsresol=tsresol, big=big)
    conv = units or (lambda t: t)
    body += b"".join(w.epb(conv(t), f, big=big) for t, f in frames)
    path.write_bytes(body)
    return path


@pytest.mark.parametrize("big", [False, True])
@pytest.mark.parametrize("ns", [False, True])
def test_pcap_byte_orders_and_resolutions(tmp_path, big, ns):
    frames = cyclic(50, rt_ns=41_000)
    path = write_pcap(tmp_path / "c.pcap", frames, big=big, ns=ns)
    read = list(CaptureReader(path))
    assert [f.timestamp_ns for f in read] == [t for t, _ in frames]
    assert [f.data for f in read] == [f for _, f in frames]
    rep = analyze_file(path).to_dict()
    assert rep["pairs"] == 50 and rep["lost_frames"] == 0
    assert rep["round_trip_us"]["mean"] == pytest.approx(41.0)
    assert rep["cycle_period_us"]["median"] == pytest.approx(500.0)


@pytest.mark.parametrize("big", [False, True])
def test_pcapng_byte_orders(fast, tmp_path, big):
    frames = cyclic(20)
    path = write_pcapng(tmp_path / "c.pcapng", frames, big=big)
    assert [f.timestamp_ns for f in CaptureReader(path)] == [t for t, _ in frames]
    assert analyze_file(path, engine="python").to_dict()["pairs"] == 20
    assert analyze_file(path, engine=fast).to_dict()["pairs"] == 20


@pytest.mark.parametrize(
    "tsresol, to_units",
    [
        (None, lambda t: t // 1000),          # default 10^-6
        (3, lambda t: t // 1_000_000),        # milliseconds
        (9, lambda t: t),
        (12, lambda t: t * 1000),             # picoseconds
        (0x80 | 20, lambda t: (t << 20) // 1_000_000_000),   # 2^-20 s
        (0x80 | 40, lambda t: (t << 40) // 1_000_000_000),   # 2^-40 s
    ],
)
def test_if_tsresol(fast, tmp_path, tsresol, to_units):
    t0 = 1_000_123_456_000  # small enough for picoseconds in 64 bits
    frames = [(t0, lrw(1)), (t0 + 2_000_000, lrw(1, wkc=3, ret=True))]
    body = w.shb() + w.idb(tsresol=tsresol) + b"".join(w.epb(to_units(t), f) for t, f in frames)
    path = tmp_path / "r.pcapng"
    path.write_bytes(body)
    got = [f.timestamp_ns for f in CaptureReader(path)]
    mode, a, b, off = ts_params(6 if tsresol is None else tsresol)
    assert got == [ts_to_ns(to_units(t), mode, a, b, off) for t, _ in frames]
    for t_got, (t, _) in zip(got, frames, strict=True):
        step = 1_000_000 if tsresol == 3 else 1000
        assert abs(t_got - t) < step
    rep_fast = analyze_file(path, engine=fast).to_dict()
    rep_slow = analyze_file(path, engine="python").to_dict()
    assert rep_fast["round_trip_us"]["mean"] == rep_slow["round_trip_us"]["mean"]
    assert rep_fast["round_trip_us"]["mean"] == pytest.approx(2000.0, abs=1.0)


def test_if_tsoffset(tmp_path):
    body = w.shb() + w.idb(tsresol=9, tsoffset_s=100) + w.epb(5, lrw(1))
    path = tmp_path / "o.pcapng"
    path.write_bytes(body)
    assert [f.timestamp_ns for f in CaptureReader(path)] == [100_000_000_005]


def test_several_sections_and_interfaces(fast, tmp_path):
    """Section 1 little endian µs with two interfaces; section 2 big endian ns. Interface
    ids restart per section."""
    t = 1_000_000_000_000
    s1 = (w.shb() + w.idb(tsresol=None) + w.idb(tsresol=9)
          + w.epb(t // 1000, lrw(1)) + w.epb(t + 30_000, lrw(1, 3, True), interface=1))
    s2 = (w.shb(big=True) + w.idb(tsresol=9, big=True)
          + w.epb(t + 500_000, lrw(2), big=True) + w.epb(t + 540_000, lrw(2, 3, True), big=True)
          + w.spb(ecat(Command.BRD, 7), big=True)
          + w.opb(t + 600_000, ecat(Command.BRD, 7, 2, True), big=True))
    path = tmp_path / "multi.pcapng"
    path.write_bytes(s1 + s2)
    reader = CaptureReader(path)
    frames = list(reader)
    assert [f.timestamp_ns for f in frames] == [
        t, t + 30_000, t + 500_000, t + 540_000, t + 540_000, t + 600_000]
    assert [f.interface for f in frames] == [0, 1, 0, 0, 0, 0]
    assert reader.stats.sections == 2 and len(reader.stats.interfaces) == 3
    for engine in (fast, "python"):
        rep = analyze_file(path, engine=engine, chunk_bytes=1 << 16).to_dict()
        assert rep["frames_total"] == 6 and rep["pairs"] == 3
        assert rep["round_trip_us"]["max"] == pytest.approx(60.0)


def test_unknown_block_type_is_skipped(tmp_path):
    frames = cyclic(3)
    body = w.shb() + w.custom_block(0x0BADBEEF, b"hello") + w.idb()
    body += b"".join(w.epb(t, f) for t, f in frames) + w.custom_block(0x80000001, bytes(40))
    path = tmp_path / "unknown-block.pcapng"
    path.write_bytes(body)
    rep = analyze_file(path).to_dict()
    assert rep["pairs"] == 3 and rep["malformed_frames"] == 0
    assert rep["other"]["skipped_blocks"] == 2


def test_vlan_and_udp_ecat_frames(tmp_path):
    plain = lrw(5)
    vlan = plain[:12] + b"\x81\x00\x00\x05" + plain[12:]
    payload = plain[14:]
    udp = b"\x88\xa4\x88\xa4" + (8 + len(payload)).to_bytes(2, "big") + b"\0\0" + payload
    ip = bytes([0x45, 0, 0, 20 + len(udp), 0, 0, 0, 0, 64, 17, 0, 0, 10, 0, 0, 1, 10, 0, 0, 2])
    udp_frame = plain[:12] + b"\x08\x00" + ip + udp
    arp = b"\xff" * 6 + OUT_MAC + b"\x08\x06" + bytes(28)
    path = write_pcap(tmp_path / "v.pcap", [(1, vlan), (2, udp_frame), (3, arp)])
    rep = analyze_file(path).to_dict()
    assert rep["ecat_frames"] == 2 and rep["non_ecat_frames"] == 1
    assert rep["other"]["vlan_frames"] == 1 and rep["other"]["udp_frames"] == 1


def test_snaplen_cut_frame_is_malformed(tmp_path):
    full = lrw(1)
    body = w.pcap_header() + w.pcap_record(1, full[:20], original_length=len(full))
    body += w.pcap_record(2, full)
    path = tmp_path / "cut.pcap"
    path.write_bytes(body)
    rep = analyze_file(path).to_dict()
    assert rep["malformed_frames"] == 1 and rep["ecat_frames"] == 1


def test_table_growth_and_stack_depth(fast, tmp_path):
    """Many distinct pending signatures force the pairing table to grow; both engines
    still agree with each other."""
    frames = []
    t = 10**18
    for i in range(9000):   # outgoing only, all different addresses: nothing pairs
        frames.append((t + i * 1000, ecat(Command.FPRD, i & 0xFF, adp=0x1000 + i)))
    for i in range(9000):
        frames.append((t + 10**7 + i * 1000, ecat(Command.FPRD, i & 0xFF, 1, True, adp=0x1000 + i)))
    path = write_pcap(tmp_path / "many.pcap", frames)
    got = analyze_file(path, engine=fast).to_dict()
    slow = analyze_file(path, engine="python").to_dict()
    assert got["pairs"] == slow["pairs"] == 9000
    assert got.pop("engine") == fast and slow.pop("engine") == "python"
    assert got == slow


# --- bad input: exit 3 (unreadable) or 0/1 with malformed counted --------------------


def _run(cli, path):
    code, out, err = cli("capture", "analyze", str(path), "--format", "json")
    assert "Traceback" not in err
    return code, out, err


@pytest.mark.parametrize(
    "name, content",
    [
        ("empty.pcap", b""),
        ("bad-magic.pcap", b"\x00\x01\x02\x03" + bytes(40)),
        ("truncated-header.pcap", w.pcap_header()[:10]),
        ("truncated-shb.pcapng", w.shb()[:9]),
        ("text.pcap", b"this is not a capture file at all\n" * 4),
        ("linktype-raw-ip.pcap", w.pcap_header(link_type=101) + w.pcap_record(1, bytes(40))),
    ],
)
def test_unreadable_files_exit_3(cli, tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    code, out, err = _run(cli, path)
    assert code == 3, (code, out, err)
    assert out == ""
    assert str(path) in err and len(err.strip().splitlines()) == 1
    with pytest.raises(CaptureError):
        analyze_file(path)


def test_missing_file_exits_3(cli, tmp_path):
    code, _, err = _run(cli, tmp_path / "nope.pcap")
    assert code == 3 and "nope.pcap" in err


def test_pcapng_without_ethernet_interface_exits_3(cli, tmp_path):
    path = tmp_path / "linktype-usb.pcapng"
    path.write_bytes(w.shb() + w.idb(link_type=220) + w.epb(1, bytes(30)))
    code, _, err = _run(cli, path)
    assert code == 3 and "Ethernet" in err


def test_truncated_record_counts_malformed(cli, tmp_path):
    good = write_pcap(tmp_path / "g.pcap", cyclic(10)).read_bytes()
    path = tmp_path / "truncated-record.pcap"
    path.write_bytes(good[:-30])
    code, out, _ = _run(cli, path)
    rep = json.loads(out)
    assert code in (0, 1)
    assert rep["malformed_frames"] == 1 and rep["frames_total"] == 19


def test_truncated_pcapng_block_counts_malformed(cli, tmp_path):
    good = write_pcapng(tmp_path / "g.pcapng", cyclic(10)).read_bytes()
    path = tmp_path / "truncated-block.pcapng"
    path.write_bytes(good[:-7])
    code, out, _ = _run(cli, path)
    rep = json.loads(out)
    assert rep["malformed_frames"] == 1 and rep["frames_total"] == 19


@pytest.mark.parametrize("seed", range(6))
def test_random_bytes_never_traceback(fast, cli, tmp_path, seed):
    import random

    rnd = random.Random(seed)
    good = bytearray(write_pcapng(tmp_path / "g.pcapng", cyclic(30)).read_bytes())
    if seed < 3:   # random garbage after a valid header
        data = bytes(good[:60]) + os.urandom(2000)
    else:          # flip bytes inside a valid file
        for _ in range(20):
            good[rnd.randrange(60, len(good))] = rnd.randrange(256)
        data = bytes(good)
    path = tmp_path / f"random-{seed}.pcapng"
    path.write_bytes(data)
    code, out, err = _run(cli, path)
    assert code in (0, 1, 3), err
    if code != 3:
        json.loads(out)
    if code != 3:
        got = analyze_file(path, engine=fast).to_dict()
        slow = analyze_file(path, engine="python").to_dict()
        got.pop("engine"), slow.pop("engine")
        assert got == slow


def test_random_bytes_without_header_exit_3(cli, tmp_path):
    path = tmp_path / "random.bin"
    path.write_bytes(bytes(range(256)) * 8)
    code, _, _ = _run(cli, path)
    assert code == 3


def test_engine_choice(monkeypatch):
    from lolacli.capture import cengine
    from lolacli.capture.fast import choose_engine

    monkeypatch.delenv("LOLACLI_ENGINE", raising=False)
    # the C kernel, when built, serves every size: it loads in milliseconds
    assert cengine.c_available()
    assert choose_engine("auto", 100) == "c" == choose_engine("auto", 10**9)
    assert choose_engine("python", 10**9) == "python"
    monkeypatch.setenv("LOLACLI_ENGINE", "python")
    assert choose_engine("auto", 10**9) == "python"
    with pytest.raises(UsageError):
        choose_engine("fortran")
    monkeypatch.setenv("LOLACLI_ENGINE", "fortran")
    with pytest.raises(UsageError):
        choose_engine("auto")
    # the removed engine: a usage error that says what to use instead
    monkeypatch.setenv("LOLACLI_ENGINE", "numba")
    with pytest.raises(UsageError, match="LOLACLI_ENGINE numba was removed.*use auto"):
        choose_engine("auto")
    monkeypatch.delenv("LOLACLI_ENGINE")
    with pytest.raises(UsageError, match="--engine numba was removed"):
        choose_engine("numba")


def test_removed_engine_is_one_usage_line(cli, tmp_path):
    path = write_pcap(tmp_path / "c.pcap", cyclic(2))
    code, out, err = cli("capture", "analyze", str(path), "--engine", "numba")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "numba was removed" in err and "Traceback" not in err


def test_without_the_c_scanner_python_runs_and_says_so_once(tmp_path, corpus):
    """A copy of the package without the built C scanner, as an install without a C
    compiler leaves it: `capture analyze` runs the Python reference, with the same
    report, and says so in one stderr line (within 80 columns)."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    import lolacli
    from lolacli.capture.fast import FALLBACK_NOTE

    src = Path(lolacli.__file__).resolve().parent
    shutil.copytree(src, tmp_path / "lolacli",
                    ignore=shutil.ignore_patterns("_cscan*.so", "__pycache__"))
    capture = corpus / "pcap" / "ethercrab__replay-sdo-error.pcapng"
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    env.pop("LOLACLI_ENGINE", None)
    done = subprocess.run(
        [sys.executable, "-m", "lolacli", "capture", "analyze", str(capture), "-f", "json"],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120,
    )
    assert done.returncode in (0, 1), done.stderr
    assert done.stderr.splitlines() == [FALLBACK_NOTE] and len(FALLBACK_NOTE) <= 80
    doc = json.loads(done.stdout)
    assert doc["engine"] == "python"
    reference = analyze_file(capture, engine="c").to_dict()
    doc.pop("engine"), reference.pop("engine")
    assert doc == json.loads(json.dumps(reference))


def test_unknown_engine_is_a_usage_error(cli, tmp_path):
    path = write_pcap(tmp_path / "c.pcap", cyclic(2))
    code, _, err = cli("capture", "analyze", str(path), "--engine", "fortran")
    assert code == 2 and "Traceback" not in err and "unknown capture engine" in err


def test_c_kernel_refuses_arrays_it_would_overrun(tmp_path):
    """The C code trusts lengths; its wrapper checks them before every call."""
    import numpy as np

    from lolacli.capture import scan as S
    from lolacli.capture.cengine import CKernels

    k = CKernels()
    z = lambda n: np.zeros(n, np.int64)  # noqa: E731
    rows = 1 << 14
    pv = 128 * S.DEPTH * S.PCOLS
    args = dict(st=z(S.S_SIZE), cmd_counts=z(256), dg=z(S.MAX_DGRAMS), pk=z(128), pn=z(128),
                pv=z(pv), sk=z(128), sc=z(128), wk=z(512), wn=z(512), wv=z(512 * S.OCOLS),
                o_rt=z(rows), o_rtts=z(rows), o_rtfr=z(rows), o_period=z(rows),
                o_burst=z(rows), o_dc=z(rows), o_mbx=z(rows * S.MBX_COLS),
                o_cfg=z(rows * S.CFG_COLS), o_evict=z(rows * S.EVICT_COLS),
                o_ctr=z(rows * S.CTR_COLS))
    buf = np.zeros(100, np.uint8)

    def call(**change):
        a = dict(args, **change)
        return k.scan(buf if "buf" not in a else a.pop("buf"), 0, a.pop("end", 100), True,
                      0, False, False, z(5), 0, **a)

    # 100 zero bytes as classic pcap: six empty 16-byte records, then 4 bytes left over
    assert call() == (96, S.ST_CORRUPT)
    assert args["st"][S.S_FRAMES] == 6 == args["st"][S.S_MALFORMED]
    for bad in (dict(end=101), dict(pv=z(10)), dict(pk=z(48), pn=z(48)),
                dict(pk=z(64), pn=z(64), pv=z(64 * S.DEPTH * S.PCOLS)),
                dict(wk=z(256), wn=z(256), wv=z(256 * S.OCOLS)), dict(wv=z(512)),
                dict(sk=z(64), sc=z(64)), dict(o_dc=z(5)), dict(o_cfg=z(rows)),
                dict(o_evict=z(rows)), dict(st=z(3)), dict(o_mbx=z(rows)), dict(o_ctr=z(rows)),
                dict(buf=np.zeros(100, np.int64)), dict(st=np.zeros(S.S_SIZE, np.int32))):
        with pytest.raises(ValueError):
            call(**bad)


def test_progress_is_called_up_to_the_file_size(tmp_path):
    path = write_pcapng(tmp_path / "p.pcapng", cyclic(3000))
    calls = []
    analyze_file(path, engine="python", chunk_bytes=1 << 16,
                 progress=lambda d, t: calls.append((d, t)))
    size = path.stat().st_size
    assert len(calls) > 3 and calls[-1] == (size, size)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_output_flushes_keep_results_identical(fast, tmp_path):
    """More pairs than one output buffer holds (64 Ki rows): the scanner returns to the
    driver to flush, in both engines, without losing or doubling anything."""
    frames = cyclic(70_000, period_ns=250_000)
    path = write_pcap(tmp_path / "long.pcap", frames, ns=True)
    got = analyze_file(path, engine=fast).to_dict()
    slow = analyze_file(path, engine="python").to_dict()
    assert got["pairs"] == 70_000 and got["cycle_period_us"]["count"] == 69_999
    got.pop("engine"), slow.pop("engine")
    assert got == slow


def test_c_kernel_constants_equal_scan_py():
    """_cscan.c repeats scan.py's constants as #defines; they must not drift apart."""
    import re
    from pathlib import Path

    from lolacli.capture import scan as S

    source = (Path(S.__file__).parent / "_cscan.c").read_text()
    defines = dict(re.findall(r"^#define (\w+) (.+)$", source, re.M))
    assert len(defines) > 50
    for name, text in defines.items():
        value = eval(text.replace("ULL", "").replace("LL", ""))  # noqa: S307 (our file)
        assert getattr(S, name) == value, name
