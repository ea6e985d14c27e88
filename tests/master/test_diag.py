"""`bus diag`: the link where errors enter, found from the error counters, against the
emulator's bad link (`--bad-link K:P`) at every position of the LOLA chain (in process,
virtual time), a clean chain, and the counters a damaged frame leaves."""

from __future__ import annotations

import pytest

from lolacli.emulator.run import EmulateOptions, make_chain, parse_bad_link
from lolacli.errors import UsageError
from lolacli.files import load_eni
from lolacli.master.diag import DiagOptions, diagnose
from lolacli.master.transport import ChainTransport
from lolacli.wire.error_counters import PortRise, frame_path, locate
from tests.live import LOLA

LOLA_ENI = load_eni(LOLA)
N = len(LOLA_ENI.slaves)
SHORT = DiagOptions(interval_ns=100_000_000, reset=True)  # 100 probe frames


def _diag(bad_link: tuple[int, float] | None, options: DiagOptions = SHORT):
    chain = make_chain(LOLA_ENI, EmulateOptions(bad_link=bad_link, seed=7))
    return chain, diagnose(ChainTransport(chain), options=options, iface="in-process")


@pytest.mark.parametrize("k", range(1, N + 1))
def test_names_the_bad_link_at_every_position(k: int) -> None:
    chain, report = _diag((k, 0.2))
    link = report.suspect
    assert link is not None
    assert (link.upstream, link.downstream, link.at, link.port) == (k - 1, k, k, 0)
    assert chain.stats.corrupted > 0 and report.probes_lost > 0
    first = next(p for p in report.ports if (p.position, p.port) == (k, 0))
    # each probe lost was damaged into slave K (and a few frames of the final read too)
    assert report.probes_lost <= first.invalid_frames <= report.probes_lost + 5
    assert all(p.rx_errors == 0 for p in report.ports if (p.position, p.port) != (k, 0))
    # the damaged frames pass on, marked: forwarded errors downstream, and on the way back
    after = [p for p in report.ports if p.position > k and p.port == 0]
    assert all(p.forwarded_rx_errors == first.invalid_frames for p in after)
    doc = report.to_dict()
    assert doc["schema"] == "lolacli.diag/1"
    assert doc["suspect_link"]["upstream"] == k - 1


def test_a_clean_bus_has_no_errors() -> None:
    _chain, report = _diag(None)
    assert report.suspect is None and not report.errors
    assert report.probes_sent == 100 and report.probes_lost == 0
    assert all(not p.any for p in report.ports)


def test_without_reset_old_counts_do_not_count() -> None:
    """Counts from before the interval stay out: a bad link that damaged frames only
    before (the chain's counters set by hand) is no suspect."""
    chain = make_chain(LOLA_ENI, EmulateOptions())
    chain.slaves[4].count_invalid_frame(0)
    report = diagnose(ChainTransport(chain), options=DiagOptions(interval_ns=50_000_000))
    assert report.suspect is None


def test_a_lost_link_alone_names_its_cable() -> None:
    rises = [PortRise(3, 1, 0, 0, 0, 1), PortRise(4, 0, 0, 0, 0, 1)]
    link = locate(rises, frame_path([0, 1, 2, 3, 4]))
    assert link is not None
    assert (link.upstream, link.downstream, link.cause) == (3, 4, "lost_links")


def test_frame_path_of_a_branch() -> None:
    """A junction (slave 1, ports 0, 3 and 1 open) with a branch (2) on port 3 and the line
    (3, 4) on port 1: the frame goes 1 -> 2 -> back into 1 at port 3 -> 3 -> 4 -> back."""
    path = frame_path([0, 1, 1, 3], [[3, 1], [], [1], []])
    assert [(h.position, h.port, h.neighbour) for h in path] == [
        (1, 0, 0), (2, 0, 1), (1, 3, 2), (3, 0, 1), (4, 0, 3), (3, 1, 4), (1, 1, 3),
    ]  # fmt: skip


@pytest.mark.parametrize("text", ["0", "3:0.5x", "3:0", "3:1.5", "x", "-1", ""])
def test_bad_link_text_is_refused(text: str) -> None:
    with pytest.raises(UsageError, match="--bad-link"):
        parse_bad_link(text)


def test_bad_link_beyond_the_chain_is_refused() -> None:
    with pytest.raises(UsageError, match="--bad-link 26: the chain has slaves 1..25"):
        make_chain(LOLA_ENI, EmulateOptions(bad_link=(26, 0.1)))


@pytest.mark.parametrize("k", [1, 9, 25])
def test_the_capture_of_a_bad_link_bus_names_the_same_link(tmp_path, k: int) -> None:
    """`bus diag` on a bus with a bad link, its frames captured (pcapng, as the master's
    side sees them): `capture analyze` finds the counters read in the captured answers
    and names the link diag named, and counts the lost frames."""
    from lolacli.capture.analyze import analyze_file
    from lolacli.master.record import PcapngRecorder

    chain = make_chain(LOLA_ENI, EmulateOptions(bad_link=(k, 0.2), seed=3))
    transport = ChainTransport(chain)
    pcap = tmp_path / "bad-link.pcapng"
    recorder = PcapngRecorder(pcap)
    transport.taps.append(recorder)
    report = diagnose(transport, options=SHORT)
    recorder.close()
    analysis = analyze_file(pcap)
    doc = analysis.to_dict()
    link = doc["error_counters"]["suspect_link"]
    assert report.suspect is not None
    assert (link["upstream"], link["downstream"], link["port"]) == (
        report.suspect.upstream, report.suspect.downstream, report.suspect.port) == (k - 1, k, 0)
    assert doc["error_counters"]["positions_from"] == "aprd"
    assert doc["lost_frames"] >= report.probes_lost > 0
    bad = [f for f in doc["findings"] if f["kind"] == "bad-link"]
    assert len(bad) == 1 and f"and slave {k} " in bad[0]["message"]


def test_a_clean_capture_has_no_suspect(tmp_path) -> None:
    from lolacli.capture.analyze import analyze_file
    from lolacli.master.record import PcapngRecorder

    transport = ChainTransport(make_chain(LOLA_ENI, EmulateOptions()))
    pcap = tmp_path / "clean.pcapng"
    recorder = PcapngRecorder(pcap)
    transport.taps.append(recorder)
    diagnose(transport, options=SHORT)
    recorder.close()
    doc = analyze_file(pcap).to_dict()
    # every slave three times: the scan, before and after the interval
    assert doc["error_counters"]["reads"] == 3 * N
    assert doc["error_counters"]["suspect_link"] is None
    assert not [f for f in doc["findings"] if f["kind"] == "bad-link"]
