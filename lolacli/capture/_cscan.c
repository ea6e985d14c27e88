/* The capture scanner in C: the same algorithm as lolacli/capture/scan.py, statement for
 * statement, for the "c" engine (lolacli/capture/cengine.py loads it with ctypes).
 *
 * scan.py is the reference: its docstrings describe the data layout (st counters, the
 * open-addressing tables, the output rows). Keep both in step; tests compare the engines
 * on every corpus capture, on damaged files and on files that force every return code,
 * and a test checks that the constants below equal scan.py's.
 *
 * Why C: `capture analyze` of a 1 M-frame capture runs about 100x faster than on
 * scan.py (benchmarks/capture_throughput.py --engines c,python); a numba-compiled twin
 * that was here ran 3-14x slower than this file, mostly its import and LLVM start-up,
 * and was removed.
 *
 * Integers are int64; scan.py bounds timestamps (TS_LIMIT_NS) so that no signed
 * operation overflows and both engines agree exactly; the hash (mix) avoids overflow as
 * well.
 */
#include <Python.h>
#include <setjmp.h>
#include <signal.h>
#include <stdint.h>
#include <string.h>

/* st indices */
#define S_FRAMES 0
#define S_ECAT 1
#define S_NONECAT 2
#define S_MALFORMED 3
#define S_DGRAMS 4
#define S_OUT 5
#define S_RET 6
#define S_PAIRS 7
#define S_UNMATCHED_RET 8
#define S_CYC_N 9
#define S_EVICTED 10
#define S_N_EVICT 11
#define S_CYC_LAST_TS 12
#define S_N_CFG 13
#define S_WKC_OBS 14
#define S_DC_DGRAMS 15
#define S_DC_BURST 16
#define S_DC_LAST_TS 17
#define S_N_RT 18
#define S_N_PERIOD 19
#define S_N_BURST 20
#define S_N_DC 21
#define S_N_MBX 22
#define S_P_USED 23
#define S_S_USED 24
#define S_W_USED 25
#define S_LAST_TS 26
#define S_MODE 27
#define S_STREAM_SIG 28
#define S_DIRMODE 29
#define S_NON_ETH 30
#define S_ECAT_OTHER 31
#define S_FIRST_TS 32
#define S_END_TS 33
#define S_UDP 34
#define S_VLAN 35
#define S_CUT 36
#define S_LOGICAL_OUT 37
#define S_SKIPPED 38
#define S_DIR_PT 39
#define S_TS_SEEN 40
#define S_BACKWARDS 41
#define S_BACK_F0 42
#define S_MALF_F0 45
#define S_CYC_BYTES 48
#define S_BRD_MAX 49
#define S_RT_EST 50
#define S_N_CTR 51
#define S_SIZE 64

/* return codes */
#define ST_NEED_MORE 0
#define ST_FLUSH 1
#define ST_BLOCK 2
#define ST_GROW 3
#define ST_CORRUPT 4
#define ST_DONE 5
#define ST_FAULT 6

#define MODE_LOGICAL 0
#define DIR_INFER 1

#define LINK_ETHERNET 1
#define LINK_SLL 113
#define LINK_SLL2 276
#define PACKET_OUTGOING 4

#define DEPTH 16
#define PCOLS 3
#define MAX_DGRAMS 128
#define CHECK_EVERY 64
#define MBX_COLS 8
#define CFG_COLS 6
#define EVICT_COLS 2
#define CTR_COLS 8
#define OCOLS 10
#define BACK_KEEP 3
#define KIND_WKC 1
#define KIND_AL_STATUS 2
#define MAX_RECORD (16 * 1024 * 1024)
#define TOUCH_STEP 4096
#define BURST_GAP_NS 1000000
#define ECHO_ROUND_TRIPS 10
#define ECHO_WINDOW_NS 1000000
#define FNV_HI 0x100
#define FNV_LO 0x1B3
#define SEED_PAIR 0x2545F4914F6CDD1DLL
#define SEED_STREAM 0x1B873593LL
#define SEED_OBS 0x5BD1E995LL

#define TS_LIMIT_NS (1LL << 62)
#define TS_OFFSET_LIMIT_NS (1LL << 60)
#define TS_BAD (-(1LL << 62))

#define REG_STATION_ADDRESS 0x0010
#define REG_AL_CONTROL 0x0120
#define REG_AL_STATUS 0x0130
#define REG_AL_STATUS_CODE 0x0134
#define REG_FMMU 0x0600
#define REG_FMMU_END 0x0700
#define REG_DC_SYSTIME 0x0910
#define REG_DC_SYSTIME_DIFF 0x092C
#define MBX_AREA 0x1000
#define REG_RX_ERROR_COUNTER 0x0300
#define ERROR_COUNTER_BYTES 20

typedef int64_t i64;

/* Every array the scanner reads or writes; lengths in elements. Filled by cengine.py. */
typedef struct {
    i64 *st, *cmd_counts;
    i64 *pk, *pn, *pv;
    i64 *sk, *sc, *wk, *wn, *wv;
    i64 *o_rt, *o_rtts, *o_rtfr, *o_period, *o_burst, *o_dc, *o_mbx, *o_cfg, *o_evict, *o_ctr;
    const i64 *ifs;
    i64 n_if, p_len, s_len, w_len, o_len;
} Tables;

static inline i64 u16le(const uint8_t *b, i64 p) { return (i64)b[p] | ((i64)b[p + 1] << 8); }
static inline i64 u16be(const uint8_t *b, i64 p) { return ((i64)b[p] << 8) | (i64)b[p + 1]; }
static inline i64 u16x(const uint8_t *b, i64 p, int big) { return big ? u16be(b, p) : u16le(b, p); }
static inline i64 u32le(const uint8_t *b, i64 p) { return u16le(b, p) | (u16le(b, p + 2) << 16); }
static inline i64 u32x(const uint8_t *b, i64 p, int big) {
    return big ? ((u16be(b, p) << 16) | u16be(b, p + 2)) : u32le(b, p);
}

/* (h ^ v) * FNV mod 2^63 from 32-bit halves, no intermediate beyond int64 (see scan._mix) */
static inline i64 mix(i64 h, i64 v) {
    i64 x = h ^ v;
    i64 lo = x & 0xFFFFFFFFLL;
    i64 low = lo * FNV_LO;
    i64 mid = ((x >> 32) * FNV_LO + lo * FNV_HI + (low >> 32)) & 0x7FFFFFFFLL;
    h = (mid << 32) | (low & 0xFFFFFFFFLL);
    return h ^ (h >> 29);
}

static inline i64 key_of(i64 h) { return h != 0 ? h : 1; }

static inline i64 slot(const i64 *keys, i64 len, i64 key) {
    i64 mask = len - 1;
    i64 i = (key ^ (key >> 21)) & mask;
    while (keys[i] != key && keys[i] != 0) i = (i + 1) & mask;
    return i;
}

/* APRD APWR APRW ARMW BRD BWR BRW: every slave increments the ADP. */
static inline int adp_incremented(i64 cmd) {
    return cmd == 1 || cmd == 2 || cmd == 3 || cmd == 13 || cmd == 7 || cmd == 8 || cmd == 9;
}

static inline i64 addr_key(i64 cmd, i64 addr) {
    return adp_incremented(cmd) ? (addr & 0xFFFF0000LL) : addr;
}

static inline i64 floordiv(i64 a, i64 b) {
    i64 q = a / b;
    if ((a % b != 0) && ((a < 0) != (b < 0))) q -= 1;
    return q;
}

/* Nanoseconds of raw pcapng units (< 2^63), or TS_BAD beyond TS_LIMIT_NS. */
static i64 ts_ns(i64 units, i64 mode, i64 a, i64 b, i64 off) {
    if (mode == 0) {
        if (a > 0 && units > TS_LIMIT_NS / a) return TS_BAD;
        if (b == 1) return units * a + off;
        return floordiv(units * a, b) + off;
    }
    i64 sec, frac;
    if (a >= 63) {
        sec = 0;
        frac = units;
    } else {
        sec = units >> a;
        frac = units & ((1LL << a) - 1);
    }
    if (sec > TS_LIMIT_NS / 1000000000LL) return TS_BAD;
    if (a > 30) {
        frac = (a - 30 >= 63) ? 0 : frac >> (a - 30);
        return sec * 1000000000LL + ((frac * 1000000000LL) >> 30) + off;
    }
    return sec * 1000000000LL + ((frac * 1000000000LL) >> a) + off;
}

static inline void push(Tables *t, i64 key, i64 ts, i64 meta, i64 ev) {
    i64 *st = t->st;
    i64 i = slot(t->pk, t->p_len, key);
    if (t->pk[i] == 0) {
        t->pk[i] = key;
        st[S_P_USED] += 1;
    }
    i64 n = t->pn[i];
    i64 base = i * DEPTH * PCOLS;
    i64 *pv = t->pv;
    if (n == DEPTH) {
        /* the oldest pending frame leaves the stack: it can no longer be paired */
        i64 r = st[S_N_EVICT] * EVICT_COLS;
        t->o_evict[r] = pv[base + 1];
        t->o_evict[r + 1] = pv[base];
        st[S_N_EVICT] += 1;
        st[S_EVICTED] += 1;
        for (i64 j = PCOLS; j < DEPTH * PCOLS; j++) pv[base + j - PCOLS] = pv[base + j];
        n = DEPTH - 1;
    }
    i64 e = base + n * PCOLS;
    pv[e] = ts;
    pv[e + 1] = meta;
    pv[e + 2] = ev;
    t->pn[i] = n + 1;
}

/* Count a malformed frame; keep the numbers of the first BACK_KEEP. */
static inline void bad(i64 *st) {
    if (st[S_MALFORMED] < BACK_KEEP) st[S_MALF_F0 + st[S_MALFORMED]] = st[S_FRAMES];
    st[S_MALFORMED] += 1;
}

static inline void count_stream(Tables *t, i64 key) {
    i64 i = slot(t->sk, t->s_len, key);
    if (t->sk[i] == 0) {
        t->sk[i] = key;
        t->st[S_S_USED] += 1;
    }
    t->sc[i] += 1;
}

/* Count one observation (kind, cmd, a, b, c, d); keep its first three and last frame. */
static inline void observe(Tables *t, i64 kind, i64 cmd, i64 a, i64 b, i64 c, i64 d,
                           i64 frame) {
    /* three words: kind|cmd|b, a, c|d (see scan.py) */
    i64 key = key_of(mix(mix(mix(SEED_OBS, (kind << 40) | (cmd << 32) | (b & 0xFFFFFFFFLL)), a),
                         (c << 32) | (d & 0xFFFFFFFFLL)));
    i64 i = slot(t->wk, t->w_len, key);
    i64 base = i * OCOLS;
    i64 n = t->wn[i];
    i64 *wv = t->wv;
    if (t->wk[i] == 0) {
        t->wk[i] = key;
        t->st[S_W_USED] += 1;
        wv[base] = kind;
        wv[base + 1] = cmd;
        wv[base + 2] = a;
        wv[base + 3] = b;
        wv[base + 4] = c;
        wv[base + 5] = d;
        wv[base + 6] = frame;
    } else if (n == 1) {
        wv[base + 7] = frame;
    } else if (n == 2) {
        wv[base + 8] = frame;
    }
    wv[base + 9] = frame;
    t->wn[i] = n + 1;
}

static inline void returned_extras(const uint8_t *buf, i64 q, i64 cmd, i64 ado, i64 ln,
                                   i64 wkc, i64 ts, Tables *t) {
    i64 *st = t->st;
    /* Reads of the DC system-time difference (0x092C): sign-and-magnitude nanoseconds. */
    if ((cmd == 1 || cmd == 4) && wkc >= 1 && ado <= REG_DC_SYSTIME_DIFF) {
        if (ado + ln >= REG_DC_SYSTIME_DIFF + 4) {
            i64 v = u32le(buf, q + 10 + REG_DC_SYSTIME_DIFF - ado);
            i64 mag = v & 0x7FFFFFFF;
            t->o_dc[st[S_N_DC]] = (v & 0x80000000LL) ? -mag : mag;
            st[S_N_DC] += 1;
        }
    }
    /* AL status reads (FPRD/FPRW of one slave, BRD/BRW of all), with the status code
     * when the read covers 0x0134 too. */
    if ((cmd == 4 || cmd == 6 || cmd == 7 || cmd == 9) && wkc >= 1 && ado <= REG_AL_STATUS) {
        if (ado + ln >= REG_AL_STATUS + 2) {
            i64 status = u16le(buf, q + 10 + REG_AL_STATUS - ado);
            i64 code = -1;
            if (ado + ln >= REG_AL_STATUS_CODE + 2)
                code = u16le(buf, q + 10 + REG_AL_STATUS_CODE - ado);
            i64 station = (cmd == 4 || cmd == 6) ? u16le(buf, q + 2) : 0;
            observe(t, KIND_AL_STATUS, cmd, station, code, wkc, status, st[S_FRAMES]);
        }
    }
    /* Mailbox candidates (ETG.1000.4 Table 29). */
    if ((cmd == 1 || cmd == 2 || cmd == 4 || cmd == 5) && wkc >= 1 && ado >= MBX_AREA) {
        if (ln >= 8) {
            i64 mlen = u16le(buf, q + 10);
            i64 mtype = buf[q + 15] & 0x0F;
            if (mlen >= 2 && mlen + 6 <= ln && (mtype <= 5 || mtype == 15)) {
                i64 r = st[S_N_MBX] * MBX_COLS;
                t->o_mbx[r] = st[S_FRAMES];
                t->o_mbx[r + 1] = ts;
                t->o_mbx[r + 2] = q;
                t->o_mbx[r + 3] = cmd;
                t->o_mbx[r + 4] = u32le(buf, q + 2);
                t->o_mbx[r + 5] = ln;
                t->o_mbx[r + 6] = wkc;
                t->o_mbx[r + 7] = u16le(buf, q + 8);
                st[S_N_MBX] += 1;
            }
        }
    }
}

/* Flag an outgoing write of a station address, AL control or FMMU (see scan.py). */
static inline void config_write(const uint8_t *buf, i64 q, i64 cmd, i64 ado, i64 ln,
                                Tables *t) {
    if (!(cmd == 2 || cmd == 3 || cmd == 5 || cmd == 6 || cmd == 8 || cmd == 9)) return;
    i64 end = ado + ln;
    if (ado >= REG_FMMU_END || end <= REG_STATION_ADDRESS) return;
    if (ado < REG_STATION_ADDRESS + 2 || (ado < REG_AL_CONTROL + 2 && end > REG_AL_CONTROL) ||
        end > REG_FMMU) {
        i64 *st = t->st;
        i64 r = st[S_N_CFG] * CFG_COLS;
        t->o_cfg[r] = st[S_FRAMES];
        t->o_cfg[r + 1] = q;
        t->o_cfg[r + 2] = cmd;
        t->o_cfg[r + 3] = u16le(buf, q + 2);
        t->o_cfg[r + 4] = ado;
        t->o_cfg[r + 5] = ln;
        st[S_N_CFG] += 1;
    }
}

/* Flag an APRD/FPRD of the error counters (0x0300, 20 bytes), out (ret 0) or back (1);
 * see scan.py. */
static inline void counter_read(const uint8_t *buf, i64 q, i64 j, i64 cmd, i64 ado, i64 ln,
                                i64 ret, Tables *t) {
    if ((cmd == 1 || cmd == 4) && ado == REG_RX_ERROR_COUNTER && ln == ERROR_COUNTER_BYTES) {
        i64 *st = t->st;
        i64 r = st[S_N_CTR] * CTR_COLS;
        t->o_ctr[r] = st[S_FRAMES];
        t->o_ctr[r + 1] = q;
        t->o_ctr[r + 2] = cmd;
        t->o_ctr[r + 3] = u16le(buf, q + 2);
        t->o_ctr[r + 4] = buf[q + 1];
        t->o_ctr[r + 5] = j;
        t->o_ctr[r + 6] = u16le(buf, q + 10 + ln);
        t->o_ctr[r + 7] = ret;
        st[S_N_CTR] += 1;
    }
}

static inline void drift(i64 ts, Tables *t) {
    i64 *st = t->st;
    st[S_DC_DGRAMS] += 1;
    if (st[S_DC_BURST] > 0 && ts - st[S_DC_LAST_TS] > BURST_GAP_NS) {
        t->o_burst[st[S_N_BURST]] = st[S_DC_BURST];
        st[S_N_BURST] += 1;
        st[S_DC_BURST] = 0;
    }
    st[S_DC_BURST] += 1;
    st[S_DC_LAST_TS] = ts;
}

/* One EtherCAT payload at p (captured bytes end at limit); ret 0 sent, 1 returned, -1 to
 * infer. 0 when malformed. */
static int ecat(const uint8_t *buf, i64 p, i64 limit, i64 ret, i64 ts, Tables *t) {
    i64 *st = t->st;
    i64 dg[MAX_DGRAMS];
    if (p + 2 > limit) return 0;
    i64 word = u16le(buf, p);
    if ((word >> 12) != 1) {
        st[S_NONECAT] += 1;
        st[S_ECAT_OTHER] += 1;
        return 1;
    }
    i64 q = p + 2;
    i64 n = 0;
    for (;;) {
        if (n == MAX_DGRAMS || q + 12 > limit) return 0;
        i64 lw = u16le(buf, q + 6);
        i64 ln = lw & 0x7FF;
        if (q + 12 + ln > limit) return 0;
        dg[n++] = q;
        q += 12 + ln;
        if ((lw & 0x8000) == 0) break;
    }
    i64 qend = q;
    st[S_ECAT] += 1;
    st[S_DGRAMS] += n;
    int infer = ret < 0;
    i64 hp = SEED_PAIR, hs = SEED_STREAM;
    int logical = 0;
    i64 wsum = 0, adps = 0, inc = 0;
    for (i64 j = 0; j < n; j++) {
        q = dg[j];
        i64 cmd = buf[q];
        i64 addr = u32le(buf, q + 2);
        i64 akey = addr_key(cmd, addr);
        t->cmd_counts[cmd] += 1;
        hp = mix(mix(hp, (cmd << 8) | buf[q + 1]), akey);
        hs = mix(mix(hs, cmd), akey);
        if (cmd == 10 || cmd == 11 || cmd == 12) logical = 1;
        if (infer) {
            i64 ln = u16le(buf, q + 6) & 0x7FF;
            hp = mix(hp, ln);
            wsum += u16le(buf, q + 10 + ln);
            if (adp_incremented(cmd)) {
                adps += addr & 0xFFFF;
                inc = 1;
            }
        }
    }
    i64 kp = key_of(hp), ks = key_of(hs);
    int cyc = st[S_MODE] == MODE_LOGICAL ? logical : (ks == st[S_STREAM_SIG]);
    i64 frame = st[S_FRAMES];
    i64 ev = (wsum << 17) | (inc << 16) | (adps & 0xFFFF);
    if (infer) {
        /* an echo of the most recent pending frame with this key, or a frame of its own */
        ret = 0;
        i64 i = slot(t->pk, t->p_len, kp);
        if (t->pk[i] != 0 && t->pn[i] > 0) {
            i64 tp = (i * DEPTH + t->pn[i] - 1) * PCOLS;
            i64 e = t->pv[tp + 2];
            if (inc == 0 || (ev & 0xFFFF) != (e & 0xFFFF)) {
                if ((ev >> 17) > (e >> 17)) {
                    ret = 1;
                } else if ((ev >> 17) == (e >> 17)) {
                    /* as it was: an echo only within the echo window (see scan.py) */
                    i64 window = ECHO_ROUND_TRIPS * st[S_RT_EST];
                    if (window < ECHO_WINDOW_NS) window = ECHO_WINDOW_NS;
                    if (ts - t->pv[tp] <= window) ret = 1;
                }
            }
        }
    }
    if (ret == 0) {
        st[S_OUT] += 1;
        if (logical)
            st[S_LOGICAL_OUT] += 1;
        else if (st[S_LOGICAL_OUT] == 0)
            count_stream(t, ks);
        i64 cbit = 0;
        if (cyc) {
            if (st[S_CYC_N] > 0) {
                t->o_period[st[S_N_PERIOD]] = ts - st[S_CYC_LAST_TS];
                st[S_N_PERIOD] += 1;
            }
            st[S_CYC_N] += 1;
            st[S_CYC_LAST_TS] = ts;
            cbit = 1;
            /* Ethernet header 14 + EtherCAT header and datagrams + FCS 4, at least 64 */
            i64 fb = 18 + qend - p;
            if (fb < 64) fb = 64;
            if (fb > st[S_CYC_BYTES]) st[S_CYC_BYTES] = fb;
        }
        push(t, kp, ts, (frame << 1) | cbit, ev);
        for (i64 j = 0; j < n; j++) {
            q = dg[j];
            i64 cmd = buf[q];
            i64 ado = u16le(buf, q + 4);
            if ((cmd == 13 || cmd == 14) && ado == REG_DC_SYSTIME) drift(ts, t);
            i64 ln = u16le(buf, q + 6) & 0x7FF;
            config_write(buf, q, cmd, ado, ln, t);
            counter_read(buf, q, j, cmd, ado, ln, 0, t);
        }
        return 1;
    }
    st[S_RET] += 1;
    i64 i = slot(t->pk, t->p_len, kp);
    if (t->pk[i] != 0 && t->pn[i] > 0) {
        i64 top = t->pn[i] - 1;
        t->pn[i] = top;
        i64 e = (i * DEPTH + top) * PCOLS;
        i64 r = st[S_N_RT];
        t->o_rt[r] = ts - t->pv[e];
        t->o_rtts[r] = ts;
        t->o_rtfr[r] = t->pv[e + 1];
        st[S_N_RT] = r + 1;
        st[S_PAIRS] += 1;
        if (infer) {
            i64 rt = ts - t->pv[e];
            if (rt < 0) rt = 0;
            st[S_RT_EST] = st[S_PAIRS] == 1 ? rt : (7 * st[S_RT_EST] + rt) >> 3;
        }
    } else {
        st[S_UNMATCHED_RET] += 1;
    }
    for (i64 j = 0; j < n; j++) {
        q = dg[j];
        i64 cmd = buf[q];
        i64 ado = u16le(buf, q + 4);
        i64 ln = u16le(buf, q + 6) & 0x7FF;
        i64 wkc = u16le(buf, q + 10 + ln);
        if ((cmd == 7 || cmd == 8) && wkc > st[S_BRD_MAX]) st[S_BRD_MAX] = wkc;
        if (cyc) {
            st[S_WKC_OBS] += 1;
            observe(t, KIND_WKC, cmd, addr_key(cmd, u32le(buf, q + 2)), ln, wkc, 0, frame);
        }
        returned_extras(buf, q, cmd, ado, ln, wkc, ts, t);
        counter_read(buf, q, j, cmd, ado, ln, 1, t);
    }
    return 1;
}

/* One link-layer frame (Ethernet, SLL or SLL2) of cap captured bytes at d. */
static void packet(const uint8_t *buf, i64 d, i64 cap, i64 orig, i64 ts, i64 link, Tables *t) {
    i64 *st = t->st;
    st[S_FRAMES] += 1;
    /* not S_FRAMES == 1: packets skipped in pcapng_record are counted without a time */
    if (st[S_TS_SEEN] == 0) {
        st[S_TS_SEEN] = 1;
        st[S_FIRST_TS] = ts;
    } else if (ts < st[S_END_TS]) {
        if (st[S_BACKWARDS] < BACK_KEEP) st[S_BACK_F0 + st[S_BACKWARDS]] = st[S_FRAMES];
        st[S_BACKWARDS] += 1;
    }
    st[S_END_TS] = ts;
    st[S_LAST_TS] = ts;
    int cooked = 1;
    i64 ret, etype, p;
    if (link == LINK_SLL) {
        if (cap < 16) {
            bad(st);
            return;
        }
        ret = u16be(buf, d) == PACKET_OUTGOING ? 0 : 1;
        etype = u16be(buf, d + 14);
        p = d + 16;
    } else if (link == LINK_SLL2) {
        if (cap < 20) {
            bad(st);
            return;
        }
        ret = buf[d + 10] == PACKET_OUTGOING ? 0 : 1;
        etype = u16be(buf, d);
        p = d + 20;
    } else {
        if (cap < 14) {
            bad(st);
            return;
        }
        ret = (buf[d + 6] & 0x02) ? 1 : 0;
        etype = u16be(buf, d + 12);
        p = d + 14;
        cooked = 0;
    }
    i64 limit = d + cap;
    if (etype == 0x8100) {
        if (p + 4 > limit) {
            bad(st);
            return;
        }
        etype = u16be(buf, p + 2);
        p = p + 4;
        st[S_VLAN] += 1;
    }
    if (etype == 0x0800) {
        /* EtherCAT over UDP (ETG.1000.4 5.3.2): IPv4, protocol 17, port 0x88A4. */
        if (p + 20 > limit || (buf[p] >> 4) != 4 || buf[p + 9] != 17) {
            st[S_NONECAT] += 1;
            return;
        }
        i64 ihl = (buf[p] & 0x0F) * 4;
        if ((u16be(buf, p + 6) & 0x1FFF) != 0 || p + ihl + 8 > limit) {
            st[S_NONECAT] += 1;
            return;
        }
        if (u16be(buf, p + ihl + 2) != 0x88A4) {
            st[S_NONECAT] += 1;
            return;
        }
        p = p + ihl + 8;
        st[S_UDP] += 1;
    } else if (etype != 0x88A4) {
        st[S_NONECAT] += 1;
        return;
    }
    if (st[S_DIRMODE] == DIR_INFER) ret = -1;
    if (!ecat(buf, p, limit, ret, ts, t)) {
        bad(st);
        return;
    }
    if (cooked && ret >= 0) st[S_DIR_PT] += 1;
    if (cap < orig) st[S_CUT] += 1;
}

/* Read one byte of every page of a record [pos, pos + size) from its end back before any
 * counter changes for it: a mapped file cut short under the scanner faults here, not in
 * the middle of a record half counted (the record's first bytes were read already). */
static inline void touch(const uint8_t *buf, i64 pos, i64 size) {
    const volatile uint8_t *b = buf;
    for (i64 p = pos + size - 1; p > pos; p -= TOUCH_STEP) (void)b[p];
}

/* Ask for the record after this one, assumed the same size as this one (a cyclic
 * capture's frames mostly are): its first two cache lines (the record, link and EtherCAT
 * headers and the first datagram's header) and its end (the last datagram's WKC, and the
 * byte touch() reads first). The scanner reads only a few lines of each record, too far
 * apart for the hardware's prefetcher, and each one it waits for stalls it: asking one
 * record ahead halves the scan of LOLA-sized frames (benchmarks/capture_throughput.py).
 * A wrong guess costs a cache line; a prefetch never faults, and none goes past end.
 * Always inlined: GCC at -O2 finds a function of prefetches alone "const" and drops its
 * calls (its result is unused). */
static inline __attribute__((always_inline)) void ahead(const uint8_t *buf, i64 pos, i64 size, i64 end) {
    i64 next = pos + size;
    if (next + size > end) return;
    __builtin_prefetch(buf + next);
    __builtin_prefetch(buf + next + 64);
    __builtin_prefetch(buf + next + size - 32);
}

static int full(Tables *t, i64 cap) {
    i64 *st = t->st;
    i64 lim = cap - MAX_DGRAMS - 2;
    if (st[S_N_RT] >= lim || st[S_N_PERIOD] >= lim || st[S_N_BURST] >= lim ||
        st[S_N_DC] >= lim || st[S_N_MBX] >= lim || st[S_N_CFG] >= lim || st[S_N_EVICT] >= lim ||
        st[S_N_CTR] >= lim)
        return ST_FLUSH;
    if (st[S_P_USED] * 2 > t->p_len || st[S_S_USED] * 2 > t->s_len || st[S_W_USED] * 2 > t->w_len)
        return ST_GROW;
    return -1;
}

/* An EPB/OPB/SPB: data offset (-1 when not analysed), captured and original length, ts,
 * link type. */
static i64 pcapng_record(const uint8_t *buf, i64 pos, i64 total, i64 btype, int big,
                         Tables *t, i64 *incl_out, i64 *orig_out, i64 *ts_out, i64 *link_out) {
    i64 *st = t->st;
    const i64 *ifs = t->ifs;
    i64 iface, incl, orig, ts, start;
    if (btype == 3) {
        if (total < 16 || t->n_if == 0) {
            st[S_FRAMES] += 1;
            bad(st);
            return -1;
        }
        orig = u32x(buf, pos + 8, big);
        incl = orig < total - 16 ? orig : total - 16;
        iface = 0;
        ts = st[S_LAST_TS];
        start = pos + 12;
    } else {
        if (total < 32) {
            st[S_FRAMES] += 1;
            bad(st);
            return -1;
        }
        iface = btype == 6 ? u32x(buf, pos + 8, big) : u16x(buf, pos + 8, big);
        i64 hi = u32x(buf, pos + 12, big);
        incl = u32x(buf, pos + 20, big);
        orig = u32x(buf, pos + 24, big);
        start = pos + 28;
        if (28 + incl > total - 4 || iface >= t->n_if) {
            st[S_FRAMES] += 1;
            bad(st);
            return -1;
        }
        ts = TS_BAD;
        if (hi < 0x80000000LL) {
            i64 b = iface * 5;
            i64 units = (hi << 32) | u32x(buf, pos + 16, big);
            ts = ts_ns(units, ifs[b], ifs[b + 1], ifs[b + 2], ifs[b + 3]);
        }
    }
    i64 link = ifs[iface * 5 + 4];
    if (link == 0) {
        st[S_FRAMES] += 1;
        st[S_NONECAT] += 1;
        st[S_NON_ETH] += 1;
        return -1;
    }
    if (ts == TS_BAD) {
        st[S_FRAMES] += 1;
        bad(st);
        return -1;
    }
    *incl_out = incl;
    *orig_out = orig;
    *ts_out = ts;
    *link_out = link;
    return start;
}

/* Walk records from *pos until the buffer ends or the driver must act; returns the
 * status and leaves the position of the next unread record in *pos. *pos is also
 * written before each record, so that after a bus error (see lolacli_scan) it names the
 * record being read. */
static i64 scan_records(const uint8_t *buf, volatile i64 *pos_io, i64 end, i64 eof, i64 fmt,
                        i64 big_, i64 ns_res, Tables *t) {
    int big = big_ != 0;
    i64 pos = *pos_io;
    i64 cap = t->o_len - CHECK_EVERY * (MAX_DGRAMS + 2);
    i64 count = 0;
    i64 *st = t->st;
    i64 pcap_link = t->n_if > 0 ? t->ifs[4] : LINK_ETHERNET;
    for (;;) {
        count += 1;
        *pos_io = pos;
        /* the observation table before every record: one record may add many keys */
        if (count % CHECK_EVERY == 1 || st[S_W_USED] * 2 > t->w_len) {
            int act = full(t, cap);
            if (act >= 0) {
                *pos_io = pos;
                return act;
            }
        }
        i64 d, incl, orig, ts, size, link;
        if (fmt == 0) {
            if (pos + 16 > end) break;
            incl = u32x(buf, pos + 8, big);
            if (incl > MAX_RECORD) {
                *pos_io = pos;
                return ST_CORRUPT;
            }
            size = 16 + incl;
            if (pos + size > end) break;
            ahead(buf, pos, size, end);
            touch(buf, pos, size);
            i64 frac = u32x(buf, pos + 4, big);
            ts = u32x(buf, pos, big) * 1000000000LL + (ns_res ? frac : frac * 1000);
            d = pos + 16;
            orig = u32x(buf, pos + 12, big);
            link = pcap_link;
        } else {
            if (pos + 8 > end) break;
            i64 btype = u32x(buf, pos, big);
            if (btype == 0x0A0D0D0A) {
                *pos_io = pos;
                return ST_BLOCK;
            }
            size = u32x(buf, pos + 4, big);
            if (size < 12 || size % 4 != 0 || size > MAX_RECORD) {
                *pos_io = pos;
                return ST_CORRUPT;
            }
            if (pos + size > end) break;
            if (btype == 1) {
                *pos_io = pos;
                return ST_BLOCK;
            }
            if (btype != 6 && btype != 2 && btype != 3) {
                st[S_SKIPPED] += 1;
                pos += size;
                continue;
            }
            ahead(buf, pos, size, end);
            touch(buf, pos, size);
            d = pcapng_record(buf, pos, size, btype, big, t, &incl, &orig, &ts, &link);
            if (d < 0) {
                pos += size;
                continue;
            }
        }
        packet(buf, d, incl, orig, ts, link, t);
        pos += size;
    }
    *pos_io = pos;
    if (eof) return pos == end ? ST_DONE : ST_CORRUPT;
    return ST_NEED_MORE;
}

/* A mapped file that shrinks while it is read: the pages past its new end are gone, and
 * reading them raises SIGBUS, which would kill the process. lolacli_scan guards the
 * walk: the handler jumps back to it (the fault is synchronous, in this thread, in code
 * that holds no lock and allocates nothing) and it returns ST_FAULT with *pos at the
 * record being read; the driver then takes the file's new size as its end. A SIGBUS
 * outside a guarded walk (another thread, other code) goes to the handler that was
 * there before (Python's faulthandler, or the default: the process ends as before). */
static __thread sigjmp_buf *fault_jump;
static struct sigaction previous_bus;
static int guard_installed;

static void on_bus(int sig, siginfo_t *info, void *ctx) {
    (void)sig, (void)info, (void)ctx;
    sigjmp_buf *jump = fault_jump;
    if (jump != NULL) {
        fault_jump = NULL;
        siglongjmp(*jump, 1);
    }
    /* not a guarded read: back to the previous disposition; the faulting instruction
     * runs again on return and faults into it */
    sigaction(SIGBUS, &previous_bus, NULL);
}

/* Install the SIGBUS handler (once; cengine calls it when it loads the library). 0 when
 * installed. */
i64 lolacli_guard(void) {
    if (guard_installed) return 0;
    struct sigaction sa, now;
    /* already ours (two threads loading the library at once): keep the saved previous
     * handler, never save ours as the one to go back to */
    if (sigaction(SIGBUS, NULL, &now) == 0 && (now.sa_flags & SA_SIGINFO) &&
        now.sa_sigaction == on_bus) {
        guard_installed = 1;
        return 0;
    }
    memset(&sa, 0, sizeof sa);
    sa.sa_sigaction = on_bus;
    sa.sa_flags = SA_SIGINFO;
    sigemptyset(&sa.sa_mask);
    if (sigaction(SIGBUS, &sa, &previous_bus) != 0) return -1;
    guard_installed = 1;
    return 0;
}

i64 lolacli_scan(const uint8_t *buf, i64 *pos_io, i64 end, i64 eof, i64 fmt, i64 big_,
                 i64 ns_res, Tables *t) {
    sigjmp_buf jump;
    volatile i64 *pos = pos_io;
    if (sigsetjmp(jump, 1) != 0) return ST_FAULT; /* *pos: the record that faulted */
    fault_jump = &jump;
    i64 status = scan_records(buf, pos, end, eof, fmt, big_, ns_res, t);
    fault_jump = NULL;
    return status;
}

/* Move the entries of one open-addressing table into a new (empty) one; see scan.rehash.
 * width values per slot (0 for the stream table). */
i64 lolacli_rehash(const i64 *ok, const i64 *on, const i64 *ov, i64 olen, i64 width, i64 *nk,
                   i64 *nn, i64 *nv, i64 nlen, i64 keep_empty) {
    i64 used = 0;
    for (i64 i = 0; i < olen; i++) {
        i64 k = ok[i];
        if (k == 0) continue;
        if (on[i] == 0 && !keep_empty) continue;
        i64 j = slot(nk, nlen, k);
        nk[j] = k;
        nn[j] = on[i];
        for (i64 w = 0; w < width; w++) nv[j * width + w] = ov[i * width + w];
        used += 1;
    }
    return used;
}

/* End of file: close the DC burst. */
void lolacli_finish(i64 *st, i64 *o_burst) {
    if (st[S_DC_BURST] > 0) {
        o_burst[st[S_N_BURST]] = st[S_DC_BURST];
        st[S_N_BURST] += 1;
        st[S_DC_BURST] = 0;
    }
}

/* An importable module, so that the build and the package data find it; the functions
 * above are called through ctypes. */
static struct PyModuleDef cscan_module = {
    PyModuleDef_HEAD_INIT, "_cscan",
    "C kernel of the capture scanner (called through ctypes by lolacli.capture.cengine).",
    -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__cscan(void) { return PyModule_Create(&cscan_module); }
