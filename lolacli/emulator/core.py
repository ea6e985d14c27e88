"""The chain's cyclic work compiled: frame plans, DC loops, watchdogs and device cycles in C,
and the register frames of a start-up (:meth:`ChainCore.register_frame`).

The C kernel (``_ccore.c``, built at install time when a C compiler is present) runs the
work of a planned frame (:class:`~lolacli.emulator.plan.FramePlan`: its answer and the
work it defers), the process-data watchdog checks and the application cycles of the
devices, on tables made here from the chain's Python objects. The Python code (plan.py,
the esc package, the device classes) stays the reference: without the kernel, or for anything the
tables do not describe, the chain runs it; tests compare the two bit for bit.

Who holds the state. ESC memory is shared: the kernel reads and writes each slave's
bytearray in place. The rest of a slave's cyclic state is in two parts, each held either by
the Python objects or by the kernel's table for the slave: the ESC's scalars (DC clock
correction, outputs-valid flag, time of the last outputs and of the last outputs event;
the frame work needs them) and the device's state (entry values and scalars, see
:mod:`lolacli.devices.flat`; the application cycle needs it). Both sides add to the ESC's
datagram and cycle counters. The kernel takes what it needs before it runs; Python gets
it back before it touches a slave: the chain gives back the ESC part of the slaves a
general-path frame addresses, a device's part goes back when Python uses the device (its
application's ``before_use`` hook: a mailbox request, an AL state change, a cycle run in
Python), and ``Chain.slaves`` gives back everything. A device the tables cannot describe
stays in Python, and so does its cycle.

The kernel trusts its tables; they are checked once when built (``lolacli_core_check_*``
walk them as the executors do), and every time passed in is bounded here.
"""

from __future__ import annotations

import ctypes
import importlib.util
import os
import warnings
from array import array
from collections.abc import Callable, Iterable
from functools import lru_cache, partial
from typing import TYPE_CHECKING, Any

from lolacli.devices.flat import CYCLIC_BYTES, VALUE_LIMIT, DeviceScalars, FlatDevice, flatten
from lolacli.emulator.esc import system_time_loop
from lolacli.emulator.esc.counters import COUNTER_CLEAR_GROUPS
from lolacli.emulator.esc.memory import register_classes
from lolacli.emulator.plan import BrdOp, DcOp, FramePlan, LogicalOp, Pieces, finish
from lolacli.emulator.registers import AL_STATUS, MEMORY_BYTES, AlState
from lolacli.errors import UsageError

if TYPE_CHECKING:
    from lolacli.devices.base import Device
    from lolacli.emulator.esc import Esc

ABI_VERSION = 12
_I64 = ctypes.c_int64
_VP = ctypes.c_void_p
_MASK64 = (1 << 64) - 1

# program layout (see _ccore.c)
MAGIC = 0x4C4F4C41504C414E
H_MAGIC, H_FRAME_LEN, H_COUNT_K, H_COUNT_DEFERRED, H_N_COUNT = 0, 1, 2, 3, 4
H_N_WATCH, H_WATCH, H_N_ADP, H_ADP, H_N_OPS, H_OPS = 5, 6, 7, 8, 9, 10
H_WORDS = 16
OP_LOGICAL, OP_BRD, OP_DC = 1, 2, 3
PEND_FIRST_SLOT = 2  # pend[0]: work pending, pend[1]: its time
AL_OP = int(AlState.OP)


class SlaveTable(ctypes.Structure):
    """``slave_t`` of _ccore.c: one slave's cyclic state while the kernel holds it."""

    _fields_ = [
        ("owned", _I64),
        ("dev_owned", _I64),
        ("mem", _VP),
        ("clk_start", _I64),
        ("clk_drift", _I64),
        ("clk_corr", _I64),
        ("outputs_valid", _I64),
        ("last_outputs_ns", _I64),
        ("now_ns", _I64),
        ("datagrams", _I64),
        ("cycles", _I64),
        ("wd_timeout", _I64),
        ("kind", _I64),
        ("out_start", _I64),
        ("out_bytes", _I64),
        ("in_start", _I64),
        ("in_bytes", _I64),
        ("vals", _VP),
        ("vals_len", _I64),
        ("omap", _VP),
        ("omap_n", _I64),
        ("imap", _VP),
        ("imap_n", _I64),
        ("chan", _VP),
        ("chan_n", _I64),
        ("phase", _VP),
        ("aux", _VP),
        ("aux_n", _I64),
        ("dev_t_ns", _I64),
        ("power", _I64),
        ("prev_cw", _I64),
        ("last_sample", _I64),
        ("has_last", _I64),
        ("period", _I64),
        ("scale", ctypes.c_double),
        ("e", _I64 * len(CYCLIC_BYTES)),
        ("qs_option", _I64),
        ("qs_ramp", _I64),
        ("fr_ramp", _I64),
        ("rated_torque", _I64),
        ("rest", _I64),
        ("rest_n", _I64),
        ("rest_out", _VP),
        ("joint", _VP),
        ("joint_n", _I64),
    ]


WORDS = ctypes.sizeof(SlaveTable) // 8
_WORD = {f[0]: getattr(SlaveTable, f[0]).offset // 8 for f in SlaveTable._fields_}
F_OWNED, F_DEV_OWNED, F_MEM = _WORD["owned"], _WORD["dev_owned"], _WORD["mem"]
F_CLK_START, F_CLK_DRIFT, F_CLK_CORR = _WORD["clk_start"], _WORD["clk_drift"], _WORD["clk_corr"]
F_OUTPUTS_VALID, F_LAST_OUTPUTS = _WORD["outputs_valid"], _WORD["last_outputs_ns"]
F_NOW, F_DATAGRAMS, F_CYCLES = _WORD["now_ns"], _WORD["datagrams"], _WORD["cycles"]
F_WATCHDOG, F_KIND = _WORD["wd_timeout"], _WORD["kind"]
F_OUT_START, F_OUT_BYTES = _WORD["out_start"], _WORD["out_bytes"]
F_IN_START, F_IN_BYTES = _WORD["in_start"], _WORD["in_bytes"]
F_VALS, F_VALS_LEN = _WORD["vals"], _WORD["vals_len"]
F_OMAP, F_OMAP_N, F_IMAP, F_IMAP_N = _WORD["omap"], _WORD["omap_n"], _WORD["imap"], _WORD["imap_n"]
F_CHAN, F_CHAN_N, F_PHASE = _WORD["chan"], _WORD["chan_n"], _WORD["phase"]
F_AUX, F_AUX_N = _WORD["aux"], _WORD["aux_n"]
F_DEV_T, F_POWER, F_PREV_CW = _WORD["dev_t_ns"], _WORD["power"], _WORD["prev_cw"]
F_LAST_SAMPLE, F_HAS_LAST = _WORD["last_sample"], _WORD["has_last"]
F_PERIOD, F_SCALE, F_E = _WORD["period"], _WORD["scale"], _WORD["e"]
F_QS_OPTION, F_QS_RAMP, F_FR_RAMP = _WORD["qs_option"], _WORD["qs_ramp"], _WORD["fr_ramp"]
F_RATED_TORQUE, F_REST, F_REST_N = _WORD["rated_torque"], _WORD["rest"], _WORD["rest_n"]
F_REST_OUT, F_JOINT, F_JOINT_N = _WORD["rest_out"], _WORD["joint"], _WORD["joint_n"]


class PlanTable(ctypes.Structure):
    """``plan_t`` of _ccore.c."""

    _fields_ = [
        ("slaves", _VP),
        ("n_slaves", _I64),
        ("prog", _VP),
        ("prog_len", _I64),
        ("buf", _VP),
        ("buf_len", _I64),
        ("snap", _VP),
        ("snap_len", _I64),
        ("pend", _VP),
        ("pend_len", _I64),
    ]


class RegisterTable(ctypes.Structure):
    """``regs_t`` of _ccore.c: the chain's line for single-slave register frames."""

    _fields_ = [
        ("slaves", _VP),
        ("n_slaves", _I64),
        ("n_active", _I64),
        ("line", _VP),
        ("line_len", _I64),
        ("classes", _VP),
        ("classes_len", _I64),
        ("buf", _VP),
        ("buf_len", _I64),
        ("out", _VP),
        ("out_len", _I64),
        ("groups", _VP),
        ("groups_len", _I64),
        ("clocks", _I64),
    ]


# register frames (see _ccore.c): line rows, the out array, touched flags
LINE_WORDS = 8
MAX_REGISTER_DATAGRAMS = 128
T_CONFIGURATION, T_RELEASED, T_CLOCK = 1, 2, 4


def out_words(n_slaves: int) -> int:
    """The out array's length for ``n_slaves``: touched count and entries, marks, the
    datagram count and lengths, the AL control requests' count and requests, the
    addressing flag, the mailbox SM writes' count and writes."""
    return 5 + 6 * n_slaves + 4 * MAX_REGISTER_DATAGRAMS


REGISTER_FRAME_BYTES = 2048  # the largest frame the register path answers


#: the per-frame functions the module also has as its own (METH_FASTCALL): ~0.05 µs a
#: call against ~0.5 through ctypes, three calls a cycle of LOLA's cyclic frame
_MODULE_FUNCTIONS = (
    "lolacli_core_answer",
    "lolacli_core_answer_cycles",  # the module's only (CompiledPlan.answer_cycles)
    "lolacli_core_finish",
    "lolacli_core_cycles",
    "lolacli_core_watchdog",
    "lolacli_core_registers",
)


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL | None:
    spec = importlib.util.find_spec("lolacli.emulator._ccore")
    if spec is None or spec.origin is None:
        return None
    lib = load_library(spec.origin)
    if lib is not None:
        # the same shared object, imported: its per-frame functions without ctypes (the
        # same arguments; a build from before them keeps the ctypes ones)
        module = importlib.import_module("lolacli.emulator._ccore")
        for name in _MODULE_FUNCTIONS:
            function = getattr(module, name, None)
            if function is not None:
                setattr(lib, name, function)
    return lib


def load_library(path: str) -> ctypes.CDLL | None:
    """The kernel at ``path`` with its functions declared, or ``None`` when it does not
    load or does not fit this module (tests load a sanitizer build this way)."""
    try:
        lib = ctypes.CDLL(path)
        lib.lolacli_core_abi.argtypes = [_I64]
        lib.lolacli_core_abi.restype = _I64
        lib.lolacli_core_answer.argtypes = [_VP, ctypes.c_char_p, _I64, _I64]
        lib.lolacli_core_answer.restype = _I64
        lib.lolacli_core_finish.argtypes = [_VP]
        lib.lolacli_core_finish.restype = None
        lib.lolacli_core_cycles.argtypes = [_VP, _I64, _I64]
        lib.lolacli_core_cycles.restype = None
        lib.lolacli_core_watchdog.argtypes = [_VP, _I64, _I64]
        lib.lolacli_core_watchdog.restype = _I64
        lib.lolacli_core_check_slave.argtypes = [_VP]
        lib.lolacli_core_check_slave.restype = _I64
        lib.lolacli_core_check_plan.argtypes = [_VP]
        lib.lolacli_core_check_plan.restype = _I64
        lib.lolacli_core_registers.argtypes = [_VP, ctypes.c_char_p, _I64, _I64]
        lib.lolacli_core_registers.restype = _I64
        lib.lolacli_core_check_registers.argtypes = [_VP]
        lib.lolacli_core_check_registers.restype = _I64
    except (OSError, AttributeError):
        return None  # not built, or a stale build without these functions
    layout = (
        ABI_VERSION,
        ctypes.sizeof(SlaveTable),
        SlaveTable.scale.offset,
        SlaveTable.e.offset,
        ctypes.sizeof(PlanTable),
        ctypes.sizeof(RegisterTable),
        out_words(0),
    )
    if tuple(lib.lolacli_core_abi(i) for i in range(len(layout))) != layout:
        return None
    return lib


def core_available() -> bool:
    """Whether the C kernel was built (``pip install`` with a C compiler) and fits this
    module (a stale build from an older checkout does not)."""
    return _library() is not None


ENGINES = ("c", "python")
ENGINE_VARIABLE = "LOLACLI_CHAIN_ENGINE"


def chain_engine(engine: str | None = None) -> str:
    """The engine a chain runs its cyclic work with: ``engine``, else the environment's
    ``LOLACLI_CHAIN_ENGINE``, else ``c`` when the C core is built and ``python`` when not.
    UsageError for an unknown name or ``c`` without the C core."""
    chosen = engine or os.environ.get(ENGINE_VARIABLE) or ""
    if not chosen:
        if core_available():
            return "c"
        _say_fallback()
        return "python"
    if chosen not in ENGINES:
        raise UsageError(f"chain engine {chosen!r}: expected one of {', '.join(ENGINES)}")
    if chosen == "c" and not core_available():
        raise UsageError(
            "chain engine 'c': the C core (lolacli.emulator._ccore) is not built; "
            "reinstall with a C compiler, or use 'python'"
        )
    return chosen


class SlowFallbackWarning(RuntimeWarning):
    """A fast kernel is not built and its Python reference runs instead."""


FALLBACK = (
    "the emulator's C core (lolacli.emulator._ccore) is not built: the emulated chain runs "
    "its Python reference, about 5x slower (bus simulate at its defaults); reinstall with "
    "a C compiler (pip install -e .)"
)
_fallback_said = False


def _say_fallback() -> None:
    """Say once a process (stderr, as a warning) that the Python reference runs."""
    global _fallback_said
    if not _fallback_said:
        _fallback_said = True
        warnings.warn(FALLBACK, SlowFallbackWarning, stacklevel=3)


def _signed64(value: int) -> int:
    return ((value + (1 << 63)) & _MASK64) - (1 << 63)


def _address(buffer: bytearray | array[Any], keep: list[Any]) -> int:
    """The address of a buffer the kernel uses; ``keep`` keeps it alive (and a bytearray
    exported, so it cannot move; the arrays are never resized)."""
    if isinstance(buffer, array):
        keep.append(buffer)
        return int(buffer.buffer_info()[0]) if len(buffer) else 0
    if not buffer:
        return 0
    pin = (ctypes.c_char * len(buffer)).from_buffer(buffer)
    keep.append(pin)
    return ctypes.addressof(pin)


class ChainCore:
    """The kernel's tables for the slaves of one chain (all of them, in line order).

    Each slave's cyclic state is in two parts, each held either by the Python objects or
    by the slave's table: its ESC's scalars (DC clock correction, outputs-valid flag and
    time, the time of the last outputs event) and its device's state. The frame work
    needs the first, the application cycle the second; both add to the ESC's counters.
    The chain gives the ESC part back before Python processes a frame (``release``);
    the device part goes back when Python uses the device (its application's
    ``before_use`` hook: mailbox requests, AL state changes, a cycle run in Python).
    """

    def __init__(self, escs: list[Esc]) -> None:
        lib = _library()
        if lib is None:
            raise RuntimeError("the chain's C core (lolacli.emulator._ccore) is not built")
        if any(len(esc.mem) != MEMORY_BYTES for esc in escs):
            raise RuntimeError("an ESC memory is not 64 KiB")
        self.lib = lib
        self.escs = escs
        n = len(escs)
        self._words = array("q", bytes(ctypes.sizeof(SlaveTable) * max(1, n)))
        self.address = int(self._words.buffer_info()[0])
        self._doubles = memoryview(self._words).cast("B").cast("d")
        self._mem_pins = [(ctypes.c_char * MEMORY_BYTES).from_buffer(esc.mem) for esc in escs]
        for i, pin in enumerate(self._mem_pins):
            self._words[i * WORDS + F_MEM] = ctypes.addressof(pin)
        self._flat: list[FlatDevice | None] = [None] * n
        self._unflat: list[tuple[int, int] | None] = [None] * n  # od (version, writes)
        self._device_pins: list[tuple[FlatDevice | None, list[Any]]] = [(None, [])] * n
        self._watchdogs: list[tuple[int, int] | None] = [None] * n  # (epoch, timeout)
        self._starts_epoch = -1  # the epoch the held devices' SM buffer starts are for
        self.released: set[int] = set(range(n))  # ESC scalars the Esc objects hold
        self.devices_released: set[int] = set(range(n))  # devices the objects hold
        self._pieces: dict[int, list[tuple[int, int, Esc | None]]] = {}
        self.index = {id(esc): i for i, esc in enumerate(escs)}
        for i, esc in enumerate(escs):
            app = esc.app
            device = _device_of(app)
            if device is not None:
                app.before_use = partial(self.release_device, i)  # type: ignore[union-attr]
                # the device as tables now, before any master: the take-in at SAFEOP then
                # only loads them while its dictionary is unchanged (flattening a drive
                # takes ~150 µs of firmware time, which a frame arriving meanwhile waits)
                self._flat[i] = flatten(device)
                if self._flat[i] is None:
                    self._unflat[i] = (device.od.version, device.od.writes)

        self._line = array("q")
        self._classes = bytearray(register_classes())
        self._groups = array("q", [a for group in COUNTER_CLEAR_GROUPS for a in group])
        self._regs_buf = bytearray(REGISTER_FRAME_BYTES)
        self._out = array("q", bytes(8 * out_words(n)))
        self._regs_keep: list[Any] = []
        self._regs: RegisterTable | None = None
        self._regs_address = 0
        self._registers = lib.lolacli_core_registers
        # answer, finish and cycles in one call: the built module's own function, not a
        # ctypes one (a library loaded from a path has none: CompiledPlan.answer_cycles
        # then calls them one by one)
        self.answer_cycles: Callable[..., int] | None = vars(lib).get(
            "lolacli_core_answer_cycles"
        )

    # ------------------------------------------------------------ register frames
    def set_line(self, port0_ns: list[int], port1_ns: list[int | None] | None = None) -> bool:
        """The slaves the frames reach (the first ``len(port0_ns)``, each reached that long
        after the frame's start, and on the way back ``port1_ns``, ``None`` for the last
        in line: the DC receive times) for :meth:`register_frame`, with their mailbox sync
        managers and SII images as they are now (the chain sets the line again when the
        line changes or an SII image or layout is replaced: ~60 µs for LOLA). False: the
        register path is off (a value out of range)."""
        n = len(port0_ns)
        back = port1_ns if port1_ns is not None else [None] * n
        line = array("q", bytes(8 * LINE_WORDS * n))
        keep: list[Any] = []
        for i, (esc, port0, port1) in enumerate(zip(self.escs, port0_ns, back, strict=False)):
            layout = esc.layout
            row = (port0, layout.mailbox_out_sm, layout.mailbox_in_sm, esc.config.sync_managers)
            returned = -1 if port1 is None else port1
            if (
                any(
                    v.__class__ is not int or not -VALUE_LIMIT < v < VALUE_LIMIT
                    for v in (*row, returned)
                )
                or returned < -1
            ):
                self._regs = None
                return False
            sii = (_address(esc.sii, keep), len(esc.sii), int(esc.config.eeprom_8_byte_reads))
            line[LINE_WORDS * i : LINE_WORDS * (i + 1)] = array("q", (*row, *sii, returned))
        table = RegisterTable(
            slaves=self.address,
            n_slaves=len(self.escs),
            n_active=min(n, len(self.escs)),
            line=_address(line, keep),
            line_len=len(line),
            classes=_address(self._classes, keep),
            classes_len=len(self._classes),
            buf=_address(self._regs_buf, keep),
            buf_len=len(self._regs_buf),
            out=_address(self._out, keep),
            out_len=len(self._out),
            groups=_address(self._groups, keep),
            groups_len=len(self._groups),
        )
        if self.lib.lolacli_core_check_registers(ctypes.addressof(table)):
            self._regs = None
            return False
        self._line, self._regs, self._regs_keep = line, table, keep
        self._regs_address = ctypes.addressof(table)
        return True

    def register_frame(self, frame: bytes, t_ns: int) -> tuple[bytearray, tuple[int, ...]] | None:
        """A frame of APRD/FPRD/APWR/FPWR, BRD and BWR datagrams of registers whose writes
        set off nothing but the store, the FMMU/SM configuration and watchdog times (worked
        out again), the EEPROM read command, an AL control request (queued for the
        firmware), a station address or alias enable (no FPRD/FPWR after it in the frame),
        the error counters' clearing, a mailbox SM's registers (its work done here after
        the frame; no later datagram may reach the slave's SM registers) and the DC
        receive-time latch and system time (the clocks of the slaves the kernel does not
        hold given to it for the frame, their corrections taken back), answered as
        ``Chain._run_slots`` would (``Esc.read_addressed``/``write_addressed``,
        ``broadcast_read``/``broadcast_write``): the answer and the datagrams' lengths.
        ``None`` (nothing changed) for any other frame. Slaves the kernel holds stay held,
        but for those whose SM or FMMU registers were written (their watchdog time may
        change): the Esc objects work the configuration out again."""
        if self._regs is None or t_ns.__class__ is not int or not -VALUE_LIMIT < t_ns < VALUE_LIMIT:
            return None
        if frame.__class__ is not bytes:
            frame = bytes(frame)
        writes = self._registers(self._regs_address, frame, len(frame), t_ns)
        if writes == -2:  # DC registers written: the clocks of the slaves Python holds
            if not self._lend_clocks():
                return None
            self._regs.clocks = 1
            writes = self._registers(self._regs_address, frame, len(frame), t_ns)
            self._regs.clocks = 0
        if writes < 0:
            return None
        out, escs, words = self._out, self.escs, self._words
        for k in range(1, out[0] + 1):
            entry = out[k]
            i = entry >> 3
            if entry & T_RELEASED:
                escs[i].now_ns = words[i * WORDS + F_NOW]
                if entry & T_CLOCK:
                    escs[i].clock.correction_ns = words[i * WORDS + F_CLK_CORR]
            elif entry & T_CONFIGURATION:
                self.release((i,))
            if entry & T_CONFIGURATION:
                escs[i].configuration_written()
        if writes:
            escs[0].epoch[0] += writes  # as Esc.write_addressed, once a write
        at = 2 + 2 * len(escs)
        lengths = tuple(out[at : at + out[at - 1]])
        at += MAX_REGISTER_DATAGRAMS
        for k in range(at + 1, at + 1 + out[at]):  # the firmware's work, in the frame's order
            request = out[k]
            escs[request >> 8].al_control_written(request & 0xFF)
        at += 1 + 2 * len(escs) + MAX_REGISTER_DATAGRAMS
        if out[at]:
            escs[0].addressing[0] += 1  # a station address or alias enable written
        for k in range(at + 2, at + 2 + out[at + 1]):  # the mailbox SMs' work, in order
            written = out[k]
            escs[written >> 8].mailbox_sm_written(written & 0xFF)
        return self._regs_buf[: len(frame)], lengths

    def _lend_clocks(self) -> bool:
        """The DC clocks of the slaves the frames reach that the kernel does not hold, into
        their tables for one register frame (their Esc objects keep them: the kernel's
        corrections are taken back after it); False where one is out of its range."""
        w, escs, limit = self._words, self.escs, VALUE_LIMIT
        n = self._regs.n_active if self._regs is not None else 0
        for i in self.released:
            if i >= n:
                continue
            clock = escs[i].clock
            start, drift, correction = clock.start_ns, clock.drift_ppb, clock.correction_ns
            if not (
                -limit < start < limit and -limit < drift < limit and -limit < correction < limit
            ):
                return False
            b = i * WORDS
            try:  # an int of the array's range, or TypeError/OverflowError
                w[b + F_CLK_START], w[b + F_CLK_DRIFT], w[b + F_CLK_CORR] = start, drift, correction
            except (TypeError, OverflowError):
                return False
        return True

    # ------------------------------------------------------------ ownership
    def acquire(self) -> bool:
        """Take every released slave's ESC scalars into the tables; ``False`` (and all
        given back) when one cannot be held (a value beyond the kernel's arithmetic)."""
        for i in sorted(self.released):
            if not self._load_esc(i):
                self.release()
                return False
            self.released.discard(i)
        return True

    def release(self, positions: Iterable[int] | None = None) -> None:
        """Give the ESC scalars of the slaves at these 0-based positions (all: ``None``)
        back to the Esc objects, with the counts the kernel added."""
        n = len(self.escs)
        if positions is None:
            if len(self.released) == n:
                return
            positions = range(n)
        for i in positions:
            if i not in self.released and 0 <= i < n:
                self._store_esc(i)
                self.released.add(i)

    def note_times(self, n: int) -> None:
        """The first ``n`` slaves took a datagram in Python that changed nothing the
        tables hold but the time it reached them (``Esc.now_ns``): that time into the
        tables of those the kernel holds."""
        w, escs, released = self._words, self.escs, self.released
        for i in range(min(n, len(escs))):
            if i not in released:
                w[i * WORDS + F_NOW] = escs[i].now_ns

    def release_device(self, i: int) -> None:
        """Give the device at 0-based position ``i`` its state back (before Python uses it)."""
        if i not in self.devices_released:
            self._store_device(i)
            self.devices_released.add(i)
            self._pieces.clear()

    def release_owner(self, work: object) -> None:
        """Give back the ESC scalars of the slave whose firmware ``work`` (a bound method
        of its Esc) is about to run; of every slave when it is not one of theirs."""
        i = self.index.get(id(getattr(work, "__self__", None)))
        if i is None:
            self.release()
        elif i not in self.released:
            self.release((i,))

    def device_due(self, work: object, active: int) -> int | None:
        """The 0-based position of the slave whose firmware ``work`` just ran when its
        device is now to be taken in: it is in SAFEOP or OP (its PDO mapping is fixed
        there) and not yet in the tables. The take-in (:meth:`take_in_device`) then runs as
        firmware work of its own, after the answer, rather than in the first cycle that
        needs it, which may run in a frame's answer path (25 LOLA devices: 1.5 ms in
        KickCAT's first LWR, whose LRD's cycle waited for it). Only the first ``active``
        slaves (those the frames reach) run cycles."""
        i = self.index.get(id(getattr(work, "__self__", None)))
        if i is None or i >= active or i not in self.devices_released:
            return None
        if self.escs[i].al_state not in (AlState.SAFEOP, AlState.OP):
            return None
        return i

    def take_in_device(self, i: int) -> bool:
        """The device at 0-based position ``i`` into the tables, if still due; where it
        cannot be, Python keeps running it. Two pieces when its dictionary changed since it
        was flattened (a master's SDO writes at PREOP): this call flattens it again and
        returns True (call again to load it), so each piece stays short."""
        if i not in self.devices_released:
            return False
        if self.escs[i].al_state not in (AlState.SAFEOP, AlState.OP):
            return False
        device = _device_of(self.escs[i].app)
        flat = self._flat[i]
        if device is not None and (flat is None or flat.version != device.od.version):
            stamp = (device.od.version, device.od.writes)
            if self._unflat[i] != stamp:
                self._flat[i] = flatten(device)
                if self._flat[i] is None:
                    self._unflat[i] = stamp
                return True
        if self._load_device(i):
            self.devices_released.discard(i)
            self._pieces.clear()
        return False

    def release_all(self) -> None:
        """Everything back to the Python objects, counters included."""
        self.release()
        for i in range(len(self.escs)):
            self.release_device(i)
            self._flush_counters(i)

    def _load_esc(self, i: int) -> bool:
        esc, w, b = self.escs[i], self._words, i * WORDS
        clock = esc.clock
        values = (
            clock.start_ns,
            clock.drift_ppb,
            clock.correction_ns,
            esc.last_outputs_ns,
            esc.now_ns,
            self._watchdog(i),
        )
        for v in values:
            if v.__class__ is not int or not -VALUE_LIMIT < v < VALUE_LIMIT:
                return False
        (
            w[b + F_CLK_START],
            w[b + F_CLK_DRIFT],
            w[b + F_CLK_CORR],
            w[b + F_LAST_OUTPUTS],
            w[b + F_NOW],
            w[b + F_WATCHDOG],
        ) = values
        w[b + F_OUTPUTS_VALID] = 1 if esc.outputs_valid else 0
        w[b + F_OWNED] = 1
        return True

    def _store_esc(self, i: int) -> None:
        esc, w, b = self.escs[i], self._words, i * WORDS
        esc.clock.correction_ns = w[b + F_CLK_CORR]
        esc.outputs_valid = w[b + F_OUTPUTS_VALID] != 0
        esc.last_outputs_ns = w[b + F_LAST_OUTPUTS]
        esc.now_ns = w[b + F_NOW]
        w[b + F_OWNED] = 0
        self._flush_counters(i)

    def _flush_counters(self, i: int) -> None:
        w, b = self._words, i * WORDS
        datagrams, cycles = w[b + F_DATAGRAMS], w[b + F_CYCLES]
        if datagrams or cycles:
            counters = self.escs[i].counters
            counters.datagrams += datagrams
            counters.cycles += cycles
            w[b + F_DATAGRAMS] = w[b + F_CYCLES] = 0

    def _watchdog(self, i: int) -> int:
        """The process-data watchdog time check_watchdog would use (-1: none), kept per
        epoch (its registers change only with one)."""
        esc = self.escs[i]
        epoch = esc.epoch[0]
        known = self._watchdogs[i]
        if known is not None and known[0] == epoch:
            return known[1]
        timeout = esc.current_watchdog_timeout_ns()
        value = -1 if timeout is None else timeout
        self._watchdogs[i] = (epoch, value)
        return value

    def _acquire_devices(self, n: int) -> None:
        for i in sorted(self.devices_released):
            if i < n and self._load_device(i):
                self.devices_released.discard(i)
                self._pieces.clear()

    def _load_device(self, i: int) -> bool:
        """The device's tables and state into the slave's table; False: Python runs it."""
        esc, w, b = self.escs[i], self._words, i * WORDS
        device = _device_of(esc.app)
        if device is None:
            return False
        flat = self._flat[i]
        loaded = flat.load() if flat is not None else None
        if flat is None or loaded is None:
            stamp = (device.od.version, device.od.writes)
            if self._unflat[i] == stamp:
                return False  # tried with this dictionary already
            flat = self._flat[i] = flatten(device)
            loaded = flat.load() if flat is not None else None
            if flat is None or loaded is None:
                self._unflat[i] = stamp
                return False
        try:
            out_start, in_start = esc.process_data_starts()
        except (IndexError, AttributeError):
            return False
        pinned, keep = self._device_pins[i]
        if pinned is not flat:
            keep = []
            w[b + F_VALS] = _address(flat.vals, keep)
            w[b + F_OMAP] = _address(flat.out_map, keep)
            w[b + F_IMAP] = _address(flat.in_map, keep)
            w[b + F_CHAN] = _address(flat.channels, keep)
            w[b + F_PHASE] = _address(flat.phases, keep)
            w[b + F_AUX] = _address(flat.aux, keep)
            w[b + F_AUX_N] = len(flat.aux)
            w[b + F_VALS_LEN] = len(flat.vals)
            w[b + F_OMAP_N], w[b + F_IMAP_N] = len(flat.out_map) // 4, len(flat.in_map) // 4
            w[b + F_CHAN_N] = len(flat.channels) // 6
            w[b + F_PERIOD] = flat.period_ns
            self._doubles[b + F_SCALE] = flat.scale
            for k, offset in enumerate(flat.cyclic):
                w[b + F_E + k] = offset
            w[b + F_JOINT] = _address(flat.joint, keep)
            w[b + F_JOINT_N] = len(flat.joint)
            w[b + F_REST_OUT] = _address(flat.rest_out, keep)
            w[b + F_KIND] = flat.kind
            self._device_pins[i] = (flat, keep)
        w[b + F_OUT_START], w[b + F_OUT_BYTES] = out_start, flat.out_bytes
        w[b + F_IN_START], w[b + F_IN_BYTES] = in_start, flat.in_bytes
        w[b + F_DEV_T], w[b + F_POWER], w[b + F_PREV_CW] = (
            loaded.t_ns,
            loaded.power,
            loaded.previous_cw,
        )
        w[b + F_LAST_SAMPLE], w[b + F_HAS_LAST] = loaded.last_sample, int(loaded.has_last)
        w[b + F_QS_OPTION], w[b + F_QS_RAMP] = loaded.quick_stop, loaded.quick_stop_ramp
        w[b + F_FR_RAMP], w[b + F_RATED_TORQUE] = loaded.fault_ramp, loaded.rated_torque
        w[b + F_REST], w[b + F_REST_N] = loaded.rest, loaded.rest_n
        if self.lib.lolacli_core_check_slave(self.address + 8 * b):
            self._device_pins[i] = (None, [])
            return False
        w[b + F_DEV_OWNED] = 1
        return True

    def _store_device(self, i: int) -> None:
        w, b = self._words, i * WORDS
        flat = self._flat[i]
        assert flat is not None
        flat.store(
            DeviceScalars(
                w[b + F_DEV_T],
                w[b + F_POWER],
                w[b + F_PREV_CW],
                w[b + F_LAST_SAMPLE],
                w[b + F_HAS_LAST] != 0,
                rest=w[b + F_REST],
                rest_n=w[b + F_REST_N],
            )
        )
        w[b + F_DEV_OWNED] = 0

    def _refresh_starts(self) -> None:
        """Where the held devices' SM buffers start: register writes (which the ESC
        takes in Python, with a new epoch) may have moved them."""
        self._starts_epoch = self.escs[0].epoch[0]  # one cell for the chain's slaves
        w = self._words
        for i in range(len(self.escs)):
            if i in self.devices_released:
                continue
            b = i * WORDS
            try:
                w[b + F_OUT_START], w[b + F_IN_START] = self.escs[i].process_data_starts()
            except (IndexError, AttributeError):
                self.release_device(i)
                continue
            if self.lib.lolacli_core_check_slave(self.address + 8 * b):
                self.release_device(i)

    def held_devices(self) -> list[int]:
        """Positions whose device cycle runs in the kernel now (for tests and reports)."""
        return [i for i in range(len(self.escs)) if i not in self.devices_released]

    # ------------------------------------------------------------- the work
    def cycles(
        self,
        n: int,
        t_ns: int,
        start: int = 0,
        should_yield: Callable[[], bool] | None = None,
    ) -> int | None:
        """The application cycle of the slaves at positions ``start``..``n - 1`` at
        ``t_ns`` (``Esc.cycle``): in the kernel for the devices it can hold, a run of
        consecutive ones in one call, in Python for the others. ``should_yield`` is asked
        after each run and each Python slave but the last; when it says yes, the position
        to go on from (the rest has not run), else ``None``."""
        escs = self.escs
        if t_ns.__class__ is not int or not -VALUE_LIMIT < t_ns < VALUE_LIMIT:
            for i in range(n):
                self.release_device(i)
            for i in range(start, n):
                escs[i].cycle(t_ns)
                if should_yield is not None and i < n - 1 and should_yield():
                    return i + 1
            return None
        if escs and escs[0].epoch[0] != self._starts_epoch:
            self._refresh_starts()
        if self.devices_released:
            self._acquire_devices(n)
        pieces = self._pieces.get(n)
        if pieces is None:
            pieces = self._pieces[n] = self._cycle_pieces(n)
        for lo, hi, esc in pieces:
            if hi <= start:
                continue
            if esc is None:
                lo = max(lo, start)
                self.lib.lolacli_core_cycles(self.address + 8 * WORDS * lo, hi - lo, t_ns)
            else:
                esc.cycle(t_ns)
            if should_yield is not None and hi < n and should_yield():
                return hi
        return None

    def cycles_in_one_call(self, n: int) -> bool:
        """Whether :meth:`cycles` of the first ``n`` slaves from position 0 is one kernel
        call and nothing else now: every device held, the SM buffer starts up to date and
        their pieces worked out (by an earlier call) as one run."""
        if self.devices_released or (self.escs and self.escs[0].epoch[0] != self._starts_epoch):
            return False
        pieces = self._pieces.get(n)
        return pieces is not None and len(pieces) == 1 and pieces[0] == (0, n, None)

    def _cycle_pieces(self, n: int) -> list[tuple[int, int, Esc | None]]:
        """Positions 0..n-1 in line order as (first, end, None) for a run of devices the
        kernel holds and (i, i + 1, esc) for a slave Python cycles."""
        pieces: list[tuple[int, int, Esc | None]] = []
        released = self.devices_released
        for i, esc in enumerate(self.escs[:n]):
            if i in released:
                pieces.append((i, i + 1, esc))
            elif pieces and pieces[-1][2] is None and pieces[-1][1] == i:
                pieces[-1] = (pieces[-1][0], i + 1, None)
            else:
                pieces.append((i, i + 1, None))
        return pieces

    def check_watchdogs(self, n: int, t_ns: int) -> None:
        """``Esc.check_watchdog`` of the first ``n`` slaves; the kernel looks at those whose
        scalars it holds, and when one would expire all go back to Python, which runs the
        checks."""
        if len(self.released) == len(self.escs):  # nothing held: Python's own checks
            for esc in self.escs[:n]:
                if esc.mem[AL_STATUS] == AL_OP:  # only a slave in OP has one to run out
                    esc.check_watchdog(t_ns)
            return
        if (
            t_ns.__class__ is int
            and -VALUE_LIMIT < t_ns < VALUE_LIMIT
            and self.lib.lolacli_core_watchdog(self.address, n, t_ns) < 0
        ):
            for i in sorted(self.released):
                if i < n:
                    self.escs[i].check_watchdog(t_ns)
            return
        self.release()
        for esc in self.escs[:n]:
            esc.check_watchdog(t_ns)

    def compile(self, plan: FramePlan) -> CompiledPlan | None:
        """The plan as a kernel program, or ``None`` when the kernel does not run it (the
        chain runs ``plan.run``)."""
        return finish(self.compile_pieces(plan))  # type: ignore[no-any-return]

    def compile_pieces(self, plan: FramePlan) -> Pieces:
        """:meth:`compile` in pieces (a slave's part of a logical datagram each), as
        :func:`~lolacli.emulator.plan.plan_pieces`; it returns what :meth:`compile` does."""
        compiled = CompiledPlan.__new__(CompiledPlan)
        try:
            yield from compiled.make_pieces(self, plan)
        except _NotCompiled:
            return None
        return compiled


def _device_of(app: object) -> Device | None:
    """The device behind a stock SlaveApplication (other applications run in Python)."""
    from lolacli.emulator.slave import SlaveApplication

    if type(app) is not SlaveApplication:
        return None
    return app.device


class _NotCompiled(Exception):
    """The kernel does not run this plan."""


class CompiledPlan:
    """One FramePlan as a kernel program with its buffers."""

    def __init__(self, core: ChainCore, plan: FramePlan) -> None:
        finish(self.make_pieces(core, plan))

    def make_pieces(self, core: ChainCore, plan: FramePlan) -> Pieces:
        self.core = core
        self.plan = plan
        self.lib = core.lib
        self._snap_len = 0
        self._pend_len = PEND_FIRST_SLOT
        self._slots: list[tuple[int, list[int]]] = []  # per op: snapshot offset, DC slots
        program = yield from self._program(plan)
        self.buf = bytearray(len(plan.buf))
        self.snap = bytearray(self._snap_len)
        self.pend = array("q", bytes(8 * self._pend_len))
        self._keep: list[Any] = []
        self.table = PlanTable(
            slaves=core.address,
            n_slaves=len(core.escs),
            prog=_address(program, self._keep),
            prog_len=len(program),
            buf=_address(self.buf, self._keep),
            buf_len=len(self.buf),
            snap=_address(self.snap, self._keep),
            snap_len=len(self.snap),
            pend=_address(self.pend, self._keep),
            pend_len=len(self.pend),
        )
        self.address = ctypes.addressof(self.table)
        if self.lib.lolacli_core_check_plan(self.address):
            raise _NotCompiled
        self.item = (self.finish, ())
        self._answer = self.lib.lolacli_core_answer

    # ------------------------------------------------------------- running
    def answer(self, frame: bytes, t_ns: int, deferred: list[Any]) -> tuple[bytes, bool] | None:
        """``FramePlan.run`` in the kernel: the returned frame, and whether a slave's
        watchdog would expire now (the chain then runs the checks in Python). Work for
        after the answer goes into ``deferred`` as the Python plan's does. ``None``: the
        kernel cannot take this one (time out of range, a slave it cannot hold)."""
        if t_ns.__class__ is not int or not -VALUE_LIMIT < t_ns < VALUE_LIMIT:
            return None
        if self.core.released and not self.core.acquire():
            return None
        pend = self.pend
        if pend[0]:
            self.finish()  # the chain runs deferred work before the next frame: not reached
        if frame.__class__ is not bytes:
            frame = bytes(frame)
        code = self._answer(self.address, frame, len(frame), t_ns)
        if code < 0:
            return None
        if pend[0]:
            deferred.append(self.item)
        return bytes(self.buf), code == 1

    def answer_cycles(
        self, frame: bytes, t_ns: int, deferred: list[Any], n: int
    ) -> tuple[tuple[bytes, bool] | None, bool]:
        """:meth:`answer`, and when no watchdog expires the work it left (:meth:`finish`)
        and :meth:`ChainCore.cycles` of the first ``n`` slaves at ``t_ns`` in the same
        kernel call, when that call is all they would do (the chain's logical frame with
        nothing else waiting: its run_deferred_cycles). What :meth:`answer` returns and
        whether the work and the cycle ran; when not, the chain goes on as after
        :meth:`answer` (a watchdog expired, or the kernel did not take the frame)."""
        core = self.core
        fused = core.answer_cycles
        if (
            fused is None
            or core.released
            or self.pend[0]
            or frame.__class__ is not bytes
            or t_ns.__class__ is not int
            or not -VALUE_LIMIT < t_ns < VALUE_LIMIT
            or not core.cycles_in_one_call(n)
        ):
            return self.answer(frame, t_ns, deferred), False
        code = fused(self.address, frame, len(frame), t_ns, n)
        if code < 0:
            return None, False  # as answer: nothing ran
        if code == 1:  # a watchdog expires: the chain runs the checks, then the rest
            if self.pend[0]:
                deferred.append(self.item)
            return (bytes(self.buf), True), False
        return (bytes(self.buf), False), True

    def finish(self) -> None:
        """The work the last answer left (datagram counters, writes with their outputs
        events, DC time loops), in the plan's order."""
        if not self.pend[0]:
            return
        if not self.core.released or self.core.acquire():
            self.lib.lolacli_core_finish(self.address)
        else:
            self._finish_in_python()

    def _finish_in_python(self) -> None:
        """The same work through the Python plan (a slave the kernel could not take)."""
        t_ns, plan = self.pend[1], self.plan
        self.pend[0] = 0
        if plan.deferred is not None:
            plan.count()
        for op, (snap_at, slots) in zip(plan.ops, self._slots, strict=True):
            if isinstance(op, LogicalOp) and op.deferred is not None:
                op.snapshot[:] = self.snap[snap_at : snap_at + len(op.snapshot)]
                op.write_later(t_ns)
            elif isinstance(op, DcOp) and op.deferred is not None:
                for (_reference, _port0, others), slot in zip(op.segments, slots, strict=True):
                    if others:
                        value = self.pend[slot] & _MASK64
                        system_time_loop(others, value, 8 * op.length, t_ns)

    # ------------------------------------------------------------- compiling
    def _program(self, plan: FramePlan) -> Pieces:
        index = self.core.index
        prog = array("q", bytes(8 * H_WORDS))
        prog[H_MAGIC] = MAGIC
        prog[H_FRAME_LEN] = len(plan.buf)
        prog[H_COUNT_K] = plan.datagrams_per_slave
        prog[H_COUNT_DEFERRED] = 1 if plan.deferred is not None else 0
        counted = [index.get(id(esc), -1) for esc in plan.escs]
        if counted != list(range(len(counted))):
            raise _NotCompiled  # the plan's slaves are not the line's first ones
        prog[H_N_COUNT] = len(counted)
        prog[H_WATCH], prog[H_N_WATCH] = len(prog), len(plan.watchdog_slaves)
        prog.extend(index[id(esc)] for esc in plan.watchdog_slaves)
        prog[H_ADP], prog[H_N_ADP] = len(prog), len(plan.adp_fixes)
        for at, adp in plan.adp_fixes:
            prog.extend((at, adp))
        prog[H_OPS], prog[H_N_OPS] = len(prog), len(plan.ops)
        for op in plan.ops:
            yield
            if isinstance(op, LogicalOp):
                record = yield from self._logical(op)
            elif isinstance(op, BrdOp):
                record = self._brd(op, counted)
            elif isinstance(op, DcOp):
                record = self._dc(op)
            else:
                raise _NotCompiled
            prog.extend(record)
        return prog

    def _logical(self, op: LogicalOp) -> Pieces:
        if op.ordered or any(esc.pending_op for esc, _, _ in op.events):
            raise _NotCompiled  # slave-major order, or an outputs event that enters OP
        index = self.core.index
        writes: list[int] = []
        reads: list[int] = []
        for step in op.steps:
            yield
            i = index[id(step.esc)]
            for (_t, _s, a, b), (p, _q) in zip(step.writes or (), step.write_memory, strict=True):
                writes += (i, p, a, b - a)
            for (_t, _s, a, b), (p, _q) in zip(step.reads or (), step.read_memory, strict=True):
                reads += (i, p, a, b - a)
        events = [v for esc, port0, _n in op.events for v in (index[id(esc)], port0)]
        length = len(op.data)
        snap_at = -1
        if op.deferred is not None:
            snap_at, self._snap_len = self._snap_len, self._snap_len + length
        self._slots.append((snap_at, []))
        head = [OP_LOGICAL, 0, op.wkc_offset - length, length, op.wkc_offset, op.fixed_wkc]
        head += [1 if op.deferred is not None else 0, max(snap_at, 0)]
        head += [len(writes) // 4, len(reads) // 4, len(events) // 2]
        record = head + writes + reads + events
        record[1] = len(record)
        return record

    def _brd(self, op: BrdOp, slaves: list[int]) -> list[int]:
        cache_at, self._snap_len = self._snap_len, self._snap_len + op.length
        flag = 0
        if op.epoch_cell is not None:
            flag, self._pend_len = self._pend_len, self._pend_len + 1
        self._slots.append((cache_at, []))
        record = [OP_BRD, 0, op.wkc_offset - op.length, op.length, op.wkc_offset, op.lo]
        record += [len(slaves), 1 if flag else 0, cache_at, flag, *slaves]
        record[1] = len(record)
        return record

    def _dc(self, op: DcOp) -> list[int]:
        index = self.core.index
        by_mem = {id(esc.mem): i for i, esc in enumerate(self.core.escs)}
        segments: list[int] = []
        others: list[int] = []
        slots: list[int] = []
        for reference, port0_ns, members in op.segments:
            slot = 0
            if members:
                slot, self._pend_len = self._pend_len, self._pend_len + 1
            slots.append(slot)
            ref = -1 if reference is None else index[id(reference)]
            segments += (ref, port0_ns if reference is not None else 0, len(members), slot)
            for mem, clock, offset_ns, registers_ns in members:
                i = by_mem[id(mem)]
                if self.core.escs[i].clock is not clock:
                    raise _NotCompiled
                others += (i, offset_ns, _signed64(registers_ns))
        self._slots.append((-1, slots))
        record = [OP_DC, 0, op.wkc_offset - op.length, op.length, op.wkc_offset, op.count]
        record += [1 if op.deferred is not None else 0, len(op.segments), *segments, *others]
        record[1] = len(record)
        return record


__all__ = [
    "ENGINES",
    "ENGINE_VARIABLE",
    "ChainCore",
    "CompiledPlan",
    "chain_engine",
    "core_available",
]
