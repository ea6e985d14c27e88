"""RawSocketTransport over a veth pair: the test holds a plain AF_PACKET socket on the
other end as the "bus". Send and receive exact bytes, kernel receive stamps, timeouts,
frames the transport itself sent, other ethertypes, taps, busy-waited waits, and every
failure as one TransportError line (exit 4 through the CLI). Needs root."""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from lolacli.errors import TransportError
from lolacli.master.transport import RawSocketTransport
from lolacli.rawsocket import ETH_P_ECAT
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram, decode_frame, encode_frame, make_frame
from tests.live import ROOT, inside, need_root, run

pytestmark = [pytest.mark.root]


def _frame(index: int, *, returned: bool = False) -> bytes:
    src = b"\x03\x01\x01\x01\x01\x01" if returned else b"\x01\x01\x01\x01\x01\x01"
    d = Datagram.physical(Command.BRD, 0, 0x0130, 2, index=index, wkc=1 if returned else 0)
    return encode_frame(make_frame([d], src=src), pad=True)


@pytest.fixture
def pair(bus) -> Iterator[tuple[RawSocketTransport, socket.socket]]:
    """The transport on the master end, a raw socket (all ethertypes) on the other."""
    with inside(bus):
        transport = RawSocketTransport(bus.master, spin_ns=100_000)
        peer = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
        peer.bind((bus.emulator, 0))
    peer.settimeout(2.0)
    try:
        yield transport, peer
    finally:
        transport.close()
        peer.close()


def _peer_recv(peer: socket.socket) -> bytes:
    while True:
        frame, address = peer.recvfrom(2048)
        if address[2] != 4 and frame[12:14] == ETH_P_ECAT.to_bytes(2, "big"):
            return frame


def test_send_puts_the_exact_bytes_on_the_wire(pair) -> None:
    transport, peer = pair
    frame = _frame(7)
    before = time.monotonic_ns()
    sent = transport.send(frame)
    assert before <= sent <= time.monotonic_ns()
    assert _peer_recv(peer) == frame


def test_recv_returns_the_peers_frame_with_its_kernel_stamp(pair) -> None:
    transport, peer = pair
    answer = _frame(9, returned=True)
    before = time.monotonic_ns()
    peer.send(answer)
    time.sleep(0.05)  # read late: the stamp is when it arrived, not when it was read
    got = transport.recv(100_000_000)
    after = time.monotonic_ns()
    assert got is not None and got.frame == answer
    assert decode_frame(got.frame).datagrams[0].index == 9
    assert transport.kernel_timestamps
    assert before <= got.received_ns <= after
    assert got.received_ns - before < 30_000_000  # not the 50 ms later read


def test_recv_times_out_and_skips_frames_sent_by_itself(pair) -> None:
    transport, _peer = pair
    transport.send(_frame(1))  # comes back to this socket as PACKET_OUTGOING only
    t0 = time.monotonic()
    assert transport.recv(20_000_000) is None
    waited = time.monotonic() - t0
    assert 0.019 <= waited < 1.0
    t0 = time.monotonic()
    assert transport.recv(0) is None
    assert time.monotonic() - t0 < 0.05


def test_other_ethertypes_are_not_received(pair) -> None:
    transport, peer = pair
    ip_like = bytes(6) + b"\x02\x00\x00\x00\x00\x01" + b"\x08\x00" + bytes(46)
    peer.send(ip_like)
    peer.send(_frame(3, returned=True))
    got = transport.recv(100_000_000)
    assert got is not None and got.frame[12:14] == b"\x88\xa4"
    assert transport.recv(10_000_000) is None


def test_another_masters_frames_are_ignored(pair) -> None:
    """Once we have sent, only frames with our source MAC (first octet with or without the
    locally administered bit, as the first ESC leaves it) are ours."""
    transport, peer = pair
    transport.send(_frame(5))
    _peer_recv(peer)
    kickcat = bytearray(_frame(5, returned=True))
    kickcat[6:12] = b"\xca\xde\xca\xde\xde\xff"  # KickCAT's master MAC
    peer.send(bytes(kickcat))
    peer.send(_frame(5, returned=True))
    got = transport.recv(100_000_000)
    assert got is not None and got.frame[6:12] == b"\x03\x01\x01\x01\x01\x01"
    assert transport.foreign_frames == 1


def test_taps_see_both_directions_in_order(pair) -> None:
    transport, peer = pair
    seen: list[tuple[int, bool]] = []
    transport.taps.append(lambda t, frame, returned: seen.append((t, returned)))
    sent = transport.send(_frame(4))
    _peer_recv(peer)
    peer.send(_frame(4, returned=True))
    got = transport.recv(100_000_000)
    assert got is not None
    assert [r for _t, r in seen] == [False, True]
    assert seen[0][0] == sent and seen[1][0] == got.received_ns >= sent


def test_wait_until_never_returns_early_and_busy_waits_the_end(pair) -> None:
    transport, _peer = pair
    late = []
    transport.wake_lateness_ns = []
    for _ in range(200):
        target = time.monotonic_ns() + 300_000
        transport.wait_until(target)
        now = time.monotonic_ns()
        assert now >= target
        late.append(now - target)
    assert len(transport.wake_lateness_ns) == 200
    assert all(x >= 0 for x in transport.wake_lateness_ns)
    late.sort()
    assert late[100] < 200_000  # median: generous for a loaded 2-core host
    transport.wait_until(time.monotonic_ns() - 1_000_000)  # in the past: returns at once


def test_no_interface_and_a_downed_interface_are_one_line(bus) -> None:
    with pytest.raises(TransportError, match=r"^no such interface: nosuchif0$"):
        RawSocketTransport("nosuchif0")
    with inside(bus):
        transport = RawSocketTransport(bus.master)
    try:
        bus.ip("link", "set", bus.master, "down")
        with pytest.raises(TransportError, match=rf"^{bus.master}: send failed: Network is down$"):
            transport.send(_frame(1))
    finally:
        transport.close()


def test_the_cli_says_no_such_interface_in_one_line() -> None:
    need_root()  # without root the socket itself is refused first (also exit 4)
    for args in (
        ("bus", "simulate", "--iface", "nosuchif0", "--cycles", "10"),
        ("bus", "scan", "--iface", "nosuchif0"),
    ):
        done = run(*args)
        assert (done.returncode, done.stderr) == (
            4,
            "lolacli: error: no such interface: nosuchif0\n",
        ), args
        assert done.stdout == ""


def test_no_permission_is_exit_4_in_one_line() -> None:
    """Root without CAP_NET_RAW (dropped from the bounding set) cannot open the socket."""
    need_root()
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("needs setpriv (util-linux)")
    for args in (("bus", "scan", "--iface", "lo"), ("bus", "simulate", "--iface", "lo")):
        done = subprocess.run(
            [setpriv, "--bounding-set=-net_raw", sys.executable, "-m", "lolacli", *args],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 4, done.stderr
        assert done.stderr == (
            "lolacli: error: no permission for a raw socket (Operation not permitted); "
            "run as root or give python CAP_NET_RAW\n"
        )
