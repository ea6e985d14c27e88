"""Acceptance: real, unmodified masters (SOEM through pysoem and its own C tools,
KickCAT) drive `lolacli bus emulate` over a veth pair with their default timeouts. Needs
root and `ip`; skipped cleanly otherwise.

The emulator runs in its own process (``python -m lolacli bus emulate``, SCHED_FIFO where
permitted), so master and emulator do not share a GIL. The masters run with normal
scheduling (raised above the kernel's softirq thread, a busy-polling master such as SOEM
would hold back the very packets it waits for). The timeouts are the masters' defaults: pysoem's
``receive_processdata(2000)`` (SOEM's EC_TIMEOUTRET), KickCAT's 2 ms link timeout for the
start-up and 500 µs in the cyclic loop, as KickCAT's own examples set it after OP.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import struct
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

from lolacli.devices.cia402 import Cia402Drive
from tests.emulator.bus import EXAMPLES
from tests.emulator.master_capture import Exchange, MasterCapture, realtime_ns
from tests.live import (
    ALL_CPUS,
    emulate_argv,
    ip,
    need_root,
    on_cpu,
    spawn_emulator,
    stop_emulator,
)

ROOT = Path(__file__).resolve().parents[2]
pytestmark = [pytest.mark.root, pytest.mark.slow]
CYCLES = 10_000  # 10 s at 1 kHz
SOAK_S = float(os.environ.get("LOLACLI_SOAK_S", "5"))  # 60 for the acceptance soak


#: the core the masters run on (the emulator follows them there, `bus emulate --cpu follow`)
MASTER_CPU = min(ALL_CPUS)


@pytest.fixture
def veth() -> Iterator[tuple[str, str]]:
    """A fresh veth pair (master end, emulator end), removed afterwards; the test's master
    on :data:`MASTER_CPU` meanwhile, as a real-time master is deployed on a core of its
    own. Free on both cores, the kernel's load balancer moves a master off the core the
    SCHED_FIFO emulator works on, and each exchange spans two vCPUs; a vCPU the hypervisor
    does not run then holds the answer past the master's deadline (KickCAT single drive,
    10,000 cycles at its 500 µs timeout, other core idle, noisy host: 9-122 time-outs a run
    free, 0 in 4 runs with master and emulator on one core). The emulator, dumpcap and
    the other children keep every core (:func:`tests.live.on_all_cpus`)."""
    need_root()
    with on_cpu(MASTER_CPU):
        yield from _veth_pair()


def _veth_pair() -> Iterator[tuple[str, str]]:
    tag = f"{os.getpid() % 10000:04d}{time.monotonic_ns() % 100:02d}"
    master, emulator = f"lcm{tag}", f"lce{tag}"
    ip("link", "add", master, "type", "veth", "peer", "name", emulator)
    try:
        for name in (master, emulator):
            subprocess.run(
                ["sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"],
                capture_output=True,
                check=False,
            )
            ip("link", "set", name, "up")
        yield master, emulator
    finally:
        subprocess.run(["ip", "link", "del", master], capture_output=True, check=False)


def test_the_capture_holds_every_frame_up_to_its_end(veth) -> None:
    """What the master's side carried until the capture ends is all in the file, the
    last frames and their answers too (dumpcap stopped at once kept none of them)."""
    import socket

    from lolacli.capture.reader import iter_frames

    capture = MasterCapture(veth[0])
    if not capture.available:
        pytest.skip("dumpcap not installed")
    sent = 0
    try:
        with capture:
            ends = [socket.socket(socket.AF_PACKET, socket.SOCK_RAW) for _ in veth]
            for sock, name in zip(ends, veth, strict=True):
                sock.bind((name, 0))
            for i in range(300):  # a request from the master's end, its answer from the other
                for sock, mac in zip(ends, ("020000000001", "020000000002"), strict=True):
                    head = bytes.fromhex("ffffffffffff" + mac + "88a4")
                    sock.send(head + i.to_bytes(4, "big") + bytes(42))
                    sent += 1
            for sock in ends:
                sock.close()
        got = [f for f in iter_frames(capture.path) if f.data[12:14] == b"\x88\xa4"]
        assert capture.dropped == 0
        assert len(got) == sent == 600
    finally:
        capture.close()


@pytest.fixture
def emulate(veth) -> Iterator[Callable[..., subprocess.Popen[bytes]]]:
    """Start `bus emulate` on the slave side of the veth pair: ``emulate(eni, *options)``
    returns once it answers. Whatever the test leaves running is stopped cleanly at its
    end (exit 130 checked); a test that reads the emulator's report stops it itself."""
    started: list[subprocess.Popen[bytes]] = []

    def start(eni: Path, *extra: str) -> subprocess.Popen[bytes]:
        started.append(spawn_emulator(emulate_argv(veth[1], eni, *extra)))
        return started[-1]

    yield start
    for proc in started:
        if proc.returncode is None:
            stop_emulator(proc)


_stop = stop_emulator


@pytest.fixture
def pysoem():
    return pytest.importorskip("pysoem")


def _to_op(master, pysoem, timeout_us: int = 2000) -> None:
    assert master.config_dc()
    assert master.state_check(pysoem.SAFEOP_STATE, 5_000_000) == pysoem.SAFEOP_STATE
    master.send_processdata()
    master.receive_processdata(timeout_us)
    _request_op(master, pysoem, timeout_us)


def _request_op(master, pysoem, timeout_us: int = 2000) -> None:  # type: ignore[no-untyped-def]
    """Request OP and send process data (the outputs OP needs) until every slave is there."""
    master.state = pysoem.OP_STATE
    master.write_state()
    for _ in range(500):
        master.send_processdata()
        master.receive_processdata(timeout_us)
        if master.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
            return
    pytest.fail(f"not in OP: {[hex(s.al_status) for s in master.slaves]}")


#: the process-data watchdog the ENIs set (0x0400 = 2498, 0x0420 = 1000: 100 ms)
PD_WATCHDOG_NS = 100_000_000


def _watchdog_trips(master, pysoem) -> tuple[int, int]:  # type: ignore[no-untyped-def]
    """Slaves found in SAFEOP+ERR with 0x001B (the process-data watchdog) after a cyclic
    phase, put back in OP as SOEM's ec_sample check does (acknowledge, request OP).

    A slave trips when the master writes no outputs for 100 ms: on these VMs the host
    now and then stops the master's process that long (a hog run failed so: every WKC
    right, the drive deaf to its controlwords). Hardware trips too; the judge then asks
    the capture whether the master really was silent that long (:func:`_judge`), up to
    the time returned with the count: when the states were read."""
    checked_ns = realtime_ns()
    master.read_state()
    error_safeop = pysoem.SAFEOP_STATE | pysoem.STATE_ERROR
    tripped = [s for s in master.slaves if s.state == error_safeop and s.al_status == 0x001B]
    for s in tripped:
        s.state = pysoem.SAFEOP_STATE | pysoem.STATE_ACK
        s.write_state()
    if tripped:
        _request_op(master, pysoem)
    return len(tripped), checked_ns


def _drive_sdo_checks(slave, pysoem) -> None:
    """Expedited read, write/read round trip, segmented read, abort for a missing object."""
    assert struct.unpack("<I", slave.sdo_read(0x1000, 0))[0] == 0x00020192
    slave.sdo_write(0x607F, 0, struct.pack("<I", 250_000))
    assert struct.unpack("<I", slave.sdo_read(0x607F, 0))[0] == 250_000
    slave.sdo_write(0x607F, 0, struct.pack("<I", 0))  # no rate limit: CSP jumps
    name = slave.sdo_read(0x1008, 0)
    assert name == Cia402Drive.LONG_NAME.encode()
    assert len(name) > 140 - 16  # more than one 140-byte mailbox holds: segmented
    with pytest.raises(pysoem.SdoError) as exc:
        slave.sdo_read(0x2345, 0)
    assert exc.value.abort_code == 0x06020000


def _cycles(master, n: int, period_s: float, timeout_us: int = 2000, poll=None) -> list[int]:
    """``n`` cycles on a fixed period; ``poll(i)`` runs in each (a mailbox poll)."""
    bad = []
    next_t = time.perf_counter()
    for i in range(n):
        master.send_processdata()
        wkc = master.receive_processdata(timeout_us)
        if wkc != master.expected_wkc:
            bad.append((i, wkc))
        if poll is not None:
            poll(i)
        next_t += period_s
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return bad


SOEM_TIMEOUT_NS = 2_000_000  # EC_TIMEOUTRET, pysoem's receive_processdata(2000)


def _pysoem_cycles(master, n: int, poll=None) -> list[MasterError]:  # type: ignore[no-untyped-def]
    """``n`` cycles at 1 kHz; a cycle whose frame did not come back (-1, EC_NOFRAME) or
    came back with another working counter than expected, with its time."""
    errors = []
    next_t = time.perf_counter()
    for i in range(n):
        t0 = realtime_ns()
        master.send_processdata()
        wkc = master.receive_processdata(2000)
        if wkc != master.expected_wkc:
            why = "no frame within 2 ms" if wkc == -1 else f"WKC {wkc} in cycle {i}"
            errors.append(MasterError(t0, realtime_ns(), why, SOEM_TIMEOUT_NS))
        if poll is not None:
            poll(i)
        next_t += 0.001
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return errors


#: CiA 402: controlword, then the statusword (masked 0x6F) it leads to, then position
_ENABLE = ((0x06, 0x21), (0x07, 0x23), (0x0F, 0x27))


def _enable_drive(master, slave, target: int, deadline_s: float = 0.5) -> list[int]:  # type: ignore[no-untyped-def]
    """Enable a CiA 402 drive and command ``target`` as a master does: each controlword
    cycle after cycle (1 kHz) until the statusword shows its state, then until the
    position follows. A drive steps on its own cycle, not on every frame: a real one
    takes a few of them per transition. The frames each step took (the emulated drive
    steps once per frame it gets: 1 each, plus the answer's one-frame lag)."""
    frames = []
    for cw, want in (*_ENABLE, (0x0F, None)):
        n, until = 0, time.perf_counter() + deadline_s
        while True:
            slave.output = struct.pack("<HbiI", cw, 8, target, 0)
            master.send_processdata()
            assert master.receive_processdata(2000) == master.expected_wkc
            n += 1
            status, _mode, actual = struct.unpack_from("<Hbi", slave.input)
            if (status & 0x6F == want) if want is not None else actual == target:
                break
            assert time.perf_counter() < until, (
                f"cw 0x{cw:02X}: status 0x{status:04X} after {n} frames"
            )
            time.sleep(0.001)
        frames.append(n)
    log = os.environ.get("LOLACLI_MASTER_LOG")
    if log:
        with open(log, "a") as f:
            f.write(json.dumps({"test": _test_name(), "enable_frames": frames}) + "\n")
    return frames


def test_pysoem_single_drive(emulate, veth, pysoem) -> None:
    from lolacli.files import load_eni

    eni_path = EXAMPLES / "single_drive.xml"
    eni = load_eni(eni_path)
    proc = emulate(eni_path)
    master = pysoem.Master()
    capture = MasterCapture(veth[0])
    try:
        capture.__enter__()
        t0 = realtime_ns()
        master.open(veth[0])
        assert master.config_init() == len(eni.slaves) == 1
        slave = master.slaves[0]
        ident = eni.slaves[0].identity
        assert (slave.name, slave.man, slave.id, slave.rev) == (
            eni.slaves[0].name,
            ident.vendor_id,
            ident.product_code,
            ident.revision,
        )
        assert master.config_map() > 0
        # SDO in SAFEOP: in OP the drive's process-data watchdog (100 ms) wants outputs
        _drive_sdo_checks(slave, pysoem)
        _to_op(master, pysoem)
        assert master.expected_wkc == eni.cyclic_frames[0].commands[0].expected_wkc == 3
        # process data: enable the drive, command a position, see it followed
        t1 = realtime_ns()
        errors = _pysoem_cycles(master, CYCLES)  # 10 s at 1 kHz
        t2 = realtime_ns()
        tripped = _watchdog_trips(master, pysoem)
        steps = _enable_drive(master, slave, target=4242)
        status, mode, actual, _velocity = struct.unpack("<Hbii", slave.input)
        assert status & 0x6F == 0x27 and mode == 8 and actual == 4242, steps
        master.state = pysoem.INIT_STATE
        master.write_state()
        capture.__exit__()
        emulator = _stop(proc)
        phases = [(t0, t1, SOEM_TIMEOUT_NS, False), (t1, t2, SOEM_TIMEOUT_NS, True)]
        _judge(capture, emulator, phases, errors, CYCLES, tripped=tripped)
    finally:
        master.close()
        capture.close()


def test_pysoem_lola_chain(emulate, veth, pysoem) -> None:
    from lolacli.files import load_eni

    eni_path = EXAMPLES / "lola.xml"
    eni = load_eni(eni_path)
    proc = emulate(eni_path)
    master = pysoem.Master()
    capture = MasterCapture(veth[0])
    try:
        capture.__enter__()
        t0 = realtime_ns()
        master.open(veth[0])
        assert master.config_init() == 25
        identities = [(s.man, s.id) for s in master.slaves]
        assert identities == [(s.identity.vendor_id, s.identity.product_code) for s in eni.slaves]
        assert master.slaves[21].name == eni.slaves[21].name  # the CAN gateway
        image = sum((s.inputs_bits + 7) // 8 + (s.outputs_bits + 7) // 8 for s in eni.slaves)
        assert master.config_map() == image == 1026
        assert struct.unpack("<I", master.slaves[24].sdo_read(0x1018, 1))[0] == 2
        _drive_sdo_checks(master.slaves[4], pysoem)  # a joint drive in mid-line
        _to_op(master, pysoem)
        assert master.expected_wkc == 70 == eni.cyclic_frames[0].commands[0].expected_wkc
        t1 = realtime_ns()
        errors = _pysoem_cycles(master, CYCLES)  # 10 s at 1 kHz
        t2 = realtime_ns()
        tripped = _watchdog_trips(master, pysoem)
        capture.__exit__()
        emulator = _stop(proc)
        phases = [(t0, t1, SOEM_TIMEOUT_NS, False), (t1, t2, SOEM_TIMEOUT_NS, True)]
        _judge(capture, emulator, phases, errors, CYCLES, tripped=tripped)
    finally:
        master.close()
        capture.close()


def test_pysoem_lola_chain_polls_a_mailbox_every_cycle(emulate, veth, pysoem) -> None:
    """A 1 kHz master that also polls one slave's mailbox each cycle, round the line (as
    SOEM's ec_sample): no cycle lost, no slave falls out of OP (no SM watchdog, 0x001B).
    LOLACLI_SOAK_S sets how long (60 s for the acceptance soak)."""
    from lolacli.files import load_eni

    eni = load_eni(EXAMPLES / "lola.xml")
    proc = emulate(EXAMPLES / "lola.xml")
    master = pysoem.Master()
    capture = MasterCapture(veth[0])
    try:
        capture.__enter__()
        t0 = realtime_ns()
        master.open(veth[0])
        assert master.config_init() == 25
        master.config_map()
        _to_op(master, pysoem)
        with_mailbox = [master.slaves[i] for i, s in enumerate(eni.slaves) if s.mailbox]

        def poll(i: int) -> None:
            with_mailbox[i % len(with_mailbox)].mbx_receive()

        cycles = int(SOAK_S * 1000)
        t1 = realtime_ns()
        errors = _pysoem_cycles(master, cycles, poll=poll)
        t2 = realtime_ns()
        tripped = _watchdog_trips(master, pysoem)
        master.read_state()
        assert [s.state for s in master.slaves] == [pysoem.OP_STATE] * 25
        capture.__exit__()
        emulator = _stop(proc)
        phases = [(t0, t1, SOEM_TIMEOUT_NS, False), (t1, t2, SOEM_TIMEOUT_NS, True)]
        _judge(capture, emulator, phases, errors, cycles, tripped=tripped)
    finally:
        master.close()
        capture.close()


KICKCAT_LINK_TIMEOUT_NS = 2_000_000  # KickCAT's default link timeout (start-up)
KICKCAT_CYCLIC_TIMEOUT_NS = 500_000  # its examples' timeout in the cyclic loop
KICKCAT_STARTS = 10  # start-ups tried, each one that timed out with every answer in time
# time-outs at the master with every answer there: the master's own (KickCAT's 20 µs
# sleep-poll with normal scheduling misses its 500 µs deadline in ~0.5-1.2 % of cycles on
# this loaded host); beyond 10 % the host is not fit for the test
MASTER_TIMEOUTS_PER_CYCLE = 0.10


@dataclass(frozen=True, slots=True)
class MasterError:
    """A call of the master that raised: when (CLOCK_REALTIME, as the capture) and why."""

    start_ns: int
    end_ns: int
    message: str
    deadline_ns: int


def _kickcat_start(kickcat, iface: str, start, errors: list[MasterError]):  # type: ignore[no-untyped-def]
    """KickCAT's bus and link after ``start(bus)`` went through; a start-up that raised is
    tried again (at most KICKCAT_STARTS in all), each failure kept for the verdict."""
    for _ in range(KICKCAT_STARTS):
        link = kickcat.create_link(iface, "")  # default link timeout: 2 ms
        bus = kickcat.Bus(link)
        t0 = realtime_ns()
        try:
            start(bus)
        except RuntimeError as exc:
            errors.append(MasterError(t0, realtime_ns(), str(exc)[:120], KICKCAT_LINK_TIMEOUT_NS))
            continue
        return bus, link
    pytest.fail(f"KickCAT did not start: {[e.message for e in errors]}")


def _kickcat_cycles(bus, link, n: int) -> list[MasterError]:  # type: ignore[no-untyped-def]
    """``n`` cycles at 1 kHz with the 500 µs link timeout of KickCAT's examples."""
    link.set_timeout(KICKCAT_CYCLIC_TIMEOUT_NS / 1e9)
    errors = []
    next_t = time.perf_counter()
    for _ in range(n):
        t0 = realtime_ns()
        try:
            bus.process_data()  # raises on a lost datagram or a working-counter mismatch
        except RuntimeError as exc:
            errors.append(MasterError(t0, realtime_ns(), str(exc)[:120], KICKCAT_CYCLIC_TIMEOUT_NS))
        next_t += 0.001
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return errors


@contextmanager
def _realtime_master() -> Iterator[str]:
    """KickCAT's thread at SCHED_FIFO 5 (below the emulator's 10) where permitted, for its
    start-up; normal scheduling again afterwards. KickCAT reads its socket in a loop that
    sleeps 20 µs and gives up when a sleep ends past its deadline, without a last look at
    the socket: with normal scheduling on this saturated 2-core host its process now and
    then does not run for 2-90 ms while the answers wait in the socket (every answer of
    such a failed start-up within 300 µs in the capture, the error raised milliseconds
    after KickCAT's last frame), and a LOLA start-up reads the socket some 3,000 times
    against its 2 ms link timeout. In the cyclic loop KickCAT runs with normal scheduling:
    polling every 20 µs at a real-time priority it holds back the kernel's softirq thread
    that delivers the veth's packets once it is behind, and the answers come late; there
    the capture check (_judge) tells its own time-outs from late answers."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(5))
    except (OSError, AttributeError):
        yield "normal"
        return
    try:
        yield "SCHED_FIFO 5"
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


LATE_SHARE = 0.01  # answers past the master's deadline: at most 1 % of a phase's exchanges
STALL_GAP_NS = 1_000_000  # late answers that come out within 1 ms of each other: one stall


def _stalls(late: list[Exchange]) -> int:
    """Late answers grouped by when they came out: a stall holds back every frame that
    arrives while it lasts, and they all come out when it ends."""
    ends = sorted(e.reply_ns or e.sent_ns for e in late)
    return sum(1 for i, t in enumerate(ends) if i == 0 or t - ends[i - 1] > STALL_GAP_NS)


def _emulator_times(text: str) -> dict[str, tuple[int, int, int]]:
    """The emulator's own reply times at stop ("wake-up"/"answer": p50, p99, max µs)."""
    found = re.findall(r"(wake-up|answer) p50 (\d+) µs, p99 (\d+) µs, max (\d+) µs", text)
    return {name: (int(a), int(b), int(c)) for name, a, b, c in found}


def _judge(
    capture: MasterCapture,
    emulator: str,
    phases: list[tuple[int, int, int, bool]],
    errors: list[MasterError],
    cycles: int,
    *,
    tripped: tuple[int, int] = (0, 0),
) -> None:
    """The emulator judged apart from the master's own verdict: does a real master with
    its default timeouts get what it needs? The latency targets themselves (p99 <= 150 µs,
    max <= 1 ms) are performance figures, measured by benchmarks/emulate_latency.py, not
    asserted here: on these 2-core VMs an idle vCPU takes 100-200 µs to wake (CI saw a
    185 µs median for SOEM's 5 ms cycle), which no emulator code can change.

    From the capture of the master's side (kernel timestamps): every frame the emulator
    received answered; per phase ((start, end, the master's deadline, cyclic)) the
    answers past the master's deadline at most LATE_SHARE of the phase's exchanges (5 at
    least: on this PREEMPT_NONE VM under load even a SCHED_FIFO C sleeper wakes up to
    ~5 ms late now and then, and the kernel leaves the veth's packets to a ksoftirqd
    thread that waits behind CPU hogs), and in the cyclic phase the median within half the
    deadline (an emulator answering in milliseconds, as before issue 9, fails both). From
    the emulator's own figures (its socket's receive timestamp to the answer sent): the p99
    of its service within the tightest deadline of the masters (KickCAT's cyclic 500 µs).
    The master's errors: never a wrong working counter; a time-out only where the capture
    shows every frame of its window answered; at most MASTER_TIMEOUTS_PER_CYCLE of the
    cycles. Slaves that ``tripped`` their process-data watchdog ((how many, when the
    states were read)): only where the master sent nothing for longer than the watchdog
    between the cyclic phase's start and then."""
    report = capture.report()
    if not capture.available:
        assert not errors, errors[:3]
        return
    assert report.exchanges, "nothing captured"
    # an answer missing from a capture that itself dropped packets is the capture's loss
    assert capture.dropped is not None, "dumpcap did not report its counts"
    if capture.dropped == 0:
        missing = report.unanswered()
        counts = re.search(
            r"stopped: (\d+) frames received, (\d+) answered(?:, (\d+) dropped "
            r"at the socket)?",
            emulator,
        )
        assert counts, emulator
        received, answered = int(counts[1]), int(counts[2])
        socket_drops = int(counts[3]) if counts[3] is not None else None
        # a frame of the master that never reached the emulator's socket (the capture holds
        # more requests than the emulator received, and its socket dropped none) is lost on
        # the host's path, which no emulator can answer: seen 1 in ~8 runs, the mailbox poll's
        # last FPRD; every frame the emulator did receive must be answered
        never_arrived = len(report.exchanges) - received
        assert answered == received, emulator
        if missing and socket_drops == 0 and len(missing) <= never_arrived:
            sys.stderr.write(f"{len(missing)} frames never reached the emulator: not judged\n")
        else:
            assert missing == [], (missing[:3], emulator)
    else:
        sys.stderr.write(f"dumpcap dropped {capture.dropped} packets: answers not judged\n")
    figures, late = [], []
    for start, end, deadline, cyclic in phases:
        window = report.between(start, end)
        late_here = report.late_in(start, end, deadline)
        late += late_here
        assert len(late_here) <= max(5, LATE_SHARE * len(window)), (
            len(late_here),
            len(window),
            late_here[:5],
            report.summary(),
        )
        p50, p99 = report.percentile_ns(0.5, window), report.percentile_ns(0.99, window)
        figures.append((p50 / 1000, p99 / 1000))
        if cyclic:
            assert p50 <= deadline / 2, (p50, p99, report.summary())
    trips, checked_ns = tripped
    cyclic_start = min((start for start, _end, _deadline, cyclic in phases if cyclic), default=0)
    silence = report.longest_silence_ns(cyclic_start, max(checked_ns, phases[-1][1]))
    if trips:
        assert silence >= PD_WATCHDOG_NS, f"{trips} watchdog trips, master silent {silence} ns"
    stalls = _stalls(late)
    times = _emulator_times(emulator)
    assert "answer" in times, emulator  # bus emulate's stop line gives its reply times
    assert times["answer"][1] <= KICKCAT_CYCLIC_TIMEOUT_NS / 1000, emulator
    for e in errors:
        assert "WKC" not in e.message.upper() and "working counter" not in e.message, e
        assert all(x.reply_ns is not None for x in report.between(e.start_ns, e.end_ns)), e
    assert len(errors) <= max(1, MASTER_TIMEOUTS_PER_CYCLE * cycles), errors[:5]
    note = f"at the master: {report.summary()}; p50/p99 per phase {figures}; "
    note += f"late {len(late)} in {stalls} stalls; "
    # the slowest answer in each time-out's window: within the deadline, the master did
    # not look at its socket in time
    slowest = [
        max((x.latency_ns or 0 for x in report.between(e.start_ns, e.end_ns)), default=0) // 1000
        for e in errors
    ]
    note += f"master time-outs {len(errors)} {[e.message for e in errors[:2]]}, slowest "
    note += f"answer in their windows {sorted(slowest)[-5:]} µs; emulator {times}"
    placement = re.search(
        r"placement: moved .*? (\d+) times, left it to the OS (\d+)", emulator
    )
    if placement:
        note += f"; moved to the master's CPU {placement[1]} times, left it {placement[2]}"
    sys.stderr.write(note + "\n")
    log = os.environ.get("LOLACLI_MASTER_LOG")  # one JSON line per run, for repeat runs
    if log:
        with open(log, "a") as f:
            record = {"phases": figures, "late": len(late), "stalls": stalls}
            record |= {"errors": len(errors), "note": note, "test": _test_name()}
            record |= {"tripped": trips, "silence_ms": round(silence / 1e6, 3)}
            record["startup_errors"] = sum(1 for e in errors if e.start_ns < phases[-1][0])
            f.write(json.dumps(record) + "\n")


def _test_name() -> str:
    return os.environ.get("PYTEST_CURRENT_TEST", "").split(" ")[0]


def test_kickcat_single_drive(emulate, veth) -> None:
    """KickCAT with its default timeouts; the emulator judged on the capture (_judge)."""
    kickcat = pytest.importorskip("kickcat")
    proc = emulate(EXAMPLES / "single_drive.xml")
    errors: list[MasterError] = []
    capture = MasterCapture(veth[0])

    def start(bus) -> None:  # type: ignore[no-untyped-def]
        bus.init(0.1)
        slaves = bus.slaves()
        assert len(slaves) == 1
        bus.create_mapping()
        assert (slaves[0].input_size, slaves[0].output_size) == (11, 11)
        bus.request_state(kickcat.State.SAFE_OP)
        bus.wait_for_state(kickcat.State.SAFE_OP, 1.0)

    try:
        with capture:
            with _realtime_master():  # the start-up; the cyclic loop with normal scheduling
                t0 = realtime_ns()
                bus, link = _kickcat_start(kickcat, veth[0], start, errors)
                slaves = bus.slaves()
                raw = bus.read_sdo(slaves[0], 0x1000, 0, kickcat.Access.PARTIAL, 4, 0.1)
                assert struct.unpack("<I", raw)[0] == 0x00020192
                # (KickCAT 2.5 crashes on segmented uploads, fixed upstream after 2.5: not asked)
                raw = bus.read_sdo(slaves[0], 0x100A, 0, kickcat.Access.PARTIAL, 64, 0.1)
                assert raw == b"lolacli emulator"
                slaves[0].set_output_bytes(struct.pack("<HbiI", 0, 8, 0, 0))
                bus.process_data_no_check()
                bus.request_state(kickcat.State.OPERATIONAL)
                bus.wait_for_state(
                    kickcat.State.OPERATIONAL, 1.0, lambda: bus.process_data_no_check()
                )
            t1 = realtime_ns()
            errors += _kickcat_cycles(bus, link, CYCLES)
            t2 = realtime_ns()
        status = struct.unpack_from("<H", slaves[0].input_data)[0]
        assert status & 0x4F == 0x40  # switch on disabled, as after power-up
        emulator = _stop(proc)
        phases = [
            (t0, t1, KICKCAT_LINK_TIMEOUT_NS, False),
            (t1, t2, KICKCAT_CYCLIC_TIMEOUT_NS, True),
        ]
        _judge(capture, emulator, phases, errors, CYCLES)
    finally:
        capture.close()


def test_emulate_reports_missing_interface(cli) -> None:
    code, _out, err = cli("bus", "emulate", "--iface", "nosuchif0", "--duration", "1")
    assert code == 4
    assert "no such interface: nosuchif0" in err


def test_kickcat_lola_chain(emulate, veth) -> None:
    """KickCAT with its default timeouts on the LOLA chain; the emulator judged on the
    capture (_judge)."""
    kickcat = pytest.importorskip("kickcat")
    from lolacli.files import load_eni

    eni = load_eni(EXAMPLES / "lola.xml")
    proc = emulate(EXAMPLES / "lola.xml")
    errors: list[MasterError] = []
    capture = MasterCapture(veth[0])

    def start(bus) -> None:  # type: ignore[no-untyped-def]
        bus.init(0.1)
        slaves = bus.slaves()
        assert len(slaves) == 25
        bus.create_mapping()
        sizes = [(s.input_size, s.output_size) for s in slaves]
        assert sizes == [
            ((sl.inputs_bits + 7) // 8, (sl.outputs_bits + 7) // 8) for sl in eni.slaves
        ]
        bus.request_state(kickcat.State.SAFE_OP)
        bus.wait_for_state(kickcat.State.SAFE_OP, 5.0)

    try:
        with capture:
            with _realtime_master():  # the start-up; the cyclic loop with normal scheduling
                t0 = realtime_ns()
                bus, link = _kickcat_start(kickcat, veth[0], start, errors)
                slaves = bus.slaves()
                raw = bus.read_sdo(slaves[3], 0x1000, 0, kickcat.Access.PARTIAL, 4, 0.1)
                assert struct.unpack("<I", raw)[0] == 0x00020192  # Joint04: a CiA 402 servo drive
                for s in slaves:
                    s.set_output_bytes(bytes(s.output_size))
                bus.process_data_no_check()
                bus.request_state(kickcat.State.OPERATIONAL)
                bus.wait_for_state(
                    kickcat.State.OPERATIONAL, 5.0, lambda: bus.process_data_no_check()
                )
            t1 = realtime_ns()
            errors += _kickcat_cycles(bus, link, CYCLES)
            t2 = realtime_ns()
        emulator = _stop(proc)
        phases = [
            (t0, t1, KICKCAT_LINK_TIMEOUT_NS, False),
            (t1, t2, KICKCAT_CYCLIC_TIMEOUT_NS, True),
        ]
        _judge(capture, emulator, phases, errors, CYCLES)
    finally:
        capture.close()


@pytest.fixture(scope="module")
def soem_tools_built() -> dict[str, Path]:
    from tests.emulator.soem_tools import soem_tools

    tools, why = soem_tools()
    if tools is None:
        pytest.skip(f"SOEM's tools cannot be built here: {why}")
    return tools


def _slaveinfo(text: str) -> list[dict[str, str]]:
    """slaveinfo's per-slave blocks: name, sizes, identity."""
    out = []
    for block in text.split("\nSlave:")[1:]:
        name = re.search(r"^ Name:(.*)$", block, re.M)
        sizes = re.search(r"Output size: (\d+)bits\n Input size: (\d+)bits", block)
        ident = re.search(r"Man: (\w+) ID: (\w+) Rev: (\w+)", block)
        assert name and sizes and ident, block[:300]
        out.append(
            {
                "name": name.group(1),
                "outputs_bits": sizes.group(1),
                "inputs_bits": sizes.group(2),
                "identity": " ".join(ident.groups()),
            }
        )
    return out


@pytest.mark.parametrize("eni_name", ["single_drive.xml", "lola.xml"])
def test_soem_slaveinfo_agrees_with_the_eni(emulate, veth, soem_tools_built, eni_name: str) -> None:
    from lolacli.files import load_eni

    eni = load_eni(EXAMPLES / eni_name)
    proc = emulate(EXAMPLES / eni_name)
    done = subprocess.run(
        [str(soem_tools_built["slaveinfo"]), veth[0], "-map"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    _stop(proc)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"{len(eni.slaves)} slaves found and configured." in done.stdout
    wkc = eni.cyclic_frames[0].commands[0].expected_wkc
    assert f"Calculated workcounter {wkc}" in done.stdout
    found = _slaveinfo(done.stdout)
    # SOEM reads the SII of the first slave of each identity and reuses it (name included)
    # for the later ones (ecx_lookup_prev_sii)
    first: dict[tuple[int, int, int], str] = {}
    for s in eni.slaves:
        ident = (s.identity.vendor_id, s.identity.product_code, s.identity.revision)
        first.setdefault(ident, s.name[:40])
    names = [
        first[(s.identity.vendor_id, s.identity.product_code, s.identity.revision)]
        for s in eni.slaves
    ]
    assert [f["name"] for f in found] == names
    assert [(int(f["outputs_bits"]), int(f["inputs_bits"])) for f in found] == [
        (s.outputs_bits, s.inputs_bits) for s in eni.slaves
    ]
    assert [f["identity"] for f in found] == [
        f"{s.identity.vendor_id:08x} {s.identity.product_code:08x} {s.identity.revision:08x}"
        for s in eni.slaves
    ]
    assert "PDO mapping according to CoE" in done.stdout


def test_soem_simple_test_loses_no_cycle(emulate, veth, soem_tools_built) -> None:
    """SOEM's simple_test on the LOLA chain: 10,000 cycles (5 ms apart), each with the
    working counter the ENI expects, no slave dropping out (its check thread would say)."""
    from lolacli.files import load_eni

    eni = load_eni(EXAMPLES / "lola.xml")
    proc = emulate(EXAMPLES / "lola.xml")
    capture = MasterCapture(veth[0])
    try:
        with capture:
            t0 = realtime_ns()
            done = subprocess.run(
                [str(soem_tools_built["simple_test"]), veth[0]],
                capture_output=True,
                text=True,
                timeout=300,
            )
            t1 = realtime_ns()
        emulator = _stop(proc)
        out = done.stdout.replace("\r", "\n")
        assert done.returncode == 0, out[-2000:]
        wkc = eni.cyclic_frames[0].commands[0].expected_wkc
        image = sum((s.inputs_bits + 7) // 8 + (s.outputs_bits + 7) // 8 for s in eni.slaves)
        assert f"segments : 1 : {image} 0 0 0" in out
        assert f"Calculated workcounter {wkc}" in out
        assert "Operational state reached for all slaves." in out
        cycles = re.findall(r"^Processdata cycle +(\d+), WKC (\d+)", out, re.M)
        assert {int(w) for _, w in cycles} == {wkc}  # never a wrong working counter
        assert not re.search(r"ERROR|WARNING|Not all slaves", out), out[-2000:]
        # simple_test prints a cycle only with WKC >= expected: the others timed out at
        # the master (2 ms); the capture shows whether their frames were answered
        missing = [
            MasterError(t0, t1, "no frame within 2 ms", SOEM_TIMEOUT_NS)
            for _ in range(10_000 - len(cycles))
        ]
        _judge(capture, emulator, [(t0, t1, SOEM_TIMEOUT_NS, True)], missing, 10_000)
    finally:
        capture.close()


def test_a_master_silent_past_the_watchdog_trips_it_and_recovers_the_slave(
    emulate, veth, pysoem
) -> None:
    """150 ms without a cyclic frame in OP: the drive's process-data watchdog (100 ms)
    trips it to SAFEOP+ERR 0x001B, as hardware does; the check every pysoem test runs
    after its cycles finds it, the capture shows the silence, the drive comes back to OP
    and is enabled."""
    eni_path = EXAMPLES / "single_drive.xml"
    proc = emulate(eni_path)
    master = pysoem.Master()
    capture = MasterCapture(veth[0])
    try:
        capture.__enter__()
        t0 = realtime_ns()
        master.open(veth[0])
        assert master.config_init() == 1
        master.config_map()
        _to_op(master, pysoem)
        t1 = realtime_ns()
        errors = _pysoem_cycles(master, 200)
        before_pause = realtime_ns()
        time.sleep(0.15)
        errors += _pysoem_cycles(master, 200)
        t2 = realtime_ns()
        tripped = _watchdog_trips(master, pysoem)
        assert tripped[0] == 1
        assert _enable_drive(master, master.slaves[0], target=-7)
        capture.__exit__()
        emulator = _stop(proc)
        phases = [(t0, t1, SOEM_TIMEOUT_NS, False), (t1, t2, SOEM_TIMEOUT_NS, True)]
        _judge(capture, emulator, phases, errors, 400, tripped=tripped)
        # a trip with the master never silent for 100 ms would be the emulator's fault
        before = [(t0, t1, SOEM_TIMEOUT_NS, False), (t1, before_pause, SOEM_TIMEOUT_NS, True)]
        with pytest.raises(AssertionError, match="watchdog trips, master silent"):
            _judge(capture, emulator, before, errors, 200, tripped=(1, before_pause))
    finally:
        master.close()
        capture.close()


def test_pysoem_sees_a_slave_stuck_in_safeop(emulate, veth, pysoem) -> None:
    emulate(EXAMPLES / "single_drive.xml", "--stuck-safeop", "1")
    master = pysoem.Master()
    try:
        master.open(veth[0])
        assert master.config_init() == 1
        master.config_map()
        assert master.state_check(pysoem.SAFEOP_STATE, 5_000_000) == pysoem.SAFEOP_STATE
        master.send_processdata()
        master.receive_processdata(2000)
        master.state = pysoem.OP_STATE
        master.write_state()
        for _ in range(50):
            master.send_processdata()
            master.receive_processdata(2000)
        master.read_state()
        slave = master.slaves[0]
        assert slave.state == pysoem.SAFEOP_STATE | 0x10  # error indicator set
        assert slave.al_status == 0x0019  # no valid outputs
    finally:
        master.close()


def test_emulate_status_line_and_clean_sigterm(veth) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", veth[1]],
        cwd=ROOT,
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        bufsize=0,
    )
    assert proc.stderr is not None
    first = b""
    while not first.endswith(b"\n") and (byte := proc.stderr.read(1)):
        first += byte  # serving from here on
    time.sleep(2.5)  # the status line comes every second
    proc.send_signal(15)
    out, rest = proc.communicate(timeout=20)
    err = (first + rest).decode()
    assert proc.returncode == 143, err  # stopped by SIGTERM
    assert out == b""  # nothing on stdout: status goes to stderr
    assert "emulating 25 slaves" in err
    assert "INIT×25" in err and "frames" in err
    assert "stopped:" in err
    # 80 columns, but the first line (it names the ENI's path, and scripts wait for it)
    assert [line for line in err.splitlines()[1:] if len(line) > 80] == [], err


def test_emulate_duration_stops_with_exit_0(veth) -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "lolacli",
            "bus",
            "emulate",
            "--iface",
            veth[1],
            "--eni",
            str(EXAMPLES / "single_drive.xml"),
            "--duration",
            "0.5",
            "--quiet",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    # no master on this pair; the count itself is not the subject (on a shared host a
    # stray EtherCAT frame of another test's master has turned up: 1 run in 20)
    assert re.search(r"stopped: \d+ frames received", done.stderr), done.stderr


def test_pysoem_counts_frames_lost_by_the_drop_fault(emulate, veth, pysoem) -> None:
    emulate(EXAMPLES / "single_drive.xml", "--drop-p", "0.02", "--seed", "3")
    master = pysoem.Master()
    try:
        master.open(veth[0])
        assert master.config_init() == 1  # SOEM's retries ride over the lost frames
        assert master.config_map() > 0
        _to_op(master, pysoem, 2000)
        bad = _cycles(master, 3000, 0.0005, 2000)
        assert all(wkc == -1 for _, wkc in bad)  # lost, never a wrong WKC
        assert 15 <= len(bad) <= 120  # 2 % of 3000 = 60
    finally:
        master.close()


def test_emulate_without_raw_socket_permission_exits_4() -> None:
    need_root()
    if shutil.which("setpriv") is None:
        pytest.skip("needs setpriv to drop CAP_NET_RAW")
    done = subprocess.run(
        [
            "setpriv",
            "--inh-caps=-net_raw",
            "--bounding-set=-net_raw",
            sys.executable,
            "-m",
            "lolacli",
            "bus",
            "emulate",
            "--iface",
            "lo",
            "--duration",
            "0.5",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 4
    assert "no permission for a raw socket" in done.stderr
    assert "Traceback" not in done.stderr


def test_pysoem_finds_the_slaves_before_a_cut_cable(emulate, veth, pysoem) -> None:
    emulate(EXAMPLES / "lola.xml", "--link-down", "7")
    master = pysoem.Master()
    try:
        master.open(veth[0])
        assert master.config_init() == 7
        assert master.slaves[-1].name == "Joint01 L Hip Yaw"  # SOEM reuses SII of equal ids
    finally:
        master.close()


def test_pysoem_sees_damaged_frames_in_wkc_and_rx_error_counters(emulate, veth, pysoem) -> None:
    emulate(EXAMPLES / "lola.xml", "--corrupt-p", "0.01", "--seed", "5")
    master = pysoem.Master()
    try:
        master.open(veth[0])
        assert master.config_init() == 25  # SOEM retries a discovery frame that came back short
        assert master.config_map() > 0
        _to_op(master, pysoem)
        bad = _cycles(master, 1000, 0.002)
        low = [wkc for _, wkc in bad if wkc >= 0]
        assert low and all(0 <= wkc < master.expected_wkc for wkc in low)
        invalid = sum(_read_counter(slave, pysoem, 0x0300) for slave in master.slaves)
        assert invalid > 0  # 0x0300: invalid frame counter of port 0, over the whole line
    finally:
        master.close()


def _read_counter(slave, pysoem, address: int) -> int:
    """One counter byte by FPRD; the read itself may be damaged (WkcError): read again."""
    for _ in range(20):
        try:
            return int(slave._fprd(address, 1)[0])
        except pysoem.WkcError:
            continue
    pytest.fail(f"FPRD 0x{address:04X} kept failing")


def test_pysoem_sees_the_line_shorten_when_the_scheduled_link_loss_comes(
    emulate, veth, pysoem
) -> None:
    emulate(EXAMPLES / "lola.xml", "--link-down", "3@1.5")
    master = pysoem.Master()
    try:
        master.open(veth[0])
        assert master.config_init() == 25  # the cable is still whole
        time.sleep(2.0)
        assert master.config_init() == 3  # cut after slave 3: a BRD reaches three slaves
        assert _read_counter(master.slaves[2], pysoem, 0x0311) == 1  # lost link, port 1
    finally:
        master.close()


def test_pysoem_drives_every_cia402_transition(emulate, veth, pysoem) -> None:
    """SOEM (pysoem) writes the controlword into the process data of `bus emulate`'s
    drive and reads the statusword back: every commanded transition of CiA 402-2
    Figure 4, a following error past its window (fault, 0x8611 in 0x603F read by SDO), the
    fault reset on the rising edge of bit 7 and quick stop by its option code, against
    the standard's statusword patterns (tests/devices/cia402_tables.py)."""
    from tests.devices import cia402_tables as t

    eni_path = EXAMPLES / "single_drive.xml"
    emulate(eni_path)
    master = pysoem.Master()
    try:
        master.open(veth[0])
        assert master.config_init() == 1
        slave = master.slaves[0]
        assert master.config_map() > 0
        _to_op(master, pysoem)
        held = {"target": 0}

        def send(cw: int, goal: str | None = None, allowed: tuple[str, ...] = ()) -> str:
            """``cw`` each 1 ms cycle until the statusword shows ``goal`` (or 3 cycles
            when None); every state shown meanwhile is one of ``allowed`` or the goal."""
            until = time.perf_counter() + 0.5
            n = 0
            while True:
                slave.output = struct.pack("<HbiI", cw, 8, held["target"], 0)
                master.send_processdata()
                assert master.receive_processdata(2000) == master.expected_wkc
                n += 1
                status, _mode, actual = struct.unpack_from("<Hbi", slave.input)
                states = t.states_of(status)
                assert len(states) == 1, hex(status)
                if states[0] == goal or goal is None and n >= 3:
                    return states[0]
                assert goal is None or states[0] in allowed, (hex(cw), hex(status), goal)
                assert time.perf_counter() < until, (hex(cw), hex(status), goal)
                time.sleep(0.001)

        def home() -> None:
            state = send(t.DISABLE_VOLTAGE)
            if state == "Fault":
                send(t.FAULT_RESET, "Switch on disabled", ("Fault",))
            send(t.DISABLE_VOLTAGE, "Switch on disabled")

        def reach(state: str) -> None:
            home()
            now = "Switch on disabled"
            for cw in t.PATH[state]:
                goal = next(g for _n, s, c, g in t.TRANSITIONS if s == now and c == cw)
                now = send(cw, goal, (now,))

        for number, source, cw, goal in t.TRANSITIONS:
            reach(source)
            assert send(cw, goal, (source,)) == goal, number
        # following error: window 50, timeout 3 ms, the follower limited to 10 increments/ms
        for index, fmt, value in ((0x6065, "<I", 50), (0x6066, "<H", 3), (0x607F, "<I", 10_000)):
            slave.sdo_write(index, 0, struct.pack(fmt, value))
        reach("Operation enabled")
        actual = struct.unpack_from("<Hbi", slave.input)[2]
        held["target"] = actual + 100_000
        reaction = ("Operation enabled", "Fault reaction active")  # transitions 13, 14
        send(t.ENABLE_OPERATION | t.FAULT_RESET, "Fault", reaction)
        send(t.FAULT_RESET)
        assert t.states_of(struct.unpack_from("<H", slave.input)[0]) == ["Fault"]  # no edge
        assert struct.unpack("<H", slave.sdo_read(0x603F, 0))[0] == 0x8611
        held["target"] = struct.unpack_from("<Hbi", slave.input)[2]
        send(t.DISABLE_VOLTAGE)
        send(t.FAULT_RESET, "Switch on disabled", ("Fault",))  # the rising edge
        assert struct.unpack("<H", slave.sdo_read(0x603F, 0))[0] == 0
        slave.sdo_write(0x6065, 0, struct.pack("<I", 0xFFFFFFFF))
        # quick stop, option code 2: stop, then switch on disabled on its own
        slave.sdo_write(0x605A, 0, struct.pack("<h", 2))
        reach("Operation enabled")
        send(t.QUICK_STOP, "Switch on disabled", ("Operation enabled", "Quick stop active"))
        slave.sdo_write(0x605A, 0, struct.pack("<h", 6))
        master.state = pysoem.INIT_STATE
        master.write_state()
    finally:
        master.close()
