"""The C engine on a mapped file against the Python engine reading it (issue 28).

The C engine maps a regular file a window at a time and reads only the bytes it
analyses; the Python reference reads the file by read(). Every JSON figure must be the
same on every corpus capture, on the benchmark's LOLA-sized capture (846-byte frames
with their returns, SDO transactions, lost frames), across window boundaries, and on
damaged files: truncated, a last record cut short, blocks of unknown type, and a file
that shrinks while it is read (no SIGBUS: the scanner's guard catches it and the pass
is read again).
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import corpus_files, corpus_ids, script_module

from lolacli.capture import scan as S
from lolacli.capture.analyze import analyze_file
from lolacli.capture.source import ChunkedSource, MappedSource, open_source
from lolacli.errors import CaptureError

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = corpus_files("pcap")
#: the LOLA chain's cyclic frame: 846 bytes on the wire with the FCS (an LRW of 800 bytes
#: and a BRD; lolacli.timing.model)
LOLA_LRW_BYTES = 800


def _doc(path: Path, **kw: object) -> object:
    try:
        doc = analyze_file(path, max_lost=10**9, **kw).to_dict()  # type: ignore[arg-type]
    except CaptureError as exc:
        return ("error", str(exc))
    doc.pop("engine")
    return doc


def _bench() -> object:
    return script_module("benchmarks/capture_throughput.py")


@pytest.fixture(scope="module")
def lola(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, int]]:
    """The benchmark's capture with LOLA-sized frames: 3,000 cycles at 2 kHz, 846-byte
    frames, returns, SDO uploads, pcapng (about 5.5 MB)."""
    path = tmp_path_factory.mktemp("lola") / "lola.pcapng"
    expected = _bench().write_capture(path, 3000, pcapng=True,  # type: ignore[attr-defined]
                                      lrw_bytes=LOLA_LRW_BYTES)
    return path, expected


def _mapped(path: Path, **kw: object) -> object:
    """The C engine's document, asserting that it did read the file mapped."""
    import lolacli.capture.analyze as A

    seen: list[bool] = []
    run = A._Pass.run

    def spy(self: A._Pass) -> None:
        run(self)
        seen.append(self.mapped_read)

    A._Pass.run = spy  # type: ignore[method-assign]
    try:
        doc = _doc(path, engine="c", **kw)
    finally:
        A._Pass.run = run  # type: ignore[method-assign]
    assert isinstance(doc, tuple) or (seen and all(seen)), seen
    return doc


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_mapped_c_equals_python_on_every_corpus_capture(path: Path) -> None:
    python = _doc(path, engine="python")
    assert _mapped(path) == python
    assert _mapped(path, chunk_bytes=1 << 16) == python  # many windows
    assert _doc(path, engine="c", mapped=False) == python


def test_mapped_c_equals_python_on_a_lola_sized_capture(lola: tuple[Path, dict[str, int]]):
    path, expected = lola
    python = _doc(path, engine="python")
    assert isinstance(python, dict)
    assert python["frames_total"] == expected["frames"]
    assert python["sdo_transactions"] == expected["sdo"]
    assert python["lost_frames"] + python["in_flight_at_end"] == expected["lost"]
    # 64 KiB windows: records cross every window boundary somewhere
    for window in (None, 1 << 16, 3 << 16):
        assert _mapped(path, chunk_bytes=window) == python, window


def test_cut_anywhere_gives_the_same_findings(lola: tuple[Path, dict[str, int]],
                                              tmp_path: Path) -> None:
    """A truncated file and a last record cut short: mapped C = Python, cut short found."""
    path, _ = lola
    data = path.read_bytes()[: 400_000]
    for k, cut in enumerate((4096, 4096 * 7 + 3, 200_001, 399_999, 300_000 - 300_000 % 924)):
        cut_path = tmp_path / f"cut{k}.pcapng"
        cut_path.write_bytes(data[:cut])
        python = _doc(cut_path, engine="python")
        assert _mapped(cut_path, chunk_bytes=1 << 16) == python, cut
        assert _mapped(cut_path) == python, cut
        assert isinstance(python, dict)
        cut_short = [f for f in python["findings"] if f["kind"] == "cut-short"]
        assert len(cut_short) == 1 and python["malformed_frames"] == 1, cut


def test_a_record_cut_short_is_reported_alike(tmp_path: Path) -> None:
    from lolacli.capture import writer as w

    frame = bytes(14) + b"\x88\xa4" + bytes(40)
    data = w.pcap_header() + w.pcap_record(1_000, frame) * 3
    path = tmp_path / "cut.pcap"
    path.write_bytes(data[:-10])
    python = _doc(path, engine="python")
    assert _mapped(path) == python
    assert isinstance(python, dict) and python["frames_total"] == 2
    assert python["malformed_frames"] == 1
    assert [f["kind"] for f in python["findings"] if f["kind"] == "cut-short"] == ["cut-short"]


def test_unknown_block_types_are_skipped_alike(lola: tuple[Path, dict[str, int]],
                                               tmp_path: Path) -> None:
    """Blocks of unknown (and custom) types between the packets: skipped, same figures."""
    path, _ = lola
    data = path.read_bytes()[:200_000]
    sizes = []
    pos, blocks = 0, []
    while pos + 8 <= len(data):
        size = struct.unpack_from("<I", data, pos + 4)[0]
        if pos + size > len(data):
            break
        blocks.append(data[pos : pos + size])
        sizes.append(size)
        pos += size
    odd = [struct.pack("<II", t, 12 + n) + bytes(n) + struct.pack("<I", 12 + n)
           for t, n in ((0x00000BAD, 4), (0x40000BAD, 20), (0x00000005, 8))]
    mixed = blocks[:2] + [b for i, blk in enumerate(blocks[2:]) for b in
                          ((blk, odd[i % 3]) if i % 5 == 0 else (blk,))]
    out = tmp_path / "unknown.pcapng"
    out.write_bytes(b"".join(mixed))
    python = _doc(out, engine="python")
    assert _mapped(out, chunk_bytes=1 << 16) == python
    assert isinstance(python, dict) and python["other"]["skipped_blocks"] > 10
    assert python["malformed_frames"] == 0


def _statuses() -> tuple[list[int], object]:
    """Spy on the C kernel's return codes."""
    from lolacli.capture import cengine

    seen: list[int] = []
    scan = cengine.CKernels.scan

    def spy(self: object, *a: object) -> tuple[int, int]:
        pos, status = scan(self, *a)  # type: ignore[arg-type]
        seen.append(status)
        return pos, status

    cengine.CKernels.scan = spy  # type: ignore[method-assign]
    return seen, scan


@pytest.mark.parametrize("fmt", ["pcapng", "pcap"])
def test_a_file_that_shrinks_while_mapped_is_read_again(tmp_path: Path, fmt: str) -> None:
    """Truncated under the scanner halfway, on a page boundary in the middle of a record:
    the scanner faults on the first page past the new end (SIGBUS, caught: ST_FAULT), the
    pass is read again by read(), and the report is the Python engine's on the file as it
    is afterwards: the last record cut short."""
    from lolacli.capture import cengine

    victim = tmp_path / f"shrinking.{fmt}"
    _bench().write_capture(victim, 3000, pcapng=fmt == "pcapng",  # type: ignore[attr-defined]
                           lrw_bytes=LOLA_LRW_BYTES)
    size = victim.stat().st_size
    new_size = size // 2 - (size // 2) % 4096
    assert size > 2 * (2 << 20)  # the scan returns to Python after its first 2 MiB slice
    truncated: list[int] = []

    def shrink(done: int, _total: int) -> None:
        if done > 4096 and not truncated:  # (after the pcapng blocks Python reads)
            os.truncate(victim, new_size)
            truncated.append(done)

    seen, scan = _statuses()
    try:
        doc = analyze_file(victim, engine="c", progress=shrink, max_lost=10**9).to_dict()
    finally:
        cengine.CKernels.scan = scan  # type: ignore[method-assign]
    assert truncated and truncated[0] < new_size
    assert S.ST_FAULT in seen  # the guard caught the bus error
    doc.pop("engine")
    assert victim.stat().st_size == new_size
    assert doc == _doc(victim, engine="python")
    assert doc["malformed_frames"] == 1  # the record cut in half
    assert [f["kind"] for f in doc["findings"] if f["kind"] == "cut-short"] == ["cut-short"]


@pytest.mark.parametrize("fmt", ["pcapng", "pcap"])
def test_a_file_cut_inside_a_page_while_mapped_is_read_again(tmp_path: Path, fmt: str) -> None:
    """Truncated mid-page: the bytes between the new end and the end of its page still
    read (as zeros) without a fault; the size check at the end of the pass (or the fault
    on the next page) sees the file shrank and it is read again: the same report as the
    Python engine's."""
    victim = tmp_path / f"tail.{fmt}"
    _bench().write_capture(victim, 3000, pcapng=fmt == "pcapng",  # type: ignore[attr-defined]
                           lrw_bytes=LOLA_LRW_BYTES)
    size = victim.stat().st_size
    new_size = size // 2 - (size // 2) % 4096 + 1001
    truncated: list[int] = []

    def shrink(done: int, _total: int) -> None:
        if done > 4096 and not truncated:
            os.truncate(victim, new_size)
            truncated.append(done)

    doc = analyze_file(victim, engine="c", progress=shrink, max_lost=10**9).to_dict()
    doc.pop("engine")
    assert truncated and victim.stat().st_size == new_size
    assert doc == _doc(victim, engine="python")
    assert doc["malformed_frames"] == 1


def test_a_sigbus_outside_the_scanner_still_ends_the_process(tmp_path: Path) -> None:
    """The guard only catches faults of the scanner's own walk: any other bus error still
    goes to the previous handler (here the default: the process dies of SIGBUS)."""
    f = tmp_path / "f"
    f.write_bytes(bytes(3 * 4096))
    code = (
        "import mmap, os, sys\n"
        "from lolacli.capture.cengine import c_available\n"
        "assert c_available()\n"  # loads the library: installs the guard
        f"fd = os.open({str(f)!r}, os.O_RDWR)\n"
        "m = mmap.mmap(fd, 3 * 4096)\n"
        "os.ftruncate(fd, 0)\n"
        "m[8192]\n"
        "print('survived')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=60)
    assert r.returncode == -7 and "survived" not in r.stdout, (r.returncode, r.stderr)


def test_pipes_and_non_regular_files_are_read(tmp_path: Path,
                                              lola: tuple[Path, dict[str, int]]) -> None:
    """A FIFO is read by read(), whatever the engine asks; a regular file is mapped."""
    path, _ = lola
    with open_source(path) as src:
        assert isinstance(src, MappedSource)
    with open_source(path, mapped=False) as src:
        assert isinstance(src, ChunkedSource)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    data = path.read_bytes()
    writer = subprocess.Popen(["sh", "-c", f"cat {path} > {fifo}"])
    try:
        with open_source(fifo) as src:
            assert isinstance(src, ChunkedSource)
            got = bytes(src.buf[: src.end])
            while not src.eof:
                src.advance(src.end)
                got += bytes(src.buf[: src.end])
    finally:
        writer.wait(timeout=30)
    assert got == data


def test_cli_reads_a_capture_from_a_pipe(tmp_path: Path,
                                         lola: tuple[Path, dict[str, int]]) -> None:
    path, _ = lola
    cmd = [sys.executable, "-m", "lolacli", "capture", "analyze", "/dev/stdin",
           "--format", "json", "--max-lost", "1000000"]
    with open(path, "rb") as f:
        r = subprocess.run(["sh", "-c", f"cat {path} | " + " ".join(cmd)], capture_output=True,
                           env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    del f
    import json

    doc = json.loads(r.stdout)
    doc.pop("engine")
    assert r.returncode in (0, 1), r.stderr
    assert doc["file"] == "/dev/stdin"
    doc.pop("file")
    python = _doc(path, engine="python")
    assert isinstance(python, dict)
    python.pop("file")
    assert doc == python
