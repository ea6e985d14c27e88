"""The capture scanner: walks pcap/pcapng records in a byte buffer and analyses each
EtherCAT frame in one pass (pure; no IO).

This module is the reference ("python" engine), written as integers, indexing and loops,
no objects, so that ``_cscan.c`` (the "c" engine, :mod:`lolacli.capture.cengine`) can
repeat it statement for statement in C; :mod:`lolacli.capture.fast` picks the engine.

Everything lives in flat integer arrays (lists in plain-Python mode):

* ``st`` — counters and running state, indexed by the ``S_*`` constants below;
* ``cmd_counts[256]`` — datagrams per command byte;
* the pairing table ``pk/pn/pv`` (open addressing, key = 63-bit hash of the frame's
  (command, index, address key) sequence; per key a stack of ``DEPTH`` pending outgoing
  frames, ``PCOLS`` values each: timestamp, ``frame << 1 | cyclic``, echo evidence).
  A return pops the most recent one (docs/architecture.md "Pairing"); a frame pushed out of a full
  stack is written to ``o_evict`` (it can no longer be answered: lost or in flight);
* the stream table ``sk/sc`` (outgoing frames per (command, address key) signature), used
  to pick the cyclic stream when there is no logical traffic;
* the observation table ``wk/wn/wv``: per distinct observation a count and ``OCOLS``
  values (kind, command, three fields, the first three and the last frame number).
  :data:`KIND_WKC`: a WKC returned by one cyclic datagram (command, address key, length,
  WKC); :data:`KIND_AL_STATUS`: an AL status register read (command, station, status
  code, WKC, status). The verdicts are drawn from it after the scan
  (:mod:`lolacli.capture.verdict`), when references are known;
* output rows ``o_*`` that the driver drains whenever :data:`ST_FLUSH` is returned;
  ``o_cfg`` flags the master's writes of station addresses, AL control and FMMUs, which
  the driver decodes from the buffer (:mod:`lolacli.capture.layout`); ``o_ctr`` every
  APRD/FPRD of the ESC error counters (ADO 0x0300, 20 bytes), out or back, whose answers
  the driver decodes (:mod:`lolacli.capture.counters`) — so that no second pass over the
  file looks for them.

Direction (docs/architecture.md "Direction"): ``st[S_DIRMODE]`` 0 takes the packet type of Linux
cooked captures (SLL/SLL2: 4 = sent by this host) and the locally administered bit of the
source MAC of Ethernet frames; 1 infers it: a frame is the echo of the pending frame with
the same datagram sequence, indexes and lengths when its WKC sum is not smaller and, if it
carries auto-increment/broadcast datagrams, their ADPs changed (every slave increments
them; compared for inequality because they wrap at 16 bits). A frame whose WKCs are only
equal to the pending one's is its echo only when it comes within the echo window
(:data:`ECHO_ROUND_TRIPS` x the running round trip): a master resends a lost frame as it
was, WKCs 0, and that copy is no echo.

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
S_EVICTED = 10
S_N_EVICT = 11
S_CYC_LAST_TS = 12
S_N_CFG = 13
S_WKC_OBS = 14
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
S_DIRMODE = 29
S_NON_ETH = 30
S_ECAT_OTHER = 31
S_FIRST_TS = 32
S_END_TS = 33
S_UDP = 34
S_VLAN = 35
S_CUT = 36
S_LOGICAL_OUT = 37
S_SKIPPED = 38
S_DIR_PT = 39
S_TS_SEEN = 40
S_BACKWARDS = 41
S_BACK_F0 = 42  # frame numbers of the first BACK_KEEP backward steps
S_MALF_F0 = 45  # frame numbers of the first BACK_KEEP malformed frames
S_CYC_BYTES = 48  # the longest cyclic outgoing frame, bytes on the wire (docs/architecture.md)
S_BRD_MAX = 49  # the highest WKC a BRD/BWR came back with: the slaves on the line
S_RT_EST = 50  # running average of round trips (direction inference: the echo window)
S_N_CTR = 51  # rows in o_ctr: reads of the ESC error counters (0x0300, 20 bytes)
S_SIZE = 64

# --- kernel return codes -----------------------------------------------------------------
ST_NEED_MORE = 0
ST_FLUSH = 1
ST_BLOCK = 2
ST_GROW = 3
ST_CORRUPT = 4
ST_DONE = 5
#: only the C engine, on a mapped file that shrank under it (a bus error caught in
#: _cscan.c): the position is the record being read, the driver re-reads the file size
ST_FAULT = 6

MODE_LOGICAL = 0
MODE_SIGNATURE = 1

DIR_AUTO = 0
DIR_INFER = 1

#: link types analysed (pcap LINKTYPE_*): Ethernet, Linux cooked v1 and v2
LINK_ETHERNET = 1
LINK_SLL = 113
LINK_SLL2 = 276
#: Linux packet type of a frame this host sent (PACKET_OUTGOING)
PACKET_OUTGOING = 4

DEPTH = 16
PCOLS = 3
MAX_DGRAMS = 128
CHECK_EVERY = 64
MBX_COLS = 8
CFG_COLS = 6
EVICT_COLS = 2
CTR_COLS = 8
OCOLS = 10
BACK_KEEP = 3
KIND_WKC = 1
KIND_AL_STATUS = 2
#: observations one record may add at most (two per datagram: a WKC and an AL status)
OBS_PER_RECORD = 2 * MAX_DGRAMS
MAX_RECORD = 16 * 1024 * 1024
#: the C engine reads one byte per this many of a record, from its end, before counting
#: it (a page of a mapped file that is gone faults there, before any counter changed)
TOUCH_STEP = 4096
BURST_GAP_NS = 1_000_000
#: direction inference: a frame that looks exactly like a pending one (WKCs not higher)
#: is its echo only within ECHO_ROUND_TRIPS x the running round trip (at least
#: ECHO_WINDOW_NS); later it is a frame of its own (a master resending a lost frame)
ECHO_ROUND_TRIPS = 10
ECHO_WINDOW_NS = 1_000_000
#: The 64-bit FNV prime, FNV_HI << 32 | FNV_LO (see _mix)
FNV_HI = 0x100
FNV_LO = 0x1B3
SEED_PAIR = 0x2545F4914F6CDD1D
SEED_STREAM = 0x1B873593
SEED_OBS = 0x5BD1E995

#: Timestamps are int64 nanoseconds: a pcapng packet whose raw timestamp has the top bit
#: set, or converts beyond TS_LIMIT_NS (year 2116), is malformed; interface offsets
#: (``if_tsoffset``) are limited to ±TS_OFFSET_LIMIT_NS (36 years). Differences of two
#: timestamps then fit in int64 as well.
TS_LIMIT_NS = 1 << 62
TS_OFFSET_LIMIT_NS = 1 << 60
TS_BAD = -(1 << 62)

REG_STATION_ADDRESS = 0x0010
REG_AL_CONTROL = 0x0120
REG_AL_STATUS = 0x0130
REG_AL_STATUS_CODE = 0x0134
REG_FMMU = 0x0600
REG_FMMU_END = 0x0700
REG_DC_SYSTIME = 0x0910
REG_DC_SYSTIME_DIFF = 0x092C
MBX_AREA = 0x1000
REG_RX_ERROR_COUNTER = 0x0300
ERROR_COUNTER_BYTES = 20


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

    The product is built from 32-bit halves so that no intermediate leaves int64: signed
    overflow is undefined in C (an LLVM-compiled twin once dropped the 63-bit mask that
    followed a plain wrapping multiply, and its keys differed from Python's)."""
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


def _adp_incremented(cmd: Any) -> Any:
    """APRD APWR APRW ARMW BRD BWR BRW: every slave increments the ADP."""
    return cmd == 1 or cmd == 2 or cmd == 3 or cmd == 13 or cmd == 7 or cmd == 8 or cmd == 9


def addr_key(cmd: Any, addr: Any) -> Any:
    if _adp_incremented(cmd):
        return addr & 0xFFFF0000
    return addr


def _ts_ns(units: Any, mode: Any, a: Any, b: Any, off: Any) -> Any:
    """Nanoseconds of raw pcapng units (``units`` < 2^63), or :data:`TS_BAD` beyond
    :data:`TS_LIMIT_NS`. Every intermediate value fits in int64 (C)."""
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


def _push(
    pk: Any, pn: Any, pv: Any, st: Any, key: Any, ts: Any, meta: Any, ev: Any, o_evict: Any,
) -> Any:
    i = _slot(pk, key)
    if pk[i] == 0:
        pk[i] = key
        st[S_P_USED] += 1
    n = pn[i]
    base = i * DEPTH * PCOLS
    if n == DEPTH:
        # the oldest pending frame leaves the stack: it can no longer be paired
        r = st[S_N_EVICT] * EVICT_COLS
        o_evict[r] = pv[base + 1]
        o_evict[r + 1] = pv[base]
        st[S_N_EVICT] += 1
        st[S_EVICTED] += 1
        for j in range(PCOLS, DEPTH * PCOLS):
            pv[base + j - PCOLS] = pv[base + j]
        n = DEPTH - 1
    e = base + n * PCOLS
    pv[e] = ts
    pv[e + 1] = meta
    pv[e + 2] = ev
    pn[i] = n + 1


def _bad(st: Any) -> Any:
    """Count a malformed frame; keep the numbers of the first BACK_KEEP."""
    if st[S_MALFORMED] < BACK_KEEP:
        st[S_MALF_F0 + st[S_MALFORMED]] = st[S_FRAMES]
    st[S_MALFORMED] += 1


def _count_stream(sk: Any, sc: Any, st: Any, key: Any) -> Any:
    i = _slot(sk, key)
    if sk[i] == 0:
        sk[i] = key
        st[S_S_USED] += 1
    sc[i] += 1


def _observe(
    wk: Any, wn: Any, wv: Any, st: Any, kind: Any, cmd: Any, a: Any, b: Any, c: Any, d: Any,
    frame: Any,
) -> Any:
    """Count one observation (kind, cmd, a, b, c, d); keep its first three and last frame."""
    # three words: kind|cmd|b, a, c|d (a and b below 2^32, kind/cmd/c/d below 2^16)
    key = _key(_mix(_mix(_mix(SEED_OBS, (kind << 40) | (cmd << 32) | (b & 0xFFFFFFFF)), a),
                    (c << 32) | (d & 0xFFFFFFFF)))
    i = _slot(wk, key)
    base = i * OCOLS
    n = wn[i]
    if wk[i] == 0:
        wk[i] = key
        st[S_W_USED] += 1
        wv[base] = kind
        wv[base + 1] = cmd
        wv[base + 2] = a
        wv[base + 3] = b
        wv[base + 4] = c
        wv[base + 5] = d
        wv[base + 6] = frame
    elif n == 1:
        wv[base + 7] = frame
    elif n == 2:
        wv[base + 8] = frame
    wv[base + 9] = frame
    wn[i] = n + 1


def _returned_extras(
    buf: Any, q: Any, cmd: Any, ado: Any, ln: Any, wkc: Any, ts: Any, st: Any, wk: Any,
    wn: Any, wv: Any, o_dc: Any, o_mbx: Any,
) -> Any:
    # Reads of the DC system-time difference (0x092C): sign-and-magnitude nanoseconds.
    if (cmd == 1 or cmd == 4) and wkc >= 1 and ado <= REG_DC_SYSTIME_DIFF:
        if ado + ln >= REG_DC_SYSTIME_DIFF + 4:
            v = _u32(buf, q + 10 + REG_DC_SYSTIME_DIFF - ado, False)
            mag = v & 0x7FFFFFFF
            o_dc[st[S_N_DC]] = -mag if v & 0x80000000 else mag
            st[S_N_DC] += 1
    # AL status reads (FPRD/FPRW of one slave, BRD/BRW of all): state, and the status
    # code when the read covers 0x0134 too.
    if (cmd == 4 or cmd == 6 or cmd == 7 or cmd == 9) and wkc >= 1 and ado <= REG_AL_STATUS:
        if ado + ln >= REG_AL_STATUS + 2:
            status = _u16(buf, q + 10 + REG_AL_STATUS - ado, False)
            code = -1
            if ado + ln >= REG_AL_STATUS_CODE + 2:
                code = _u16(buf, q + 10 + REG_AL_STATUS_CODE - ado, False)
            station = _u16(buf, q + 2, False) if cmd == 4 or cmd == 6 else 0
            _observe(wk, wn, wv, st, KIND_AL_STATUS, cmd, station, code, wkc, status,
                     st[S_FRAMES])
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


def _config_write(buf: Any, q: Any, cmd: Any, ado: Any, ln: Any, st: Any, o_cfg: Any) -> Any:
    """Flag an outgoing write of a station address (0x0010), AL control (0x0120) or FMMU
    (0x0600-0x06FF): the master's configuration, decoded by the driver."""
    if not (cmd == 2 or cmd == 3 or cmd == 5 or cmd == 6 or cmd == 8 or cmd == 9):
        return
    end = ado + ln
    if ado >= REG_FMMU_END or end <= REG_STATION_ADDRESS:
        return
    if ado < REG_STATION_ADDRESS + 2 or (ado < REG_AL_CONTROL + 2 and end > REG_AL_CONTROL) \
            or end > REG_FMMU:
        r = st[S_N_CFG] * CFG_COLS
        o_cfg[r] = st[S_FRAMES]
        o_cfg[r + 1] = q
        o_cfg[r + 2] = cmd
        o_cfg[r + 3] = _u16(buf, q + 2, False)
        o_cfg[r + 4] = ado
        o_cfg[r + 5] = ln
        st[S_N_CFG] += 1


def _counter_read(
    buf: Any, q: Any, j: Any, cmd: Any, ado: Any, ln: Any, ret: Any, st: Any, o_ctr: Any,
) -> Any:
    """Flag an APRD/FPRD of the error counters (0x0300, 20 bytes), out (``ret`` 0) or back
    (1): frame, the datagram's offset, command, ADP, index, place ``j`` in the frame, WKC,
    direction. The driver pairs them and reads the answers' data from the buffer."""
    if (cmd == 1 or cmd == 4) and ado == REG_RX_ERROR_COUNTER and ln == ERROR_COUNTER_BYTES:
        r = st[S_N_CTR] * CTR_COLS
        o_ctr[r] = st[S_FRAMES]
        o_ctr[r + 1] = q
        o_ctr[r + 2] = cmd
        o_ctr[r + 3] = _u16(buf, q + 2, False)
        o_ctr[r + 4] = _byte(buf, q + 1)
        o_ctr[r + 5] = j
        o_ctr[r + 6] = _u16(buf, q + 10 + ln, False)
        o_ctr[r + 7] = ret
        st[S_N_CTR] += 1


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
    pk: Any, pn: Any, pv: Any, sk: Any, sc: Any, wk: Any, wn: Any, wv: Any, o_rt: Any,
    o_rtts: Any, o_rtfr: Any, o_period: Any, o_burst: Any, o_dc: Any, o_mbx: Any,
    o_cfg: Any, o_evict: Any, o_ctr: Any,
) -> Any:
    """One EtherCAT payload at ``p`` (captured bytes end at ``limit``); ``ret`` 0 sent by
    the master, 1 returned, -1 to infer.

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
    qend = q
    st[S_ECAT] += 1
    st[S_DGRAMS] += n
    infer = ret < 0
    hp = SEED_PAIR
    hs = SEED_STREAM
    logical = False
    wsum = 0
    adps = 0
    inc = 0
    for j in range(n):
        q = dg[j]
        cmd = _byte(buf, q)
        addr = _u32(buf, q + 2, False)
        akey = addr_key(cmd, addr)
        cmd_counts[cmd] += 1
        hp = _mix(_mix(hp, (cmd << 8) | _byte(buf, q + 1)), akey)
        hs = _mix(_mix(hs, cmd), akey)
        if cmd == 10 or cmd == 11 or cmd == 12:
            logical = True
        if infer:
            ln = _u16(buf, q + 6, False) & 0x7FF
            hp = _mix(hp, ln)
            wsum += _u16(buf, q + 10 + ln, False)
            if _adp_incremented(cmd):
                adps += addr & 0xFFFF
                inc = 1
    hp = _key(hp)
    hs = _key(hs)
    if st[S_MODE] == MODE_LOGICAL:
        cyc = logical
    else:
        cyc = hs == st[S_STREAM_SIG]
    frame = st[S_FRAMES]
    ev = (wsum << 17) | (inc << 16) | (adps & 0xFFFF)
    if infer:
        # an echo of the most recent pending frame with this key, or a frame of its own
        ret = 0
        i = _slot(pk, hp)
        if pk[i] != 0 and pn[i] > 0:
            t = (i * DEPTH + pn[i] - 1) * PCOLS
            e = pv[t + 2]
            if inc == 0 or (ev & 0xFFFF) != (e & 0xFFFF):
                if (ev >> 17) > (e >> 17):
                    ret = 1
                elif (ev >> 17) == (e >> 17):
                    window = ECHO_ROUND_TRIPS * st[S_RT_EST]
                    if window < ECHO_WINDOW_NS:
                        window = ECHO_WINDOW_NS
                    if ts - pv[t] <= window:
                        ret = 1
    if ret == 0:
        st[S_OUT] += 1
        if logical:
            st[S_LOGICAL_OUT] += 1
        elif st[S_LOGICAL_OUT] == 0:
            # only needed to pick the cyclic stream of a capture without logical traffic
            _count_stream(sk, sc, st, hs)
        cbit = 0
        if cyc:
            if st[S_CYC_N] > 0:
                o_period[st[S_N_PERIOD]] = ts - st[S_CYC_LAST_TS]
                st[S_N_PERIOD] += 1
            st[S_CYC_N] += 1
            st[S_CYC_LAST_TS] = ts
            cbit = 1
            # Ethernet header 14 + EtherCAT header and datagrams + FCS 4, at least 64
            fb = 18 + qend - p
            if fb < 64:
                fb = 64
            if fb > st[S_CYC_BYTES]:
                st[S_CYC_BYTES] = fb
        _push(pk, pn, pv, st, hp, ts, (frame << 1) | cbit, ev, o_evict)
        for j in range(n):
            q = dg[j]
            cmd = _byte(buf, q)
            ado = _u16(buf, q + 4, False)
            if (cmd == 13 or cmd == 14) and ado == REG_DC_SYSTIME:
                _drift(ts, st, o_burst)
            ln = _u16(buf, q + 6, False) & 0x7FF
            _config_write(buf, q, cmd, ado, ln, st, o_cfg)
            _counter_read(buf, q, j, cmd, ado, ln, 0, st, o_ctr)
        return True
    st[S_RET] += 1
    i = _slot(pk, hp)
    if pk[i] != 0 and pn[i] > 0:
        top = pn[i] - 1
        pn[i] = top
        e = (i * DEPTH + top) * PCOLS
        r = st[S_N_RT]
        o_rt[r] = ts - pv[e]
        o_rtts[r] = ts
        o_rtfr[r] = pv[e + 1]
        st[S_N_RT] = r + 1
        st[S_PAIRS] += 1
        if infer:
            rt = ts - pv[e]
            if rt < 0:
                rt = 0
            st[S_RT_EST] = rt if st[S_PAIRS] == 1 else (7 * st[S_RT_EST] + rt) >> 3
    else:
        st[S_UNMATCHED_RET] += 1
    for j in range(n):
        q = dg[j]
        cmd = _byte(buf, q)
        ado = _u16(buf, q + 4, False)
        ln = _u16(buf, q + 6, False) & 0x7FF
        wkc = _u16(buf, q + 10 + ln, False)
        if (cmd == 7 or cmd == 8) and wkc > st[S_BRD_MAX]:
            st[S_BRD_MAX] = wkc
        if cyc:
            st[S_WKC_OBS] += 1
            _observe(wk, wn, wv, st, KIND_WKC, cmd, addr_key(cmd, _u32(buf, q + 2, False)),
                     ln, wkc, 0, frame)
        _returned_extras(buf, q, cmd, ado, ln, wkc, ts, st, wk, wn, wv, o_dc, o_mbx)
        _counter_read(buf, q, j, cmd, ado, ln, 1, st, o_ctr)
    return True


def _packet(
    buf: Any, d: Any, cap: Any, orig: Any, ts: Any, link: Any, st: Any, cmd_counts: Any,
    dg: Any, pk: Any, pn: Any, pv: Any, sk: Any, sc: Any, wk: Any, wn: Any, wv: Any,
    o_rt: Any, o_rtts: Any, o_rtfr: Any, o_period: Any, o_burst: Any, o_dc: Any, o_mbx: Any,
    o_cfg: Any, o_evict: Any, o_ctr: Any,
) -> Any:
    """One link-layer frame (Ethernet, SLL or SLL2) of ``cap`` captured bytes at ``d``."""
    st[S_FRAMES] += 1
    # not S_FRAMES == 1: packets skipped in _pcapng_record are counted without a time
    if st[S_TS_SEEN] == 0:
        st[S_TS_SEEN] = 1
        st[S_FIRST_TS] = ts
    elif ts < st[S_END_TS]:
        if st[S_BACKWARDS] < BACK_KEEP:
            st[S_BACK_F0 + st[S_BACKWARDS]] = st[S_FRAMES]
        st[S_BACKWARDS] += 1
    st[S_END_TS] = ts
    st[S_LAST_TS] = ts
    cooked = True
    if link == LINK_SLL:
        # packet type u16, ARPHRD u16, address length u16, address 8, protocol u16
        if cap < 16:
            _bad(st)
            return
        ret = 0 if _u16(buf, d, True) == PACKET_OUTGOING else 1
        etype = _u16(buf, d + 14, True)
        p = d + 16
    elif link == LINK_SLL2:
        # protocol u16, reserved u16, ifindex u32, ARPHRD u16, packet type u8, address
        # length u8, address 8
        if cap < 20:
            _bad(st)
            return
        ret = 0 if _byte(buf, d + 10) == PACKET_OUTGOING else 1
        etype = _u16(buf, d, True)
        p = d + 20
    else:
        if cap < 14:
            _bad(st)
            return
        ret = 1 if _byte(buf, d + 6) & 0x02 else 0
        etype = _u16(buf, d + 12, True)
        p = d + 14
        cooked = False
    limit = d + cap
    if etype == 0x8100:
        if p + 4 > limit:
            _bad(st)
            return
        etype = _u16(buf, p + 2, True)
        p = p + 4
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
    if st[S_DIRMODE] == DIR_INFER:
        ret = -1
    ok = _ecat(buf, p, limit, ret, ts, st, cmd_counts, dg, pk, pn, pv, sk, sc, wk, wn, wv,
               o_rt, o_rtts, o_rtfr, o_period, o_burst, o_dc, o_mbx, o_cfg, o_evict, o_ctr)
    if not ok:
        _bad(st)
        return
    if cooked and ret >= 0:
        st[S_DIR_PT] += 1
    if cap < orig:
        st[S_CUT] += 1


def _full(st: Any, cap: Any, pk: Any, sk: Any, wk: Any) -> Any:
    """ST_FLUSH / ST_GROW / -1: whether the driver must act before the next record."""
    lim = cap - MAX_DGRAMS - 2
    if (st[S_N_RT] >= lim or st[S_N_PERIOD] >= lim or st[S_N_BURST] >= lim
            or st[S_N_DC] >= lim or st[S_N_MBX] >= lim or st[S_N_CFG] >= lim
            or st[S_N_EVICT] >= lim or st[S_N_CTR] >= lim):
        return ST_FLUSH
    if st[S_P_USED] * 2 > len(pk) or st[S_S_USED] * 2 > len(sk) or st[S_W_USED] * 2 > len(wk):
        return ST_GROW
    return -1


def scan(
    buf: Any, pos: Any, end: Any, eof: Any, fmt: Any, big: Any, ns_res: Any, ifs: Any,
    n_if: Any, st: Any, cmd_counts: Any, dg: Any, pk: Any, pn: Any, pv: Any, sk: Any,
    sc: Any, wk: Any, wn: Any, wv: Any, o_rt: Any, o_rtts: Any, o_rtfr: Any, o_period: Any,
    o_burst: Any, o_dc: Any, o_mbx: Any, o_cfg: Any, o_evict: Any, o_ctr: Any,
) -> Any:
    """Walk records from ``pos`` until the buffer ends or the driver must act.

    ``fmt`` 0 = classic pcap (``ns_res`` 1 for nanosecond files), 1 = pcapng. ``ifs`` holds
    5 integers per pcapng interface: ts mode, a, b, offset_ns, link type (0 when not
    analysed); classic pcap uses the link type of row 0.
    Returns ``(pos, status)``.
    """
    # outputs and tables are checked every CHECK_EVERY records: leave room for that many.
    # The observation table is checked before every record: one record may add
    # OBS_PER_RECORD keys, and a full open-addressing table would make _slot loop forever.
    cap = len(o_rt) - CHECK_EVERY * (MAX_DGRAMS + 2)
    count = 0
    pcap_link = ifs[4] if n_if > 0 else LINK_ETHERNET
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
            link = pcap_link
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
            d, incl, orig, ts, link = _pcapng_record(buf, pos, size, btype, big, ifs, n_if, st)
            if d < 0:
                pos += size
                continue
        _packet(buf, d, incl, orig, ts, link, st, cmd_counts, dg, pk, pn, pv, sk, sc, wk, wn,
                wv, o_rt, o_rtts, o_rtfr, o_period, o_burst, o_dc, o_mbx, o_cfg, o_evict, o_ctr)
        pos += size
    if eof:
        if pos == end:
            return pos, ST_DONE
        return pos, ST_CORRUPT
    return pos, ST_NEED_MORE


def _pcapng_record(
    buf: Any, pos: Any, total: Any, btype: Any, big: Any, ifs: Any, n_if: Any, st: Any,
) -> Any:
    """``(data offset, captured, original, ts_ns, link type)`` of an EPB/OPB/SPB; data
    offset -1 when the packet is not analysed (counted here as malformed or non-Ethernet)."""
    if btype == 3:
        if total < 16 or n_if == 0:
            st[S_FRAMES] += 1
            _bad(st)
            return -1, 0, 0, 0, 0
        orig = _u32(buf, pos + 8, big)
        incl = min(orig, total - 16)
        iface = 0
        ts = st[S_LAST_TS]
        start = pos + 12
    else:
        if total < 32:
            st[S_FRAMES] += 1
            _bad(st)
            return -1, 0, 0, 0, 0
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
            _bad(st)
            return -1, 0, 0, 0, 0
        ts = TS_BAD
        if hi < 0x80000000:
            b = iface * 5
            units = (hi << 32) | _u32(buf, pos + 16, big)
            ts = _ts_ns(units, ifs[b], ifs[b + 1], ifs[b + 2], ifs[b + 3])
    link = ifs[iface * 5 + 4]
    if link == 0:
        st[S_FRAMES] += 1
        st[S_NONECAT] += 1
        st[S_NON_ETH] += 1
        return -1, 0, 0, 0, 0
    if ts == TS_BAD:
        st[S_FRAMES] += 1
        _bad(st)
        return -1, 0, 0, 0, 0
    return start, incl, orig, ts, link


def rehash(ok: Any, on: Any, ov: Any, nk: Any, nn: Any, nv: Any, keep_empty: Any) -> Any:
    """Move the entries of one open-addressing table into a new (empty) one.

    ``on`` holds one count per slot, ``ov`` ``len(ov) // len(ok)`` values per slot (none
    for the stream table). Slots whose count is 0 are dropped unless ``keep_empty`` (the
    pairing table drops keys without pending frames). Returns the number of keys moved.
    """
    used = 0
    width = len(ov) // len(ok) if len(ok) > 0 else 0
    for i in range(len(ok)):
        k = ok[i]
        if k == 0:
            continue
        if on[i] == 0 and not keep_empty:
            continue
        j = _slot(nk, k)
        nk[j] = k
        nn[j] = on[i]
        for t in range(width):
            nv[j * width + t] = ov[i * width + t]
        used += 1
    return used


def finish(st: Any, o_burst: Any) -> Any:
    """End of file: close the DC burst."""
    if st[S_DC_BURST] > 0:
        o_burst[st[S_N_BURST]] = st[S_DC_BURST]
        st[S_N_BURST] += 1
        st[S_DC_BURST] = 0

