"""Run an emulated chain on an interface: the library side of ``lolacli bus emulate``."""

from __future__ import annotations

import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from lolacli.devices.can import CanConfig, LiveSamples
from lolacli.devices.io import CanGateway
from lolacli.emulator.chain import Chain, Faults
from lolacli.emulator.line import ChainTiming
from lolacli.emulator.rawsock import RawSocketServer, ServerStats
from lolacli.emulator.registers import AL_ERROR_INDICATOR, AL_STATE_MASK, AlState
from lolacli.emulator.sii import sii_from_esi_device
from lolacli.emulator.slave import build_chain, device_of
from lolacli.eni.esi import EsiDevice, EsiFile
from lolacli.eni.model import Eni, Slave
from lolacli.errors import EniError, UsageError
from lolacli.timing.model import parse_duration_ns

#: clock drift along the line: a crystal drifts about ±100 ppm; ten times that at most
MAX_DRIFT_PPB = 1_000_000


@dataclass(frozen=True, slots=True)
class EmulateOptions:
    drop_probability: float = 0.0
    stuck_safeop: tuple[int, ...] = ()  # 1-based positions that refuse SAFEOP -> OP
    drift_ppb: int = 0
    seed: int = 0
    link_down_after: int | None = None  # cable cut after this 1-based position
    link_down_at_s: float = 0.0  # ... this long after serving starts (0: from the start)
    corrupt_probability: float = 0.0
    foe_password: int = 0  # every slave's FoE password (BOOT: firmware read and write)
    timing: ChainTiming | None = None  # the line's delays (None: the timing model's defaults)
    bad_link: tuple[int, float] | None = None  # (K, P): the cable into slave K damages frames


@dataclass(frozen=True, slots=True)
class EsiMatch:
    """An ENI slave (1-based ``position``) and the ESI device that describes it."""

    position: int
    slave: str
    device: EsiDevice
    source: str
    exact_revision: bool


def esi_matches(eni: Eni, esi: Sequence[EsiFile]) -> tuple[EsiMatch, ...]:
    """For each ENI slave, the ESI device of its vendor and product code: one with the same
    revision in any of the files first, else the first file's closest product match."""
    out: list[EsiMatch] = []
    for position, slave in enumerate(eni.slaves, start=1):
        match = _esi_match(slave, esi)
        if match is not None:
            device, source = match
            exact = device.identity.revision == slave.identity.revision
            out.append(EsiMatch(position, slave.name, device, source, exact))
    return tuple(out)


def _esi_match(slave: Slave, esi: Sequence[EsiFile]) -> tuple[EsiDevice, str] | None:
    ident = slave.identity
    found = [(f.find(ident.vendor_id, ident.product_code, ident.revision), f.source) for f in esi]
    candidates = [(d, src) for d, src in found if d is not None]
    exact = [(d, src) for d, src in candidates if d.identity.revision == ident.revision]
    best = exact or candidates
    return best[0] if best else None


def make_chain(eni: Eni, options: EmulateOptions, *, esi: Sequence[EsiFile] = ()) -> Chain:
    """The chain of ``eni`` with the faults of ``options``; UsageError for bad positions.
    Slaves that an ``esi`` device describes (see :func:`esi_matches`) take their SII from
    it; a product matched with another revision keeps the ENI's revision. An ENI without
    slaves is an EniError: there is no chain to emulate."""
    if not eni.slaves:
        raise EniError("the ENI has no <Slave>: no chain to emulate", path=eni.source)
    if not 0.0 <= options.drop_probability <= 1.0:
        raise UsageError(f"drop probability {options.drop_probability} is not in [0, 1]")
    if not 0.0 <= options.corrupt_probability <= 1.0:
        raise UsageError(f"corrupt probability {options.corrupt_probability} is not in [0, 1]")
    if not 0 <= options.foe_password <= 0xFFFF_FFFF:
        raise UsageError(f"FoE password {options.foe_password} is not a 32-bit unsigned number")
    bad = options.bad_link
    if bad is not None and not 1 <= bad[0] <= len(eni.slaves):
        raise UsageError(f"--bad-link {bad[0]}: the chain has slaves 1..{len(eni.slaves)}")
    faults = Faults(
        drop_probability=options.drop_probability,
        seed=options.seed,
        corrupt_probability=options.corrupt_probability,
        bad_link=bad[0] if bad else None,
        bad_link_probability=bad[1] if bad else 0.0,
    )
    try:  # the ENI/ESI readers take any integer; SII and register fields have fixed widths
        chain = build_chain(
            eni,
            timing=options.timing,
            faults=faults,
            drift_ppb=options.drift_ppb,
            foe_password=options.foe_password,
        )
        for m in esi_matches(eni, esi):
            ident = eni.slaves[m.position - 1].identity
            revision = None if m.exact_revision else ident.revision
            chain.use_sii(
                m.position, sii_from_esi_device(m.device, serial=ident.serial, revision=revision)
            )
    except (struct.error, OverflowError) as exc:
        raise EniError(
            f"cannot emulate: a number does not fit its EtherCAT field ({exc})", path=eni.source
        ) from None
    if abs(options.drift_ppb) > MAX_DRIFT_PPB:
        raise UsageError(
            f"--drift-ppb {options.drift_ppb}: expected -{MAX_DRIFT_PPB:,} to "
            f"{MAX_DRIFT_PPB:,} ppb (a crystal drifts about ±100,000 ppb)"
        )
    for position in options.stuck_safeop:
        if not 1 <= position <= len(chain.slaves):
            raise UsageError(
                f"--stuck-safeop {position}: the chain has slaves 1..{len(chain.slaves)}"
            )
        chain.stuck_in_safeop(position)
    after = options.link_down_after
    if after is not None and not 0 <= after <= len(chain.slaves):
        raise UsageError(f"--link-down {after}: the chain has slaves 1..{len(chain.slaves)}")
    if after is not None and options.link_down_at_s <= 0:
        chain.break_link(after)
    return chain


def arm_link_loss(chain: Chain, options: EmulateOptions, start_ns: int) -> None:
    """Schedule the ``link_down_after`` cut ``link_down_at_s`` after ``start_ns`` (the
    chain's time base) when it is not one from the start."""
    if options.link_down_after is not None and options.link_down_at_s > 0:
        chain.schedule_link_loss(
            options.link_down_after, start_ns + round(options.link_down_at_s * 1e9)
        )


def parse_link_down(text: str) -> tuple[int, float]:
    """``K`` or ``K@T`` -> (position K, seconds; 0 = from the start); UsageError. T is a
    duration (``0.5``, ``0.5s``, ``500ms``; bare numbers are seconds)."""
    position_text, at, seconds_text = text.partition("@")
    try:
        position = int(position_text)
        seconds = parse_duration_ns(seconds_text, "s") / 1e9 if at else 0.0
    except (ValueError, UsageError):
        raise UsageError(
            f"--link-down {text!r}: expected K or K@T (T in seconds, or 500ms, 0.5s)"
        ) from None
    if position < 0 or not 0.0 <= seconds < 1e9 or (at and seconds == 0.0):
        raise UsageError(f"--link-down {text!r}: K >= 0, SECONDS > 0")
    return position, seconds


#: --bad-link K without P: one frame in a hundred damaged
DEFAULT_BAD_LINK_P = 0.01


def parse_bad_link(text: str) -> tuple[int, float]:
    """``K`` or ``K:P`` -> (position K >= 1, probability P in (0, 1]); UsageError."""
    position_text, colon, p_text = text.partition(":")
    try:
        position = int(position_text)
        p = float(p_text) if colon else DEFAULT_BAD_LINK_P
    except ValueError:
        raise UsageError(
            f"--bad-link {text!r}: expected K or K:P (slave position, probability)"
        ) from None
    if position < 1 or not 0.0 < p <= 1.0:
        raise UsageError(f"--bad-link {text!r}: K >= 1 and 0 < P <= 1")
    return position, p


def state_summary(chain: Chain) -> str:
    """Slave states as a compact run-length string, e.g. ``OP×24 SAFEOP!×1``."""
    names = {int(s): s.name for s in AlState}
    parts: list[tuple[str, int]] = []
    for status in chain.al_statuses():
        state = status & AL_STATE_MASK
        label = names.get(state, f"0x{state:X}") + ("!" if status & AL_ERROR_INDICATOR else "")
        if parts and parts[-1][0] == label:
            parts[-1] = (label, parts[-1][1] + 1)
        else:
            parts.append((label, 1))
    return " ".join(f"{label}×{n}" for label, n in parts)


# A master's start-up, register by register (command, ADO, length; BWR/APWR/FPWR write
# zeros): the first frames of a real start-up then find the interpreter's specialised code
# and the ESCs' per-range write plans ready, instead of paying for them in their answer.
_WARM_UP: tuple[tuple[str, int, int], ...] = (
    ("BRD", 0x0000, 1), ("BRD", 0x0000, 2), ("BWR", 0x0101, 1), ("BWR", 0x0103, 1),
    ("BWR", 0x0200, 2), ("BWR", 0x0300, 8), ("BWR", 0x0300, 20), ("BWR", 0x0600, 48),
    ("BWR", 0x0600, 256), ("BWR", 0x0800, 32), ("BWR", 0x0800, 128), ("BWR", 0x0910, 4),
    ("BWR", 0x0910, 8), ("BWR", 0x0930, 2), ("BWR", 0x0934, 2), ("BWR", 0x0980, 2),
    ("BWR", 0x0981, 1), ("BWR", 0x0400, 2), ("BWR", 0x0410, 2), ("BWR", 0x0420, 2),
    ("BWR", 0x0442, 2), ("BWR", 0x0500, 1), ("BWR", 0x0500, 2), ("BWR", 0x0900, 4),
    ("BRD", 0x0130, 1), ("BRD", 0x0130, 2), ("BRD", 0x0110, 1), ("BRD", 0x09AE, 1),
    ("APRD", 0x0140, 2), ("APRD", 0x0010, 2), ("APWR", 0x0100, 2), ("FPRD", 0x0000, 10),
    ("FPRD", 0x0007, 2), ("FPRD", 0x0008, 2), ("FPRD", 0x0012, 2), ("FPRD", 0x0110, 2),
    ("FPRD", 0x0130, 2), ("FPRD", 0x0130, 6), ("FPRD", 0x0502, 2), ("FPRD", 0x0508, 4),
    ("FPRD", 0x0508, 8), ("FPRD", 0x0805, 1), ("FPRD", 0x080D, 1), ("FPRD", 0x080D, 2),
    ("FPRD", 0x0900, 4), ("FPRD", 0x0904, 4), ("FPRD", 0x0908, 4), ("FPRD", 0x090C, 4),
    ("FPRD", 0x0918, 8), ("FPWR", 0x0920, 8), ("FPWR", 0x0928, 4), ("FPWR", 0x0500, 1),
    ("FPWR", 0x0600, 16), ("FPWR", 0x0610, 16), ("FPWR", 0x0800, 8), ("FPWR", 0x0808, 8),
    ("FPWR", 0x0810, 8), ("FPWR", 0x0818, 8), ("FPWR", 0x0800, 16),
)  # fmt: skip


def warm_up(scratch: Chain) -> None:
    """Run a master's start-up (:data:`_WARM_UP`, twice) through ``scratch``, a chain made
    for that alone (of the same ENI as the one to serve: the same device models)."""
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    stations = [1001 + i for i in range(len(scratch.slaves))]
    t_ns = 0
    for _ in range(2):
        for i, station in enumerate(stations):  # addresses first, so FPxx reach a slave
            d = Datagram.physical(
                Command.APWR, (-i) & 0xFFFF, 0x0010, station.to_bytes(2, "little")
            )
            scratch.process(encode_frame(make_frame([d]), pad=True), t_ns, defer_cycles=True)
        for name, ado, length in _WARM_UP:
            cmd = Command[name]
            adp = stations[0] if name.startswith("FP") else 0
            data: bytes | int = bytes(length) if name.endswith("WR") else length
            frame = encode_frame(make_frame([Datagram.physical(cmd, adp, ado, data)]), pad=True)
            t_ns += 50_000
            scratch.process(frame, t_ns, defer_cycles=True)
            scratch.run_deferred_cycles()


def keep_warm_with(
    scratch: Chain, served: Chain | None = None
) -> Callable[[Callable[[], bool] | None], bool]:
    """Work for a server between frames (:class:`RawSocketServer` ``keep_warm``): a few
    register frames through ``scratch`` (the :func:`warm_up` chain, never the one served),
    so the code and data a frame needs stay in the caches while the master is silent or
    sends only its cyclic frame, and ``served``'s own memories read
    (:meth:`Chain.keep_warm`). The work's argument, ``should_yield``, is asked between its
    pieces (a frame each); False when it gave way. A session's first frame after an idle
    second (veth, LOLA, BRD probe of ``benchmarks/emulate_latency.py``): 260-410 µs
    without, 140-310 with; a plain echo server's 110-190. pysoem's closing BWR after
    10,000 cycles, its session replayed in process: 80 µs without, 33 with."""
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    frames = [
        encode_frame(make_frame([Datagram.physical(Command[name], 0, ado, data)]), pad=True)
        for name, ado, data in (("BRD", 0x0000, 2), ("BWR", 0x0103, b"\0"), ("BRD", 0x0130, 2))
    ]
    clock = [0]

    def warm(should_yield: Callable[[], bool] | None = None) -> bool:
        for frame in frames:
            clock[0] += 10_000_000
            scratch.process(frame, clock[0], defer_cycles=True)
            if should_yield is not None and should_yield():
                return False
        scratch.run_firmware()
        if served is not None:
            served.keep_warm()
        return True

    return warm


def serve(
    iface: str,
    chain: Chain,
    should_stop: Callable[[], bool],
    on_status: Callable[[ServerStats], None] | None = None,
    status_interval_s: float = 1.0,
    on_ready: Callable[[str], None] | None = None,
    realtime_priority: int | None = None,
    scratch: Chain | None = None,
    keep_cpus_awake: bool = True,
    cpu: int | str = "follow",
) -> ServerStats:
    """Serve ``chain`` on ``iface`` until ``should_stop()``; TransportError on socket trouble.
    ``on_ready(scheduling)`` is called once the socket is open (frames are answered from
    then on), with the scheduling the server got. ``realtime_priority``: ``None`` runs
    SCHED_FIFO where permitted (root or CAP_SYS_NICE) and normal scheduling elsewhere,
    0 normal scheduling, 1..99 SCHED_FIFO at that priority or a TransportError. A slave
    does not wait for other processes to yield the core; neither should its stand-in.
    ``scratch``: a second chain of the same ENI to :func:`warm_up` with first and to
    keep warm with while the master is silent (:func:`keep_warm_with`).
    ``keep_cpus_awake``: hold the CPUs' wake-up latency at 0 while serving (PM QoS, where
    permitted), as slave hardware never sleeps between frames. ``cpu``: where the server
    runs (:class:`RawSocketServer`: "follow" the master's CPU, "any", or a CPU number)."""
    keep_warm = None
    if scratch is not None:
        warm_up(scratch)
        keep_warm = keep_warm_with(scratch, chain)
    with RawSocketServer(
        iface,
        chain,
        realtime_priority=realtime_priority,
        keep_cpus_awake=keep_cpus_awake,
        keep_warm=keep_warm,
        cpu=cpu,
    ) as server:
        if on_ready is not None:
            on_ready(server.scheduling)
        return server.serve(should_stop, on_status=on_status, status_interval_s=status_interval_s)


def parse_cpu(text: str) -> int | str:
    """Where a server runs, as ``--cpu`` says it: "follow", "any" or a CPU number;
    UsageError otherwise."""
    if text in ("follow", "any"):
        return text
    if not text.isdigit():
        raise UsageError(f"{text!r}: expected follow, any or a CPU number")
    return int(text)


@dataclass(frozen=True, slots=True)
class EmulationStatus:
    """What a served chain has done so far (``bus emulate``'s status line)."""

    frames: int
    frames_per_s: float
    cycles: int
    lost: int
    damaged: int
    states: str  # :func:`state_summary`


class Emulation:
    """An ENI's chain with the faults of ``options``, served on an interface so a real
    master can drive it (``lolacli bus emulate``). Slaves that an ``esi`` device describes
    take their SII from it (:func:`make_chain`); the errors of a bad ENI or bad options
    come from the constructor, before anything is served."""

    def __init__(
        self, eni: Eni, options: EmulateOptions = EmulateOptions(), *,
        esi: Sequence[EsiFile] = (),
    ) -> None:
        self.eni = eni
        self.options = options
        self.esi_files = tuple(esi)
        self.chain = make_chain(eni, options, esi=self.esi_files)
        #: the ENI's slaves that an ESI device describes
        self.esi = esi_matches(eni, self.esi_files) if self.esi_files else ()
        #: the samples of a live CAN bus the gateway holds (:meth:`bridge_gateway`)
        self.live: LiveSamples | None = None

    def bridge_gateway(self) -> LiveSamples:
        """Let the chain's CAN gateway take its sensors' samples from a live CAN bus
        (``bus emulate --can``): the samples the caller's receiver feeds
        (:class:`~lolacli.devices.can.LiveSamples` of the LOLA sensors' TPDOs), held by
        the gateway's process data until the next arrives (its cycle then runs in Python,
        the others' in the C core). UsageError when the ENI has no gateway; of several,
        the first."""
        gateway = next(
            (d for d in map(device_of, self.chain.slaves) if isinstance(d, CanGateway)), None
        )
        if gateway is None:
            raise UsageError(
                "--can: the ENI has no CAN gateway (IMU, force/torque sensors) to bridge"
            )
        live = LiveSamples(CanConfig())
        gateway.bridge(live)
        self.live = live
        return live

    def status(self, stats: ServerStats) -> EmulationStatus:
        s = self.chain.stats
        elapsed = max(1e-9, (time.monotonic_ns() - stats.started_ns) / 1e9)
        return EmulationStatus(
            s.frames, s.frames / elapsed, s.logical_frames, s.dropped, s.corrupted,
            state_summary(self.chain),
        )

    def serve(
        self,
        iface: str,
        should_stop: Callable[[], bool],
        *,
        duration_s: float = 0.0,
        on_ready: Callable[[str], None] | None = None,
        on_status: Callable[[ServerStats], None] | None = None,
        realtime_priority: int | None = None,
        keep_cpus_awake: bool = True,
        cpu: int | str = "follow",
    ) -> ServerStats:
        """Serve the chain on ``iface`` until ``should_stop()`` or, when ``duration_s`` is
        over 0, that long; the arguments as :func:`serve`'s. A cable cut the options
        schedule counts from ``on_ready`` (frames are answered from then on)."""
        deadline = time.monotonic() + duration_s if duration_s > 0 else None

        def ready(scheduling: str) -> None:
            arm_link_loss(self.chain, self.options, time.monotonic_ns())  # the server's clock
            if on_ready is not None:
                on_ready(scheduling)

        def stop() -> bool:
            return should_stop() or (deadline is not None and time.monotonic() >= deadline)

        scratch = make_chain(self.eni, EmulateOptions(), esi=self.esi_files)  # to warm up
        return serve(
            iface, self.chain, stop, on_status, on_ready=ready,
            realtime_priority=realtime_priority, scratch=scratch,
            keep_cpus_awake=keep_cpus_awake, cpu=cpu,
        )
