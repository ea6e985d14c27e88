"""The arrays `capture analyze --plot` draws (lolacli.capture.plots.plot_series): the same
for every engine and every read-chunk size, and equal to tshark's frames paired
independently (capture_oracle), on a capture of many chunks written by `bus simulate`'s
pcapng recorder and on every corpus capture.

The compiled engines once kept views of their output rows for the plotted series, which
the next chunk overwrote: a 23 MB capture's round trips spanned -0.37 s to 1.0 s instead
of 0 to 3.75 s, while every JSON figure (built from copies) agreed.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from capture_oracle import cyclic_periods, pair_series, tshark_available, tshark_frames
from conftest import corpus_files, corpus_ids

from lolacli.capture.analyze import CHUNK_BYTES, analyze_file
from lolacli.capture.plots import PlotSeries, plot_series

CAPTURES = corpus_files("pcap")
#: the smallest read chunk analyze_file takes: a 250 kB capture is four chunks
SMALL_CHUNK = 1 << 16
needs_tshark = pytest.mark.skipif(not tshark_available(), reason="tshark not installed")


@pytest.fixture(params=["c", "python"])
def engine(request: pytest.FixtureRequest) -> str:
    from lolacli.capture.cengine import c_available

    if request.param == "c" and not c_available():
        pytest.fail("the C scanner was not built: install a C compiler, then pip install -e .")
    return str(request.param)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """400 cycles of the LOLA chain (bring-up, mailbox, DC, some frames lost), recorded by
    the simulator's own pcapng writer: about 1.7 MB, 27 chunks of SMALL_CHUNK."""
    from lolacli.cli.common import default_eni
    from lolacli.files import load_eni
    from lolacli.simulate import SimulateOptions, simulate

    path = tmp_path_factory.mktemp("sim") / "lola-400.pcapng"
    simulate(load_eni(default_eni()),
             SimulateOptions(cycles=400, pcap=path, drop_probability=0.002, seed=5))
    assert path.stat().st_size > 8 * SMALL_CHUNK
    return path


def _analysed(path: Path, engine: str, chunk: int) -> tuple[dict, PlotSeries]:
    report = analyze_file(path, engine=engine, keep_series=True, chunk_bytes=chunk)
    doc = report.to_dict()
    doc.pop("engine")
    return doc, plot_series(report)


def _assert_same(got: PlotSeries, want: PlotSeries) -> None:
    for f in fields(PlotSeries):
        a, b = getattr(got, f.name), getattr(want, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b, err_msg=f.name)
        else:
            assert a == b, f.name


def _oracle_series(path: Path) -> tuple[np.ndarray, np.ndarray, list[int] | None]:
    """(seconds since the first return, round trips in µs, cycle periods in ns of the
    logical stream or None when it has no logical frames), from tshark's frames."""
    frames = tshark_frames(path)
    pairs = pair_series(frames)
    at = np.array([t for t, _ in pairs], np.int64)
    rt = np.array([r for _, r in pairs], np.int64)
    x = (at - at[0]) / 1e9 if at.size else np.zeros(0)
    periods = cyclic_periods(frames)
    return x, rt / 1000.0, periods or None


@needs_tshark
def test_plotted_arrays_of_a_capture_of_many_chunks(simulated: Path, engine: str) -> None:
    doc, series = _analysed(simulated, engine, SMALL_CHUNK)
    x, rt_us, periods = _oracle_series(simulated)
    assert doc["pairs"] == rt_us.size > 800 and doc["lost_frames"] > 0
    np.testing.assert_array_equal(series.round_trip_us, rt_us)
    np.testing.assert_array_equal(series.round_trip_x, x)
    assert series.round_trip_x[0] == 0 and np.all(np.diff(series.round_trip_x) >= 0)
    assert series.round_trip_x[-1] <= doc["time_span_us"] / 1e6
    assert periods is not None and doc["cyclic_stream"] == "logical"
    np.testing.assert_array_equal(series.cycle_period_us, np.array(periods) / 1000.0)
    np.testing.assert_array_equal(series.cdf_round_trip_us, np.sort(rt_us))
    assert series.cdf_fraction[-1] == 1.0
    # the whole report and the plots do not depend on how the file was read
    whole_doc, whole = _analysed(simulated, engine, CHUNK_BYTES)
    assert doc == whole_doc
    _assert_same(series, whole)
    if engine != "python":
        py_doc, py = _analysed(simulated, "python", CHUNK_BYTES)
        assert doc == py_doc
        _assert_same(series, py)


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_plotted_arrays_of_corpus_captures(path: Path, engine: str) -> None:
    """Read in chunks of 64 KiB (the larger captures are up to 44 chunks), every engine
    gives the Python engine's arrays read in one chunk, and tshark's pairs."""
    doc, series = _analysed(path, engine, SMALL_CHUNK)
    py_doc, py = _analysed(path, "python", CHUNK_BYTES)
    assert doc == py_doc
    _assert_same(series, py)
    if not tshark_available():
        return
    x, rt_us, periods = _oracle_series(path)
    np.testing.assert_array_equal(series.round_trip_us, rt_us)
    np.testing.assert_array_equal(series.round_trip_x, x)
    if doc["cyclic_stream"] == "logical" and periods is not None:
        np.testing.assert_array_equal(series.cycle_period_us, np.array(periods) / 1000.0)


def _converging_dc_and_an_unanswered_read() -> bytes:
    """1500 cycles of an FPRD of the DC system-time difference (0x092C) whose answer
    shrinks from 1 ms to under 1 µs, and a BRD that is never answered (its pending copies
    leave the pairing stack one per cycle): about 4 chunks of SMALL_CHUNK."""
    import struct

    from lolacli.capture import writer as w
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    out_mac, ret_mac = b"\x00" * 6, b"\x02" * 6
    body = [w.shb(), w.idb()]
    t = 1_700_000_000 * 10**9
    for i in range(1500):
        diff = 1_000_000 // (i + 1)
        value = struct.pack("<I", diff | (0x80000000 if i % 2 else 0))  # sign and magnitude
        read = Datagram.physical(Command.FPRD, 0x1001, 0x092C, 4, index=i & 0xFF)
        got = Datagram.physical(Command.FPRD, 0x1001, 0x092C, value, index=i & 0xFF, wkc=1)
        brd = Datagram.physical(Command.BRD, 0, 0x0130, 2, index=0xEE)
        body.append(w.epb(t, encode_frame(make_frame([read], src=out_mac), pad=True)))
        body.append(w.epb(t + 20_000, encode_frame(make_frame([got], src=ret_mac), pad=True)))
        body.append(w.epb(t + 30_000, encode_frame(make_frame([brd], src=out_mac), pad=True)))
        t += 1_000_000
    return b"".join(body)


def test_series_drained_per_chunk_are_copies(tmp_path: Path, engine: str) -> None:
    """The DC differences and the frames pushed out of the pairing stack are drained per
    chunk like the round trips; views of the output rows would show the last chunk's
    values in place of the first's (the largest difference, the first lost frames)."""
    path = tmp_path / "dc.pcapng"
    path.write_bytes(_converging_dc_and_an_unanswered_read())
    assert path.stat().st_size > 3 * SMALL_CHUNK
    doc, _ = _analysed(path, engine, SMALL_CHUNK)
    dc = doc["dc"]
    assert dc["system_time_difference_reads"] == 1500
    assert dc["system_time_difference_max_abs_ns"] == 1_000_000
    assert dc["system_time_difference_last_ns"] == -(1_000_000 // 1500)
    lost = next(f for f in doc["findings"] if f["kind"] == "lost")
    assert lost["frames"][:3] == [3, 6, 9]  # the BRDs of the first cycles, by frame number
    assert doc == _analysed(path, "python", CHUNK_BYTES)[0]
