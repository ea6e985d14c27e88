"""The ``c`` engine: the scanner kernel of ``_cscan.c`` (built at install time), called
through ctypes with the same arguments as :func:`lolacli.capture.scan.scan`.

The extension is optional: when no C compiler was available at install time it is simply
missing, :func:`c_available` says so and the Python engine runs instead (the CLI says
so on stderr, once: :func:`lolacli.capture.fast.fallback_note`).

The C code trusts the lengths it is given, so every call checks here, in Python, that
the arrays are what the kernel assumes (dtype, contiguity, sizes); a mismatch raises
instead of reading or writing out of bounds. The arrays are ``array.array("q")`` (a
small capture: no numpy import) or int64 numpy arrays; the bytes a ``bytearray``, a
mapped window (:class:`lolacli.capture.source.Mapping`) or a uint8 numpy array.
"""

from __future__ import annotations

import ctypes
import importlib.util
from array import array
from functools import lru_cache
from typing import Any

from lolacli.capture import scan as S

_I64P = ctypes.POINTER(ctypes.c_int64)


class _Tables(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_void_p)
        for name in (
            "st", "cmd_counts", "pk", "pn", "pv", "sk", "sc", "wk", "wn", "wv",
            "o_rt", "o_rtts", "o_rtfr", "o_period", "o_burst", "o_dc", "o_mbx", "o_cfg",
            "o_evict", "o_ctr", "ifs",
        )
    ] + [(name, ctypes.c_int64) for name in ("n_if", "p_len", "s_len", "w_len", "o_len")]


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL | None:
    spec = importlib.util.find_spec("lolacli.capture._cscan")
    if spec is None or spec.origin is None:
        return None
    lib = ctypes.CDLL(spec.origin)
    i64, vp = ctypes.c_int64, ctypes.c_void_p
    lib.lolacli_scan.argtypes = [vp, _I64P, i64, i64, i64, i64, i64, ctypes.POINTER(_Tables)]
    lib.lolacli_scan.restype = i64
    lib.lolacli_rehash.argtypes = [vp, vp, vp, i64, i64, vp, vp, vp, i64, i64]
    lib.lolacli_rehash.restype = i64
    lib.lolacli_finish.argtypes = [vp, vp]
    lib.lolacli_finish.restype = None
    lib.lolacli_guard.argtypes = []
    lib.lolacli_guard.restype = i64
    if lib.lolacli_guard() != 0:  # the SIGBUS guard of mapped files (lolacli_scan)
        raise OSError("the C scanner could not install its SIGBUS handler")
    return lib


def c_available() -> bool:
    """Whether the C kernel was built (``pip install`` with a C compiler) and loads with
    the functions this module expects (a stale build from an older checkout may not)."""
    try:
        return _library() is not None
    except (OSError, AttributeError):
        return False


def _ptr(a: Any, n: int | None = None) -> int:
    """The address of an int64 array (``array("q")`` or numpy) of at least ``n`` values."""
    if isinstance(a, array):
        if a.typecode != "q" or a.itemsize != 8:
            raise ValueError("scanner arrays must be writable contiguous int64")
        address, size = a.buffer_info()
    else:
        face = getattr(a, "__array_interface__", None)
        if (face is None or face["typestr"] != "<i8" or not a.flags.c_contiguous
                or not a.flags.writeable):
            raise ValueError("scanner arrays must be writable contiguous int64")
        address, size = face["data"][0], a.size
    if n is not None and size < n:
        raise ValueError(f"scanner array too short ({size} < {n})")
    return int(address)


def _bytes(buf: Any, keep: list[Any]) -> tuple[int, int]:
    """(address, size) of the bytes the scanner walks; ``keep`` holds what pins them."""
    if isinstance(buf, bytearray):
        if not buf:
            return 0, 0
        pin = (ctypes.c_char * len(buf)).from_buffer(buf)
        keep.append(pin)
        return ctypes.addressof(pin), len(buf)
    mapped = getattr(buf, "address", None)
    if mapped is not None:  # a mapped window (lolacli.capture.source.Mapping)
        return int(mapped), int(buf.size)
    face = getattr(buf, "__array_interface__", None)
    if face is None or face["typestr"] != "|u1" or not buf.flags.c_contiguous:
        raise ValueError("scanner buffer must be contiguous uint8 holding [pos, end)")
    return int(face["data"][0]), int(buf.size)


#: Open-addressing lookups end only when a table has a free slot. The pairing and stream
#: tables gain at most one key per record and are checked every CHECK_EVERY records; the
#: observation table gains up to OBS_PER_RECORD keys per record and is checked before
#: each one. A table grows once half full, so these sizes keep a free slot at all times.
MIN_KEY_SLOTS = 2 * S.CHECK_EVERY
MIN_OBS_SLOTS = 2 * S.OBS_PER_RECORD


def _pow2(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


#: st counters the kernel uses as row indices into the outputs (it bounds them above)
_ROW_COUNTERS = (S.S_N_RT, S.S_N_PERIOD, S.S_N_BURST, S.S_N_DC, S.S_N_MBX, S.S_N_CFG,
                 S.S_N_EVICT, S.S_N_CTR)


def _check_state(st: Any, pn: Any, ifs: Any, n_if: int) -> None:
    """The values the kernel indexes with or divides by, besides the array sizes: row
    counters, backward-step and malformed counts not negative, stack depths within
    DEPTH, interface rows as ts_params makes them (mode 0: a >= 0, b >= 1; mode 1:
    a >= 0; offsets bounded)."""
    if n_if < 0 or min(int(st[i]) for i in (*_ROW_COUNTERS, S.S_BACKWARDS, S.S_MALFORMED)) < 0:
        raise ValueError("scanner state: negative interface count or output row")
    if isinstance(pn, array):
        low, high = (min(pn), max(pn)) if len(pn) else (0, 0)
    else:
        low, high = (int(pn.min()), int(pn.max())) if pn.size else (0, 0)
    if low < 0 or high > S.DEPTH:
        raise ValueError("scanner state: pairing stack depth out of range")
    for j in range(0, 5 * n_if, 5):
        mode, a, b, off = (int(v) for v in ifs[j : j + 4])
        if not (((mode == 0 and b >= 1) or mode == 1) and a >= 0
                and abs(off) <= S.TS_OFFSET_LIMIT_NS):
            raise ValueError("scanner state: interface timestamp parameters out of range")


class CKernels:
    """``scan``, ``rehash`` and ``finish`` with the signatures of :mod:`scan`."""

    def __init__(self) -> None:
        lib = _library()
        if lib is None:
            raise RuntimeError("the C scanner (lolacli.capture._cscan) is not built")
        self._lib = lib
        self._pos = ctypes.c_int64(0)
        # the arrays of the last call and their checked _Tables: a scan of a large file
        # calls the kernel thousands of times with the same arrays
        self._arrays: tuple[Any, ...] = ()
        self._tables: _Tables | None = None

    def scan(
        self, buf: Any, pos: int, end: int, eof: Any, fmt: int, big: Any, ns_res: Any,
        ifs: Any, n_if: int, st: Any, cmd_counts: Any, dg: Any, pk: Any, pn: Any, pv: Any,
        sk: Any, sc: Any, wk: Any, wn: Any, wv: Any, o_rt: Any, o_rtts: Any, o_rtfr: Any,
        o_period: Any, o_burst: Any, o_dc: Any, o_mbx: Any, o_cfg: Any, o_evict: Any,
        o_ctr: Any,
    ) -> tuple[int, int]:
        keep: list[Any] = []
        address, size = _bytes(buf, keep)
        if not 0 <= pos <= end <= size:
            raise ValueError("scanner buffer must be contiguous uint8 holding [pos, end)")
        arrays = (st, cmd_counts, pk, pn, pv, sk, sc, wk, wn, wv, o_rt, o_rtts, o_rtfr,
                  o_period, o_burst, o_dc, o_mbx, o_cfg, o_evict, o_ctr, ifs)
        t = self._tables
        if t is None or t.n_if != int(n_if) or len(arrays) != len(self._arrays) or not all(
            a is b for a, b in zip(arrays, self._arrays, strict=True)
        ):
            t = self._checked(*arrays, int(n_if))
        self._arrays, self._tables = arrays, t
        _check_state(st, pn, ifs, int(n_if))
        self._pos.value = int(pos)
        status = self._lib.lolacli_scan(
            address, ctypes.byref(self._pos), int(end), int(bool(eof)), int(fmt),
            int(bool(big)), int(bool(ns_res)), ctypes.byref(t),
        )
        return int(self._pos.value), int(status)

    def _checked(
        self, st: Any, cmd_counts: Any, pk: Any, pn: Any, pv: Any, sk: Any, sc: Any, wk: Any,
        wn: Any, wv: Any, o_rt: Any, o_rtts: Any, o_rtfr: Any, o_period: Any, o_burst: Any,
        o_dc: Any, o_mbx: Any, o_cfg: Any, o_evict: Any, o_ctr: Any, ifs: Any, n_if: int,
    ) -> _Tables:
        """The kernel's table of array pointers, after checking every array's type and
        size (the arrays' sizes and places never change: a grown table is a new array)."""
        rows = len(o_rt)
        p_len, s_len, w_len = len(pk), len(sk), len(wk)
        if not (_pow2(p_len) and _pow2(s_len) and _pow2(w_len)) or rows <= S.CHECK_EVERY * (
            S.MAX_DGRAMS + 2
        ) + S.MAX_DGRAMS + 2:
            raise ValueError("scanner tables must be powers of two, outputs large enough")
        if p_len < MIN_KEY_SLOTS or s_len < MIN_KEY_SLOTS or w_len < MIN_OBS_SLOTS:
            raise ValueError("scanner tables too small to stay below half full between checks")
        t = _Tables(
            _ptr(st, S.S_SIZE), _ptr(cmd_counts, 256),
            _ptr(pk), _ptr(pn, p_len), _ptr(pv, p_len * S.DEPTH * S.PCOLS),
            _ptr(sk), _ptr(sc, s_len), _ptr(wk), _ptr(wn, w_len), _ptr(wv, w_len * S.OCOLS),
            _ptr(o_rt), _ptr(o_rtts, rows), _ptr(o_rtfr, rows), _ptr(o_period, rows),
            _ptr(o_burst, rows), _ptr(o_dc, rows), _ptr(o_mbx, rows * S.MBX_COLS),
            _ptr(o_cfg, rows * S.CFG_COLS), _ptr(o_evict, rows * S.EVICT_COLS),
            _ptr(o_ctr, rows * S.CTR_COLS),
            _ptr(ifs, 5 * int(n_if)),
            int(n_if), p_len, s_len, w_len, rows,
        )
        return t

    def rehash(
        self, ok: Any, on: Any, ov: Any, nk: Any, nn: Any, nv: Any, keep_empty: Any,
    ) -> int:
        olen, nlen = len(ok), len(nk)
        width = len(ov) // olen if olen else 0
        if not _pow2(nlen) or nlen < olen:
            raise ValueError("the new table must be a power of two, not smaller")
        return int(self._lib.lolacli_rehash(
            _ptr(ok), _ptr(on, olen), _ptr(ov, olen * width), olen, width, _ptr(nk),
            _ptr(nn, nlen), _ptr(nv, nlen * width), nlen, int(bool(keep_empty)),
        ))

    def finish(self, st: Any, o_burst: Any) -> None:
        # finish may write one burst row, at st[S_N_BURST]
        st_ptr = _ptr(st, S.S_SIZE)
        row = int(st[S.S_N_BURST])
        if row < 0:
            raise ValueError("scanner state: negative output row")
        self._lib.lolacli_finish(st_ptr, _ptr(o_burst, row + 1))
