"""The capture scanner: walks pcap/pcapng records in a byte buffer and analyses each
EtherCAT frame in one pass (pure; no IO).

This module is written in the small subset of Python that numba compiles: integers,
indexing, loops, no objects. :mod:`lolacli.capture.fast` compiles it with ``numba.njit``;
without numba the very same functions run as plain Python (slower, same results).

Everything lives in flat integer arrays (lists in plain-Python mode):

* ``st`` — counters and running state, indexed by the ``S_*`` constants below;
* ``cmd_counts[256]`` — datagrams per command byte;
* the pairing table ``pk/pn/pts/pmeta`` (open addressing, key = 63-bit hash of the
  frame's (command, index, address key) sequence, a stack of ``DEPTH`` pending outgoing
  timestamps per key: a return pops the most recent one, DESIGN.md "Pairing");
* the stream table ``sk/sc`` (outgoing frames per (command, address key) signature), used
  to pick the cyclic stream when there is no logical traffic;
* the WKC table ``wk/wv`` (expected WKC per cyclic datagram key: the ENI's ``<Cnt>``, or
  the first WKC seen);
* output rows ``o_*`` that the driver drains whenever :data:`ST_FLUSH` is returned.

Address key: auto-increment and broadcast commands have their ADP incremented by every
slave, so only ADO identifies them; configured-address and logical commands keep the
full 32-bit address.
"""

from __future__ import annotations

from typing import Any

# --- st indices -------------------------------------------------------------------------
S_FRAMES = 0
S_ECAT = 1
S_NONECAT = 2
S_MALFORMED = 3
S_DGRAMS = 4
S_OUT = 5
S_RET = 6
S_PAIRS = 7
S_UNMATCHED_RET = 8
S_CYC_N = 9
S_CYC_MATCHED = 10
S_LOST = 11
S_CYC_LAST_TS = 12
S_WKC_MISMATCH = 13
S_WKC_CHECKED = 14
S_DC_DGRAMS = 15
S_DC_BURST = 16
S_DC_LAST_TS = 17
S_N_RT = 18
S_N_PERIOD = 19
S_N_BURST = 20
S_N_DC = 21
S_N_MBX = 22
S_P_USED = 23
S_S_USED = 24
S_W_USED = 25
S_LAST_TS = 26
S_MODE = 27
S_STREAM_SIG = 28
S_WKC_FIXED = 29
S_NON_ETH = 30
S_ECAT_OTHER = 31
S_FIRST_TS = 32
S_END_TS = 33
S_UDP = 34
S_VLAN = 35
S_CUT = 36
S_LOGICAL_OUT = 37
S_SKIPPED = 38
S_N_WKCBAD = 39
S_TS_SEEN = 40
S_SIZE = 48

# --- kernel return codes -----------------------------------------------------------------
ST_NEED_MORE = 0
ST_FLUSH = 1
ST_BLOCK = 2
ST_GROW = 3
ST_CORRUPT = 4
ST_DONE = 5

MODE_LOGICAL = 0
MODE_SIGNATURE = 1

DEPTH = 16
MAX_DGRAMS = 128
CHECK_EVERY = 64
MBX_COLS = 8
WKC_COLS = 5
MAX_RECORD = 16 * 1024 * 1024
BURST_GAP_NS = 1_000_000
#: The 64-bit FNV prime, FNV_HI << 32 | FNV_LO (see _mix)
FNV_HI = 0x100
FNV_LO = 0x1B3
SEED_PAIR = 0x2545F4914F6CDD1D
SEED_STREAM = 0x1B873593
SEED_WKC = 0x5BD1E995

#: Timestamps are int64 nanoseconds: a pcapng packet whose raw timestamp has the top bit
#: set, or converts beyond TS_LIMIT_NS (year 2116), is malformed; interface offsets
#: (``if_tsoffset``) are limited to ±TS_OFFSET_LIMIT_NS (36 years). Differences of two
#: timestamps then fit in int64 as well.
TS_LIMIT_NS = 1 << 62
TS_OFFSET_LIMIT_NS = 1 << 60
TS_BAD = -(1 << 62)

REG_DC_SYSTIME = 0x0910
REG_DC_SYSTIME_DIFF = 0x092C
MBX_AREA = 0x1000


def _byte(buf: Any, p: Any) -> Any:
    return buf[p]


def _u16(buf: Any, p: Any, big: Any) -> Any:
    if big:
        return (_byte(buf, p) << 8) | _byte(buf, p + 1)
    return _byte(buf, p) | (_byte(buf, p + 1) << 8)


def _u32(buf: Any, p: Any, big: Any) -> Any:
    if big:
        return (_u16(buf, p, True) << 16) | _u16(buf, p + 2, True)
    return _u16(buf, p, False) | (_u16(buf, p + 2, False) << 16)


def _mix(h: Any, v: Any) -> Any:
    """``(h ^ v) * FNV mod 2^63``, then a shift-xor; ``h`` and ``v`` in [0, 2^63).

    The product is built from 32-bit halves so that no intermediate leaves int64: numba
    (LLVM) takes signed overflow to be impossible, and dropped the 63-bit mask that once
    followed a plain wrapping multiply (its keys then differed from Python's and C's)."""
    x = h ^ v
    lo = x & 0xFFFFFFFF
    low = lo * FNV_LO                                     # < 2^41
    mid = ((x >> 32) * FNV_LO + lo * FNV_HI + (low >> 32)) & 0x7FFFFFFF
    h = (mid << 32) | (low & 0xFFFFFFFF)
    return h ^ (h >> 29)


def _key(h: Any) -> Any:
    return h if h != 0 else 1


def _slot(keys: Any, key: Any) -> Any:
    mask = len(keys) - 1
    i = (key ^ (key >> 21)) & mask
    while keys[i] != key and keys[i] != 0:
        i = (i + 1) & mask
    return i


def _addr_key(cmd: Any, addr: Any) -> Any:
    # APRD APWR APRW ARMW BRD BWR BRW: ADP is incremented by every slave.
    if cmd == 1 or cmd == 2 or cmd == 3 or cmd == 13 or cmd == 7 or cmd == 8 or cmd == 9:
        return addr & 0xFFFF0000
    return addr


def _ts_ns(units: Any, mode: Any, a: Any, b: Any, off: Any) -> Any:
    """Nanoseconds of raw pcapng units (``units`` < 2^63), or :data:`TS_BAD` beyond
    :data:`TS_LIMIT_NS`. Every intermediate value fits in int64 (numba, C)."""
    if mode == 0:
        if a > 0 and units > TS_LIMIT_NS // a:
            return TS_BAD
        if b == 1:
            return units * a + off
        return units * a // b + off
    if a >= 63:
        sec = 0
        frac = units
    else:
        sec = units >> a
        frac = units & ((1 << a) - 1)
    if sec > TS_LIMIT_NS // 1000000000:
        return TS_BAD
    if a > 30:
        frac = 0 if a - 30 >= 63 else frac >> (a - 30)
        return sec * 1000000000 + ((frac * 1000000000) >> 30) + off
    return sec * 1000000000 + ((frac * 1000000000) >> a) + off


def _push(pk: Any, pn: Any, pts: Any, pmeta: Any, st: Any, key: Any, ts: Any, meta: Any) -> Any:
    i = _slot(pk, key)
    if pk[i] == 0:
        pk[i] = key
        st[S_P_USED] += 1
    n = pn[i]
    base = i * DEPTH
    if n == DEPTH:
        for j in range(DEPTH - 1):
            pts[base + j] = pts[base + j + 1]
            pmeta[base + j] = pmeta[base + j + 1]
        n = DEPTH - 1
    pts[base + n] = ts
    pmeta[base + n] = meta
    pn[i] = n + 1


def _count_stream(sk: Any, sc: Any, st: Any, key: Any) -> Any:
    i = _slot(sk, key)
    if sk[i] == 0:
        sk[i] = key
        st[S_S_USED] += 1
    sc[i] += 1


def _check_wkc(
    buf: Any, q: Any, cmd: Any, akey: Any, ln: Any, wkc: Any, wk: Any, wv: Any, st: Any,
    o_wkc: Any,
) -> Any:
    wkey = _key(_mix(_mix(_mix(SEED_WKC, cmd), akey), ln))
    wslot = _slot(wk, wkey)
    wknown = wk[wslot] != 0
    if not wknown and st[S_WKC_FIXED] == 0:
        wk[wslot] = wkey
        wv[wslot] = wkc
        st[S_W_USED] += 1
        wknown = True
    if wknown:
        st[S_WKC_CHECKED] += 1
        if wv[wslot] != wkc:
            st[S_WKC_MISMATCH] += 1
            wrow = st[S_N_WKCBAD] * WKC_COLS
            o_wkc[wrow] = st[S_FRAMES]
            o_wkc[wrow + 1] = cmd
            o_wkc[wrow + 2] = _u32(buf, q + 2, False)
            o_wkc[wrow + 3] = wv[wslot]
            o_wkc[wrow + 4] = wkc
            st[S_N_WKCBAD] += 1


def _returned_extras(
    buf: Any, q: Any, cmd: Any, ado: Any, ln: Any, wkc: Any, ts: Any, st: Any, o_dc: Any,
    o_mbx: Any,
) -> Any:
    # Reads of the DC system-time difference (0x092C): sign-and-magnitude nanoseconds.
    if (cmd == 1 or cmd == 4) and wkc >= 1 and ado <= REG_DC_SYSTIME_DIFF:
        if ado + ln >= REG_DC_SYSTIME_DIFF + 4:
            v = _u32(buf, q + 10 + REG_DC_SYSTIME_DIFF - ado, False)
            mag = v & 0x7FFFFFFF
            o_dc[st[S_N_DC]] = -mag if v & 0x80000000 else mag
            st[S_N_DC] += 1
    # Mailbox candidates: a physical read/write in the process-memory area whose data
    # starts with a plausible mailbox header (ETG.1000.4 Table 29).
    if (cmd == 1 or cmd == 2 or cmd == 4 or cmd == 5) and wkc >= 1 and ado >= MBX_AREA:
        if ln >= 8:
            mlen = _u16(buf, q + 10, False)
            mtype = _byte(buf, q + 15) & 0x0F
            if mlen >= 2 and mlen + 6 <= ln and (mtype <= 5 or mtype == 15):
                r = st[S_N_MBX] * MBX_COLS
                o_mbx[r] = st[S_FRAMES]
                o_mbx[r + 1] = ts
                o_mbx[r + 2] = q
                o_mbx[r + 3] = cmd
                o_mbx[r + 4] = _u32(buf, q + 2, False)
                o_mbx[r + 5] = ln
                o_mbx[r + 6] = wkc
                o_mbx[r + 7] = _u16(buf, q + 8, False)
                st[S_N_MBX] += 1


def _drift(ts: Any, st: Any, o_burst: Any) -> Any:
    st[S_DC_DGRAMS] += 1
    if st[S_DC_BURST] > 0 and ts - st[S_DC_LAST_TS] > BURST_GAP_NS:
        o_burst[st[S_N_BURST]] = st[S_DC_BURST]
        st[S_N_BURST] += 1
        st[S_DC_BURST] = 0
    st[S_DC_BURST] += 1
    st[S_DC_LAST_TS] = ts


def _ecat(
    buf: Any, p: Any, limit: Any, ret: Any, ts: Any, st: Any, cmd_counts: Any, dg: Any,
    pk: Any, pn: Any, pts: Any, pmeta: Any, sk: Any, sc: Any, wk: Any, wv: Any, o_rt: Any,
    o_rtts: Any, o_rtcyc: Any, o_period: Any, o_burst: Any, o_dc: Any, o_mbx: Any, o_wkc: Any,
) -> Any:
    """One EtherCAT payload at ``p`` (captured bytes end at ``limit``).

    Returns False when the datagrams do not fit (a malformed frame).
    """
    if p + 2 > limit:
        return False
    word = _u16(buf, p, False)
    if (word >> 12) != 1:
        # An EtherCAT header of another type (network variables, mailbox gateway…):
        # no datagrams, counted with the non-EtherCAT-command traffic.
        st[S_NONECAT] += 1
        st[S_ECAT_OTHER] += 1
        return True
    q = p + 2
    n = 0
    while True:
        if n == MAX_DGRAMS or q + 12 > limit:
            return False
        lw = _u16(buf, q + 6, False)
        ln = lw & 0x7FF
        if q + 12 + ln > limit:
            return False
        dg[n] = q
        n += 1
        q += 12 + ln
        if (lw & 0x8000) == 0:
            break
    st[S_ECAT] += 1
    st[S_DGRAMS] += n
    hp = SEED_PAIR
    hs = SEED_STREAM
    logical = False
    for j in range(n):
        q = dg[j]
        cmd = _byte(buf, q)
        akey = _addr_key(cmd, _u32(buf, q + 2, False))
        cmd_counts[cmd] += 1
        hp = _mix(_mix(hp, (cmd << 8) | _byte(buf, q + 1)), akey)
        hs = _mix(_mix(hs, cmd), akey)
        if cmd == 10 or cmd == 11 or cmd == 12:
            logical = True
    hp = _key(hp)
    hs = _key(hs)
    if st[S_MODE] == MODE_LOGICAL:
        cyc = logical
    else:
        cyc = hs == st[S_STREAM_SIG]
    if ret == 0:
        st[S_OUT] += 1
        if logical:
            st[S_LOGICAL_OUT] += 1
        elif st[S_LOGICAL_OUT] == 0:
            # only needed to pick the cyclic stream of a capture without logical traffic
            _count_stream(sk, sc, st, hs)
        meta = 0
        if cyc:
            if st[S_CYC_N] > 0:
                if st[S_CYC_MATCHED] == 0:
                    st[S_LOST] += 1
                o_period[st[S_N_PERIOD]] = ts - st[S_CYC_LAST_TS]
                st[S_N_PERIOD] += 1
            st[S_CYC_N] += 1
            st[S_CYC_MATCHED] = 0
            st[S_CYC_LAST_TS] = ts
            meta = st[S_CYC_N]
        _push(pk, pn, pts, pmeta, st, hp, ts, meta)
        for j in range(n):
            q = dg[j]
            cmd = _byte(buf, q)
            if (cmd == 13 or cmd == 14) and _u16(buf, q + 4, False) == REG_DC_SYSTIME:
                _drift(ts, st, o_burst)
        return True
    st[S_RET] += 1
    i = _slot(pk, hp)
    if pk[i] != 0 and pn[i] > 0:
        top = pn[i] - 1
        pn[i] = top
        meta = pmeta[i * DEPTH + top]
        r = st[S_N_RT]
        o_rt[r] = ts - pts[i * DEPTH + top]
        o_rtts[r] = ts
        o_rtcyc[r] = 1 if meta > 0 else 0
        st[S_N_RT] = r + 1
        st[S_PAIRS] += 1
        if meta > 0 and meta == st[S_CYC_N]:
            st[S_CYC_MATCHED] = 1
    else:
        st[S_UNMATCHED_RET] += 1
    for j in range(n):
        q = dg[j]
        cmd = _byte(buf, q)
        ado = _u16(buf, q + 4, False)
        ln = _u16(buf, q + 6, False) & 0x7FF
        wkc = _u16(buf, q + 10 + ln, False)
        if cyc:
            akey = _addr_key(cmd, _u32(buf, q + 2, False))
            _check_wkc(buf, q, cmd, akey, ln, wkc, wk, wv, st, o_wkc)
        _returned_extras(buf, q, cmd, ado, ln, wkc, ts, st, o_dc, o_mbx)
    return True


def _packet(
    buf: Any, d: Any, cap: Any, orig: Any, ts: Any, st: Any, cmd_counts: Any, dg: Any, pk: Any,
    pn: Any, pts: Any, pmeta: Any, sk: Any, sc: Any, wk: Any, wv: Any, o_rt: Any, o_rtts: Any,
    o_rtcyc: Any, o_period: Any, o_burst: Any, o_dc: Any, o_mbx: Any, o_wkc: Any,
) -> Any:
    """One Ethernet frame of ``cap`` captured bytes at ``d``."""
    st[S_FRAMES] += 1
    # not S_FRAMES == 1: packets skipped in _pcapng_record are counted without a time
    if st[S_TS_SEEN] == 0:
        st[S_TS_SEEN] = 1
        st[S_FIRST_TS] = ts
    st[S_END_TS] = ts
    st[S_LAST_TS] = ts
    if cap < 14:
        st[S_MALFORMED] += 1
        return
    limit = d + cap
    etype = _u16(buf, d + 12, True)
    p = d + 14
    if etype == 0x8100:
        if cap < 18:
            st[S_MALFORMED] += 1
            return
        etype = _u16(buf, d + 16, True)
        p = d + 18
        st[S_VLAN] += 1
    if etype == 0x0800:
        # EtherCAT over UDP (ETG.1000.4 §5.3.2): IPv4, protocol 17, port 0x88A4.
        if p + 20 > limit or (_byte(buf, p) >> 4) != 4 or _byte(buf, p + 9) != 17:
            st[S_NONECAT] += 1
            return
        ihl = (_byte(buf, p) & 0x0F) * 4
        if (_u16(buf, p + 6, True) & 0x1FFF) != 0 or p + ihl + 8 > limit:
            st[S_NONECAT] += 1
            return
        if _u16(buf, p + ihl + 2, True) != 0x88A4:
            st[S_NONECAT] += 1
            return
        p = p + ihl + 8
        st[S_UDP] += 1
    elif etype != 0x88A4:
        st[S_NONECAT] += 1
        return
    ret = _byte(buf, d + 6) & 0x02
    ok = _ecat(buf, p, limit, ret, ts, st, cmd_counts, dg, pk, pn, pts, pmeta, sk, sc, wk, wv,
               o_rt, o_rtts, o_rtcyc, o_period, o_burst, o_dc, o_mbx, o_wkc)
    if not ok:
        st[S_MALFORMED] += 1
    elif cap < orig:
        st[S_CUT] += 1


def _full(st: Any, cap: Any, pk: Any, sk: Any, wk: Any) -> Any:
    """ST_FLUSH / ST_GROW / -1: whether the driver must act before the next record."""
    lim = cap - MAX_DGRAMS - 2
    if (st[S_N_RT] >= lim or st[S_N_PERIOD] >= lim or st[S_N_BURST] >= lim
            or st[S_N_DC] >= lim or st[S_N_MBX] >= lim or st[S_N_WKCBAD] >= lim):
        return ST_FLUSH
    if st[S_P_USED] * 2 > len(pk) or st[S_S_USED] * 2 > len(sk) or st[S_W_USED] * 2 > len(wk):
        return ST_GROW
    return -1


def scan(
    buf: Any, pos: Any, end: Any, eof: Any, fmt: Any, big: Any, ns_res: Any, ifs: Any,
    n_if: Any, st: Any, cmd_counts: Any, dg: Any, pk: Any, pn: Any, pts: Any, pmeta: Any,
    sk: Any, sc: Any, wk: Any, wv: Any, o_rt: Any, o_rtts: Any, o_rtcyc: Any, o_period: Any,
    o_burst: Any, o_dc: Any, o_mbx: Any, o_wkc: Any,
) -> Any:
    """Walk records from ``pos`` until the buffer ends or the driver must act.

    ``fmt`` 0 = classic pcap (``ns_res`` 1 for nanosecond files), 1 = pcapng. ``ifs`` holds
    5 integers per pcapng interface: ts mode, a, b, offset_ns, is_ethernet.
    Returns ``(pos, status)``.
    """
    # outputs and tables are checked every CHECK_EVERY records: leave room for that many.
    # The WKC table is checked before every record: one record may add MAX_DGRAMS keys,
    # and a full open-addressing table would make _slot loop forever.
    cap = len(o_rt) - CHECK_EVERY * (MAX_DGRAMS + 2)
    count = 0
    while True:
        count += 1
        if count % CHECK_EVERY == 1 or st[S_W_USED] * 2 > len(wk):
            act = _full(st, cap, pk, sk, wk)
            if act >= 0:
                return pos, act
        if fmt == 0:
            if pos + 16 > end:
                break
            incl = _u32(buf, pos + 8, big)
            if incl > MAX_RECORD:
                return pos, ST_CORRUPT
            size = 16 + incl
            if pos + size > end:
                break
            frac = _u32(buf, pos + 4, big)
            ts = _u32(buf, pos, big) * 1000000000 + (frac if ns_res else frac * 1000)
            d = pos + 16
            orig = _u32(buf, pos + 12, big)
        else:
            if pos + 8 > end:
                break
            btype = _u32(buf, pos, big)
            if btype == 0x0A0D0D0A:
                return pos, ST_BLOCK
            size = _u32(buf, pos + 4, big)
            if size < 12 or size % 4 != 0 or size > MAX_RECORD:
                return pos, ST_CORRUPT
            if pos + size > end:
                break
            if btype == 1:
                return pos, ST_BLOCK
            if btype != 6 and btype != 2 and btype != 3:
                st[S_SKIPPED] += 1
                pos += size
                continue
            d, incl, orig, ts = _pcapng_record(buf, pos, size, btype, big, ifs, n_if, st)
            if d < 0:
                pos += size
                continue
        _packet(buf, d, incl, orig, ts, st, cmd_counts, dg, pk, pn, pts, pmeta, sk, sc, wk, wv,
                o_rt, o_rtts, o_rtcyc, o_period, o_burst, o_dc, o_mbx, o_wkc)
        pos += size
    if eof:
        if pos == end:
            return pos, ST_DONE
        return pos, ST_CORRUPT
    return pos, ST_NEED_MORE


def _pcapng_record(
    buf: Any, pos: Any, total: Any, btype: Any, big: Any, ifs: Any, n_if: Any, st: Any,
) -> Any:
    """``(data offset, captured, original, ts_ns)`` of an EPB/OPB/SPB; data offset -1 when
    the packet is not analysed (counted here as malformed or non-Ethernet)."""
    if btype == 3:
        if total < 16 or n_if == 0:
            st[S_FRAMES] += 1
            st[S_MALFORMED] += 1
            return -1, 0, 0, 0
        orig = _u32(buf, pos + 8, big)
        incl = min(orig, total - 16)
        iface = 0
        ts = st[S_LAST_TS]
        start = pos + 12
    else:
        if total < 32:
            st[S_FRAMES] += 1
            st[S_MALFORMED] += 1
            return -1, 0, 0, 0
        if btype == 6:
            iface = _u32(buf, pos + 8, big)
        else:
            iface = _u16(buf, pos + 8, big)
        hi = _u32(buf, pos + 12, big)
        incl = _u32(buf, pos + 20, big)
        orig = _u32(buf, pos + 24, big)
        start = pos + 28
        if 28 + incl > total - 4 or iface >= n_if:
            st[S_FRAMES] += 1
            st[S_MALFORMED] += 1
            return -1, 0, 0, 0
        ts = TS_BAD
        if hi < 0x80000000:
            b = iface * 5
            units = (hi << 32) | _u32(buf, pos + 16, big)
            ts = _ts_ns(units, ifs[b], ifs[b + 1], ifs[b + 2], ifs[b + 3])
    if ifs[iface * 5 + 4] == 0:
        st[S_FRAMES] += 1
        st[S_NONECAT] += 1
        st[S_NON_ETH] += 1
        return -1, 0, 0, 0
    if ts == TS_BAD:
        st[S_FRAMES] += 1
        st[S_MALFORMED] += 1
        return -1, 0, 0, 0
    return start, incl, orig, ts


def rehash(
    ok: Any, on: Any, ots: Any, ometa: Any, nk: Any, nn: Any, nts: Any, nmeta: Any,
    keep_empty: Any,
) -> Any:
    """Move the entries of one open-addressing table into a new (empty) one.

    With ``on`` given (a pairing table), slots whose stack is empty are dropped unless
    ``keep_empty``. Returns the number of keys moved. For the stream and WKC tables the
    value array is passed as ``on`` and ``ots``/``ometa`` are empty.
    """
    used = 0
    depth = len(ots) // len(ok) if len(ok) > 0 else 0
    for i in range(len(ok)):
        k = ok[i]
        if k == 0:
            continue
        if depth > 0 and on[i] == 0 and not keep_empty:
            continue
        j = _slot(nk, k)
        nk[j] = k
        nn[j] = on[i]
        for t in range(depth):
            nts[j * depth + t] = ots[i * depth + t]
            nmeta[j * depth + t] = ometa[i * depth + t]
        used += 1
    return used


def finish(st: Any, o_burst: Any) -> Any:
    """End of file: the last cyclic frame without a return is lost; close the DC burst."""
    if st[S_CYC_N] > 0 and st[S_CYC_MATCHED] == 0:
        st[S_LOST] += 1
        st[S_CYC_MATCHED] = 1
    if st[S_DC_BURST] > 0:
        o_burst[st[S_N_BURST]] = st[S_DC_BURST]
        st[S_N_BURST] += 1
        st[S_DC_BURST] = 0


#: Everything called per frame is inlined: a call that passes arrays costs reference
#: counting of each array in numba, which would dominate the per-frame time. Not
#: ``_slot`` and ``_check_wkc``: inlined (numba 0.60-0.61), the WKC table lookups gave
#: wrong results (the engine-equivalence tests caught it).
INLINE = frozenset({
    "_byte", "_u16", "_u32", "_mix", "_key", "_addr_key", "_ts_ns", "_push",
    "_count_stream", "_returned_extras", "_drift", "_ecat", "_packet", "_full",
    "_pcapng_record",
})

KERNELS = (
    "_byte", "_u16", "_u32", "_mix", "_key", "_slot", "_addr_key", "_ts_ns", "_push",
    "_count_stream",
    "_check_wkc", "_returned_extras", "_drift", "_ecat", "_packet", "_full", "scan",
    "_pcapng_record", "rehash", "finish",
)
