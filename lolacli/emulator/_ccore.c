/* The chain's cyclic work in C: frame plans, DC time loops, watchdogs and device cycles,
 * for lolacli/emulator/core.py (loaded with ctypes).
 *
 * The Python code is the reference and this file follows it statement for statement:
 *   - FramePlan.run and the work it defers (lolacli/emulator/plan.py),
 *   - system_time_loop, Esc.system_time_ns, Esc.check_watchdog, Esc.cycle
 *     (lolacli/emulator/esc/),
 *   - Device.cycle / unpack_outputs / pack_inputs (lolacli/devices/base.py), the steps of
 *     Cia402Drive (devices/cia402.py) with its kinematic Follower or its JointLoad
 *     (devices/joint_load.py, the cascade of motion/joint.py), DigitalIo, AnalogInput and CanGateway
 *     (devices/io.py; the gateway's CAN bus as its CanSchedule, devices/can.py),
 *   - Chain._run_slots for frames of register reads and writes that only store bytes
 *     (lolacli/emulator/chain.py, esc/controller.py, esc/sm.py, esc/eeprom.py).
 * The tables it runs on are built from the Python objects by core.py and
 * lolacli/devices/flat.py; tests/emulator/test_core.py and tests/devices/test_flat.py
 * compare the two implementations bit for bit.
 *
 * Safety: every table is checked once, when it is built (lolacli_core_check_slave and
 * lolacli_core_check_plan walk it as the executors do and refuse any index or range
 * outside its buffer); the executors then trust the tables. The buffer lengths and row
 * counts themselves are the wrapper's, which takes them from the buffers it allocates. The wrapper bounds every time
 * (|t| < 2^62) and every state value it loads (|x| < 2^62), so sums of two of them never
 * overflow; products of a time with a rate are taken in 128 bits, and the DC arithmetic
 * is done modulo 2^64, which is what Python's masks give.
 */
#include <Python.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#ifndef __SIZEOF_INT128__
#error "the chain core needs 128-bit integers (gcc or clang on a 64-bit target)"
#endif

typedef int64_t i64;
typedef uint64_t u64;
typedef __int128 i128;

#define ABI_VERSION 12
#define MEMORY_BYTES 65536
#define AL_STATUS 0x0130
#define AL_STATE_MASK 0x0F
#define AL_SAFEOP 4
#define AL_OP 8
#define DC_SYSTEM_TIME_OFFSET 0x0920
#define DC_SYSTEM_TIME_DIFFERENCE 0x092C
#define MAX_CORRECTION_NS 1000
#define NS_PER_S 1000000000
#define LIMIT ((i64)1 << 62)
#define PI 3.141592653589793 /* math.pi, the same double */

/* device kinds (lolacli/devices/flat.py) */
enum { K_NONE = 0, K_PYTHON = 1, K_GENERIC = 2, K_CIA402 = 3, K_DIGITAL_IO = 4, K_ANALOG = 5,
       K_CAN_GATEWAY = 6 };

/* CiA 402: the cyclic entries (Cia402Drive.entries order) and their sizes */
enum { E_CW, E_SW, E_MODES, E_MODES_DISPLAY, E_TARGET, E_POSITION, E_VELOCITY,
       E_TARGET_VELOCITY, E_MAX_VELOCITY, E_ERROR, E_TARGET_TORQUE, E_MAX_TORQUE, E_TORQUE,
       E_DEMAND, E_PROFILE_VELOCITY, E_FOLLOWING_ERROR, E_POSITION_OFFSET, E_VELOCITY_OFFSET,
       E_TORQUE_OFFSET, N_CYCLIC };
static const i64 CYCLIC_BYTES[N_CYCLIC] = {2, 2, 1, 1, 4, 4, 4, 4, 4, 2, 2, 2, 2, 4, 4, 4, 4, 4, 2};

/* rows */
#define MAP_WORDS 4     /* image bit, bits, value offset, value bytes */
#define DIO_WORDS 6     /* position, input offset, input bytes, bits, source offset (-1), source bytes */
#define ANALOG_WORDS 6  /* offset, bytes, type (0 integer, 1 REAL32, 2 REAL64), full, offset added, mask */
#define CAN_WORDS 6     /* sensor, value offset, 4, 1 (REAL32), 0, 0; doubles: phase, scale */
/* the gateway's aux table: header, per sensor, then per schedule row its instant and the
 * sample every sensor holds after it (-1: none) */
enum { A_SENSORS, A_HYPER, A_ROWS, A_SPARE, A_HEADER };
enum { S_STATUS, S_STATUS_BYTES, S_COUNTER, S_COUNTER_BYTES, S_SHIFT, S_PERIOD, S_PHASE,
       S_HELD, S_WORDS };
#define CAN_MAX_SENSORS 64

/* One slave: its ESC's cyclic state and its device's. Field order and types are mirrored
 * by core.py's SlaveTable (ctypes); lolacli_core_abi lets it check the layout. */
typedef struct {
    i64 owned;               /* 1: this table holds the ESC's scalars; 0: the Esc object */
    i64 dev_owned;           /* 1: this table holds the device's state; 0: the Device */
    uint8_t *mem;            /* the ESC's memory, MEMORY_BYTES */
    i64 clk_start, clk_drift, clk_corr;
    i64 outputs_valid, last_outputs_ns, now_ns;
    i64 datagrams, cycles;   /* counted here since they were last added to the Esc's */
    i64 wd_timeout;          /* process-data watchdog (ns), < 0: none */
    i64 kind;
    i64 out_start, out_bytes, in_start, in_bytes;
    uint8_t *vals; i64 vals_len;
    i64 *omap; i64 omap_n;
    i64 *imap; i64 imap_n;
    i64 *chan; i64 chan_n;
    double *phase;
    i64 *aux; i64 aux_n;     /* the CAN gateway's sensors and schedule */
    i64 dev_t_ns, power, prev_cw, last_sample, has_last, period;
    double scale;
    i64 e[N_CYCLIC];
    /* CiA 402: the configuration the step reads (Cia402Drive.config): quick stop option
     * code, the decelerations of quick stop and fault reaction (Cia402Drive.ramp), the
     * rated torque 0x6076 */
    i64 qs_option, qs_ramp, fr_ramp, rated_torque;
    /* a drive with a joint: Device.cycle's rest cache (1: at rest with the rest_n bytes of
     * outputs in rest_out, out_bytes long) and the JointLoad (J_WORDS doubles) */
    i64 rest, rest_n;
    uint8_t *rest_out;
    double *joint; i64 joint_n;
} slave_t;

/* One frame plan: the program core.py compiles from a FramePlan, and its buffers. */
typedef struct {
    slave_t *slaves; i64 n_slaves;
    i64 *prog; i64 prog_len;
    uint8_t *buf; i64 buf_len;     /* the frame, answered in place */
    uint8_t *snap; i64 snap_len;   /* datagram copies for deferred writes, BRD caches */
    i64 *pend; i64 pend_len;       /* [0] work pending, [1] its time, then DC values, caches */
} plan_t;

/* program header */
enum { H_MAGIC, H_FRAME_LEN, H_COUNT_K, H_COUNT_DEFERRED, H_N_COUNT, H_N_WATCH, H_WATCH,
       H_N_ADP, H_ADP, H_N_OPS, H_OPS, H_WORDS = 16 };
#define MAGIC 0x4C4F4C41504C414ELL /* "LOLAPLAN" */
enum { OP_LOGICAL = 1, OP_BRD = 2, OP_DC = 3 };
/* op records: [type, words, data offset, data bytes, wkc offset, ...] */
enum { L_FIXED_WKC = 5, L_DEFERRED, L_SNAP, L_N_WRITES, L_N_READS, L_N_EVENTS, L_ROWS };
enum { B_LO = 5, B_N, B_CACHE, B_CACHE_SNAP, B_CACHE_FLAG, B_ROWS };
enum { D_COUNT = 5, D_DEFERRED, D_N_SEGMENTS, D_ROWS };
#define COPY_WORDS 4     /* slave, memory offset, datagram offset, bytes */
#define EVENT_WORDS 2    /* slave, port 0 offset */
#define SEGMENT_WORDS 4  /* reference slave (-1: none), its port 0 offset, others, value slot */
#define OTHER_WORDS 3    /* slave, port 0 offset, offset minus delay registers */

/* ------------------------------------------------------------------ arithmetic */

static inline i128 floordiv(i128 a, i128 b) {
    if (a >= INT64_MIN && a <= INT64_MAX && b >= INT64_MIN && b <= INT64_MAX && b != -1) {
        i64 x = (i64)a, y = (i64)b; /* the usual case, in one 64-bit division */
        i64 q = x / y;
        if (x % y != 0 && ((x < 0) != (y < 0))) q -= 1;
        return q;
    }
    i128 q = a / b;
    if (a % b != 0 && ((a < 0) != (b < 0))) q -= 1;
    return q;
}

static inline i128 floormod(i128 a, i128 b) { return a - floordiv(a, b) * b; }

static inline i64 half_floor(i64 x) { return (x - (x & 1)) / 2; } /* Python's x >> 1 */

static inline u64 get_le(const uint8_t *p, i64 n) {
    u64 v = 0;
    for (i64 i = n - 1; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}

static inline void put_le(uint8_t *p, i64 n, u64 v) {
    for (i64 i = 0; i < n; i++) {
        p[i] = (uint8_t)(v & 0xFF);
        v >>= 8;
    }
}

static inline i64 wrap32(i128 v) { return (i64)(int32_t)(uint32_t)(u64)v; }

/* ------------------------------------------------------------------ DC */

/* DcClock.local_ns + the system time offset register: Esc.system_time_ns, mod 2^64 */
static u64 system_time(const slave_t *s, i64 t) {
    i128 drift = s->clk_drift ? floordiv((i128)t * s->clk_drift, NS_PER_S) : 0;
    u64 offset = get_le(s->mem + DC_SYSTEM_TIME_OFFSET, 8);
    return (u64)t + (u64)drift + (u64)s->clk_start + (u64)s->clk_corr + offset;
}

/* esc.system_time_loop for the others of one segment */
static void time_loop(slave_t *slaves, const i64 *rows, i64 n, u64 value, i64 width, i64 t) {
    u64 half = (u64)1 << (width - 1);
    u64 mask = width == 64 ? ~(u64)0 : ((u64)1 << width) - 1;
    u64 base = (u64)t - value + half;
    for (i64 k = 0; k < n; k++) {
        const i64 *row = rows + k * OTHER_WORDS;
        slave_t *s = &slaves[row[0]];
        i64 offset_ns = row[1];
        u64 x = base + (u64)offset_ns + (u64)s->clk_start + (u64)s->clk_corr + (u64)row[2];
        if (s->clk_drift) x += (u64)floordiv((i128)(t + offset_ns) * s->clk_drift, NS_PER_S);
        i64 diff = width == 64 ? (i64)((x & mask) - half) : (i64)(x & mask) - (i64)half;
        uint8_t *reg = s->mem + DC_SYSTEM_TIME_DIFFERENCE;
        if (diff < 0) {
            put_le(reg, 4, (u64)((diff > -0x7FFFFFFF ? -diff : 0x7FFFFFFF) | 0x80000000LL));
            s->clk_corr -= diff > -2 * MAX_CORRECTION_NS ? half_floor(diff) : -MAX_CORRECTION_NS;
        } else {
            put_le(reg, 4, (u64)(diff < 0x7FFFFFFF ? diff : 0x7FFFFFFF));
            s->clk_corr -= diff < 2 * MAX_CORRECTION_NS ? half_floor(diff) : MAX_CORRECTION_NS;
        }
    }
}

/* ------------------------------------------------------------------ devices */

/* OR ``bits`` bits of src (LSB first, zero past src_len bytes) into img at bit ``at``
 * (Device.pack_inputs: img starts zeroed, mapped ranges do not overlap) */
static void put_bits(uint8_t *img, i64 at, const uint8_t *src, i64 src_len, i64 bits) {
    if ((at & 7) == 0 && (bits & 7) == 0 && bits / 8 <= src_len) {
        memcpy(img + at / 8, src, (size_t)(bits / 8));
        return;
    }
    i64 have = 8 * src_len < bits ? 8 * src_len : bits;
    for (i64 b = 0; b < have; b++)
        if ((src[b >> 3] >> (b & 7)) & 1) img[(at + b) >> 3] |= (uint8_t)(1 << ((at + b) & 7));
}

/* dst (dst_len bytes) = ``bits`` bits of img from bit ``at``, zero-extended
 * (Device.unpack_outputs) */
static void get_bits(uint8_t *dst, i64 dst_len, const uint8_t *img, i64 at, i64 bits) {
    memset(dst, 0, (size_t)dst_len);
    if ((at & 7) == 0 && (bits & 7) == 0) {
        memcpy(dst, img + at / 8, (size_t)(bits / 8));
        return;
    }
    for (i64 b = 0; b < bits; b++)
        if ((img[(at + b) >> 3] >> ((at + b) & 7)) & 1) dst[b >> 3] |= (uint8_t)(1 << (b & 7));
}

/* CiA 402-2 power states (Cia402State) and commands (Command) */
enum { NOT_READY = 0x0000, SWITCH_ON_DISABLED = 0x0040, READY_TO_SWITCH_ON = 0x0021,
       SWITCHED_ON = 0x0023, OPERATION_ENABLED = 0x0027, QUICK_STOP_ACTIVE = 0x0007,
       FAULT_REACTION_ACTIVE = 0x000F, FAULT = 0x0008 };
enum { C_NONE, C_SHUTDOWN, C_SWITCH_ON, C_ENABLE_OPERATION, C_DISABLE_VOLTAGE, C_QUICK_STOP,
       C_DISABLE_OPERATION, C_FAULT_RESET };

static int decode_controlword(i64 cw, i64 previous) {
    if ((cw & 0x80) && !(previous & 0x80)) return C_FAULT_RESET;
    if ((cw & 0x02) == 0) return C_DISABLE_VOLTAGE;
    if ((cw & 0x06) == 0x02) return C_QUICK_STOP;
    if ((cw & 0x07) == 0x06) return C_SHUTDOWN;
    if ((cw & 0x0F) == 0x07) return (previous & 0x0F) != 0x0F ? C_SWITCH_ON : C_DISABLE_OPERATION;
    if ((cw & 0x0F) == 0x0F) return C_ENABLE_OPERATION;
    return C_NONE;
}

/* next_state: ``option`` the quick stop option code, ``stopped`` whether the ramp of quick
 * stop or fault reaction has come to rest */
static i64 next_state(i64 state, int command, i64 option, int stopped) {
    if (state == NOT_READY) return SWITCH_ON_DISABLED;
    if (state == FAULT_REACTION_ACTIVE) return stopped ? FAULT : state;
    if (state == QUICK_STOP_ACTIVE) {
        if (command == C_DISABLE_VOLTAGE) return SWITCH_ON_DISABLED;
        if (option >= 5 && option <= 8) /* stays in quick stop active */
            return command == C_ENABLE_OPERATION ? OPERATION_ENABLED : state;
        return stopped ? SWITCH_ON_DISABLED : state;
    }
    if (command == C_NONE) return state;
    switch (state) {
    case SWITCH_ON_DISABLED:
        if (command == C_SHUTDOWN) return READY_TO_SWITCH_ON;
        break;
    case READY_TO_SWITCH_ON:
        if (command == C_SWITCH_ON) return SWITCHED_ON;
        if (command == C_ENABLE_OPERATION) return OPERATION_ENABLED;
        if (command == C_DISABLE_VOLTAGE || command == C_QUICK_STOP) return SWITCH_ON_DISABLED;
        break;
    case SWITCHED_ON:
        if (command == C_ENABLE_OPERATION) return OPERATION_ENABLED;
        if (command == C_SHUTDOWN) return READY_TO_SWITCH_ON;
        if (command == C_DISABLE_VOLTAGE || command == C_QUICK_STOP) return SWITCH_ON_DISABLED;
        break;
    case OPERATION_ENABLED:
        if (command == C_DISABLE_OPERATION || command == C_SWITCH_ON) return SWITCHED_ON;
        if (command == C_SHUTDOWN) return READY_TO_SWITCH_ON;
        if (command == C_DISABLE_VOLTAGE) return SWITCH_ON_DISABLED;
        if (command == C_QUICK_STOP) return QUICK_STOP_ACTIVE;
        break;
    case FAULT:
        if (command == C_FAULT_RESET) return SWITCH_ON_DISABLED;
        break;
    }
    return state;
}

static i64 status_bits(i64 state) {
    i64 status = state | 0x0200;
    if (state == READY_TO_SWITCH_ON || state == SWITCHED_ON || state == OPERATION_ENABLED ||
        state == QUICK_STOP_ACTIVE)
        status |= 0x0010;
    if (state == OPERATION_ENABLED) status |= 0x1000;
    return status;
}

static inline i128 tighter(i128 a, i128 b) { return a && b ? (a < b ? a : b) : (a ? a : b); }

/* ---- the joint behind a drive: JointLoad.follow and Cascade.run, operation for operation
 * (the same doubles: no contraction, libm's sin and tanh as Python's math) */

/* the JointLoad's doubles: the cascade's constants in Cascade._c order, the load's own,
 * then its state (flat.py writes and reads them) */
enum { J_P00, J_P01, J_P02, J_P10, J_P11, J_P12, J_P20, J_P21, J_P22, J_G0V, J_G0T, J_G1V,
       J_G1T, J_G2V, J_G2T, J_KP, J_KV, J_KPC, J_IMAX, J_VMAX, J_FC, J_WS, J_GRAV, J_KVI_TP,
       J_KCI_TC, J_KVEL_FF, J_SCALE, J_INERTIA_PER_A, J_GRAVITY_PER_A, J_EMF, J_TORQUE_PER_A,
       J_RATED, J_CUR, J_THETA, J_OMEGA, J_VINT, J_IINT, J_REF, J_REF_V, J_FF, J_PENDING,
       J_HAS_LAST, J_LAST_POS, J_LAST_VEL, J_TORQUE, J_WORDS };
#define POSITION_PERIOD_NS 100000 /* motion/joint.py; the current loop runs twice in one */
enum { L_POSITION, L_VELOCITY, L_TORQUE, L_STOP };

/* Python's min(a, b) and max(a, b) of two floats: the first unless the second is less
 * (greater) */
static inline double py_min(double a, double b) { return b < a ? b : a; }
static inline double py_max(double a, double b) { return b > a ? b : a; }

/* Cascade.run over ``periods`` control periods on the held targets */
static void cascade_run(double *j, i64 periods, double target, double vel, double ff,
                        int current_only) {
    const double p00 = j[J_P00], p01 = j[J_P01], p02 = j[J_P02], p10 = j[J_P10],
                 p11 = j[J_P11], p12 = j[J_P12], p20 = j[J_P20], p21 = j[J_P21],
                 p22 = j[J_P22], g0v = j[J_G0V], g0t = j[J_G0T], g1v = j[J_G1V],
                 g1t = j[J_G1T], g2v = j[J_G2V], g2t = j[J_G2T], kp = j[J_KP], kv = j[J_KV],
                 kpc = j[J_KPC], imax = j[J_IMAX], vmax = j[J_VMAX], fc = j[J_FC],
                 ws = j[J_WS], grav = j[J_GRAV], kvi_tp = j[J_KVI_TP], kci_tc = j[J_KCI_TC],
                 kvel_ff = j[J_KVEL_FF];
    double cur = j[J_CUR], th = j[J_THETA], w = j[J_OMEGA], vint = j[J_VINT], iint = j[J_IINT];
    for (i64 n = 0; n < periods; n++) {
        double icmd;
        if (current_only) {
            icmd = ff;
            if (icmd > imax) icmd = imax;
            else if (icmd < -imax) icmd = -imax;
        } else {
            double ev = kp * (target - th) + kvel_ff * vel - w;
            icmd = kv * ev + vint + ff;
            if (icmd > imax) icmd = imax;
            else if (icmd < -imax) icmd = -imax;
            else vint += kvi_tp * ev;
        }
        for (int k = 0; k < 2; k++) {
            double ei = icmd - cur;
            double volts = kpc * ei + iint;
            if (volts > vmax) volts = vmax;
            else if (volts < -vmax) volts = -vmax;
            else iint += kci_tc * ei;
            double tau = fc * tanh(w / ws) + grav * sin(th);
            double c1 = p00 * cur + p01 * th + p02 * w + g0v * volts + g0t * tau;
            double t1 = p10 * cur + p11 * th + p12 * w + g1v * volts + g1t * tau;
            double w1 = p20 * cur + p21 * th + p22 * w + g2v * volts + g2t * tau;
            cur = c1;
            th = t1;
            w = w1;
        }
    }
    j[J_CUR] = cur;
    j[J_THETA] = th;
    j[J_OMEGA] = w;
    j[J_VINT] = vint;
    j[J_IINT] = iint;
}

/* JointLoad.last after a step: round(θ scale), round(ω scale) (half to even, as Python's
 * round); where one is not finite, none (Python raises there; here the next step starts
 * again from the actual values) */
static void joint_measure(double *j, double *position, double *velocity) {
    double p = nearbyint(j[J_THETA] * j[J_SCALE]), v = nearbyint(j[J_OMEGA] * j[J_SCALE]);
    j[J_HAS_LAST] = isfinite(p) && isfinite(v) ? 1.0 : 0.0;
    j[J_LAST_POS] = p;
    j[J_LAST_VEL] = v;
    *position = p;
    *velocity = v;
}

/* JointLoad.follow: the new position and velocity (integers, as doubles) */
static void joint_follow(double *j, int kind, i64 demand, i64 position, i64 velocity,
                         i64 limit, i64 dt, double *new_position, double *new_velocity) {
    double scale = j[J_SCALE];
    if (!(j[J_HAS_LAST] != 0.0 && j[J_LAST_POS] == (double)position &&
          j[J_LAST_VEL] == (double)velocity)) {
        j[J_THETA] = (double)position / scale; /* Cascade.reset */
        j[J_OMEGA] = 0.0;
        j[J_CUR] = 0.0;
        j[J_VINT] = 0.0;
        j[J_IINT] = j[J_EMF] * 0.0;
        j[J_REF] = (double)position / scale;
        j[J_REF_V] = (double)velocity / scale;
        j[J_PENDING] = 0.0;
        j[J_FF] = j[J_GRAVITY_PER_A] * sin(j[J_REF]);
        j[J_TORQUE] = 0.0;
    }
    if (dt <= 0) {
        j[J_HAS_LAST] = 1.0;
        j[J_LAST_POS] = *new_position = (double)position;
        j[J_LAST_VEL] = *new_velocity = (double)velocity;
        return;
    }
    i64 total = (i64)j[J_PENDING] + dt;
    i64 periods = total / POSITION_PERIOD_NS; /* both >= 0 */
    j[J_PENDING] = (double)(total % POSITION_PERIOD_NS);
    double ref = j[J_REF], ref_v = j[J_REF_V];
    if (periods) cascade_run(j, periods, ref, ref_v, j[J_FF], j[J_TORQUE] != 0.0);
    if (kind == L_TORQUE) {
        i64 rated = limit ? limit : (i64)j[J_RATED];
        j[J_FF] = (double)(demand * rated) / 1e6 / j[J_TORQUE_PER_A];
        j[J_TORQUE] = 1.0;
        joint_measure(j, new_position, new_velocity);
        return;
    }
    if (j[J_TORQUE] != 0.0) {
        ref = j[J_THETA];
        ref_v = j[J_OMEGA];
        j[J_TORQUE] = 0.0;
    }
    double dt_s = (double)dt * 1e-9, v;
    if (kind == L_POSITION) {
        double target = (double)demand / scale;
        if (limit) {
            double step = (double)limit * dt_s / scale;
            target = py_max(ref - step, py_min(ref + step, target));
        }
        v = (target - ref) / dt_s;
        ref = target;
    } else if (kind == L_VELOCITY) {
        v = (double)demand / scale;
        ref += v * dt_s;
    } else {
        double step = limit ? (double)limit * dt_s / scale : INFINITY;
        v = py_max(0.0, fabs(ref_v) - step);
        v = ref_v > 0 ? v : -v;
        ref += v * dt_s;
    }
    j[J_FF] = j[J_INERTIA_PER_A] * (v - ref_v) / dt_s + j[J_GRAVITY_PER_A] * sin(ref);
    j[J_REF] = ref;
    j[J_REF_V] = v;
    joint_measure(j, new_position, new_velocity);
}

/* _int32 of an integer held in a double (exact: fmod is); 0 where it is not finite */
static i64 wrap32d(double x) {
    if (!isfinite(x)) return 0;
    return wrap32((i128)(i64)fmod(x, 4294967296.0));
}

static inline int int32_range(double x) { return x >= -2147483648.0 && x <= 2147483647.0; }

/* Follower.follow for a stop: the ramp at ``limit`` (0: at once) */
static void follower_stop(i128 actual, i128 velocity, i128 limit, i64 dt, i128 *new_position,
                          i128 *new_velocity) {
    if (!limit || !dt) {
        *new_position = actual;
        *new_velocity = 0;
        return;
    }
    i128 step = floordiv(limit * dt, NS_PER_S);
    if (step < 1) step = 1;
    i128 speed = (velocity < 0 ? -velocity : velocity) - step;
    if (speed < 0) speed = 0;
    i128 v = velocity > 0 ? speed : -speed;
    *new_position = actual + floordiv(v * dt, NS_PER_S);
    *new_velocity = v;
}

/* Cia402Drive.step with the kinematic Follower or a JointLoad, for the configurations
 * core_can_run admits (no following-error monitor, software limits or max motor speed) */
static void cia402_step(slave_t *s, i64 t) {
    uint8_t *v = s->vals;
    const i64 *e = s->e;
    double *joint = s->joint;
    i64 cw = (i64)get_le(v + e[E_CW], 2);
    i64 previous = s->prev_cw;
    s->prev_cw = cw;
    i128 actual = (int32_t)(uint32_t)get_le(v + e[E_POSITION], 4);
    i64 actual_velocity = (int32_t)(uint32_t)get_le(v + e[E_VELOCITY], 4);
    i64 state = s->power;
    int stopping = state == QUICK_STOP_ACTIVE || state == FAULT_REACTION_ACTIVE;
    i64 ramp = state == QUICK_STOP_ACTIVE ? s->qs_ramp : s->fr_ramp;
    int stopped = actual_velocity == 0 || (stopping && ramp == 0);
    i64 power = s->power =
        next_state(state, decode_controlword(cw, previous), s->qs_option, stopped);
    if (power == SWITCH_ON_DISABLED && get_le(v + e[E_ERROR], 2) != 0) put_le(v + e[E_ERROR], 2, 0);
    v[e[E_MODES_DISPLAY]] = v[e[E_MODES]];
    i64 dt = s->dev_t_ns ? t - s->dev_t_ns : 0;
    i64 mode = (int8_t)v[e[E_MODES]];
    i128 target = actual, velocity = 0, demand = actual;
    double jp = 0.0, jv = 0.0; /* the joint's new position and velocity */
    i64 torque = 0, reached = 0, limited = 0;
    if (power == OPERATION_ENABLED) {
        i128 limit = (i128)get_le(v + e[E_MAX_VELOCITY], 4);
        if (mode == 8 || mode == 1) { /* CSP, PP */
            if (mode == 8) {
                demand = (i128)(int32_t)(uint32_t)get_le(v + e[E_TARGET], 4) +
                         (int32_t)(uint32_t)get_le(v + e[E_POSITION_OFFSET], 4);
            } else {
                demand = (int32_t)(uint32_t)get_le(v + e[E_DEMAND], 4);
                if ((cw & 0x10) && !(previous & 0x10)) {
                    i128 goal = (int32_t)(uint32_t)get_le(v + e[E_TARGET], 4);
                    demand = (cw & 0x40) ? demand + goal : goal;
                }
                limit = tighter((i128)get_le(v + e[E_PROFILE_VELOCITY], 4), limit);
            }
            demand = wrap32(demand);
            if (mode == 1 && (cw & 0x100)) {
                target = actual; /* halt */
            } else if (joint) {
                joint_follow(joint, L_POSITION, (i64)demand, (i64)actual, actual_velocity,
                             (i64)limit, dt, &jp, &jv);
                target = wrap32d(jp); /* beyond int32 Python's pack raises */
                velocity = wrap32d(jv);
                reached = jp == (double)demand;
            } else {
                target = demand;
                if (limit && dt) {
                    i128 step = floordiv(limit * dt, NS_PER_S);
                    if (step < 1) step = 1;
                    i128 move = demand - actual;
                    if (move > step) move = step;
                    if (move < -step) move = -step;
                    target = actual + move;
                }
                velocity = dt > 0 ? floordiv((target - actual) * NS_PER_S, dt) : 0;
            }
            reached = reached || target == demand || (mode == 1 && (cw & 0x100));
        } else {
            if (mode == 9) { /* CSV */
                i128 want = (i128)(int32_t)(uint32_t)get_le(v + e[E_TARGET_VELOCITY], 4) +
                            (int32_t)(uint32_t)get_le(v + e[E_VELOCITY_OFFSET], 4);
                if (limit) want = want > limit ? limit : (want < -limit ? -limit : want);
                if (joint) {
                    joint_follow(joint, L_VELOCITY, (i64)want, (i64)actual, actual_velocity,
                                 (i64)limit, dt, &jp, &jv);
                    reached = jv == (double)want;
                } else {
                    target = actual + floordiv(want * dt, NS_PER_S);
                    velocity = dt > 0 ? floordiv((target - actual) * NS_PER_S, dt) : 0;
                    reached = velocity == want;
                }
            } else if (mode == 10) { /* CST: the follower holds still, a joint moves */
                i64 want = (i64)(int16_t)(uint16_t)get_le(v + e[E_TARGET_TORQUE], 2) +
                           (int16_t)(uint16_t)get_le(v + e[E_TORQUE_OFFSET], 2);
                i64 most = (i64)get_le(v + e[E_MAX_TORQUE], 2);
                if (most && (want > most || want < -most)) {
                    want = want > most ? most : -most;
                    limited = 1;
                }
                torque = (int16_t)(uint16_t)(u64)want;
                if (joint)
                    joint_follow(joint, L_TORQUE, torque, (i64)actual, actual_velocity,
                                 s->rated_torque, dt, &jp, &jv);
                reached = 1;
            }
            if (joint && (mode == 9 || mode == 10)) {
                if (int32_range(jp)) {
                    target = (i128)jp;
                    velocity = wrap32d(jv);
                } else { /* beyond the position limits: held there (no software limits) */
                    target = jp > 0 ? INT32_MAX : INT32_MIN;
                    velocity = 0;
                    limited = 1;
                }
            } else if (target < INT32_MIN || target > INT32_MAX) {
                target = target > 0 ? INT32_MAX : INT32_MIN;
                velocity = 0;
                limited = 1;
            }
            target = demand = wrap32(target);
        }
    } else if (power == QUICK_STOP_ACTIVE || power == FAULT_REACTION_ACTIVE) {
        i64 slope = power == QUICK_STOP_ACTIVE ? s->qs_ramp : s->fr_ramp;
        if (joint) {
            joint_follow(joint, L_STOP, 0, (i64)actual, actual_velocity, slope, dt, &jp, &jv);
            target = wrap32d(jp);
            velocity = wrap32d(jv);
        } else {
            follower_stop(actual, actual_velocity, slope, dt, &target, &velocity);
        }
        target = demand = wrap32(target);
    }
    put_le(v + e[E_POSITION], 4, (u64)wrap32(target));
    put_le(v + e[E_VELOCITY], 4, (u64)wrap32(velocity));
    put_le(v + e[E_TORQUE], 2, (u64)torque);
    put_le(v + e[E_DEMAND], 4, (u64)wrap32(demand));
    put_le(v + e[E_FOLLOWING_ERROR], 4, (u64)wrap32(demand - target));
    i64 status = status_bits(power);
    if (power == OPERATION_ENABLED) {
        if (mode == 1) status = (status & ~0x1000) | ((cw & 0x10) ? 0x1000 : 0);
        if (reached) status |= 0x0400;
    }
    if (limited) status |= 0x0800;
    put_le(v + e[E_SW], 2, (u64)status);
}

/* Cia402Drive.at_rest after a step (for the configurations core_can_run admits) */
static int cia402_at_rest(const slave_t *s) {
    i64 power = s->power;
    if (power == NOT_READY || power == FAULT_REACTION_ACTIVE) return 0;
    i64 cw = s->prev_cw;
    if (next_state(power, decode_controlword(cw, cw), s->qs_option, 1) != power) return 0;
    const uint8_t *v = s->vals;
    const i64 *e = s->e;
    if (get_le(v + e[E_VELOCITY], 4) != 0) return 0;
    if (power != OPERATION_ENABLED) return 1;
    i64 mode = (int8_t)v[e[E_MODES]];
    if (mode == 9)
        return get_le(v + e[E_TARGET_VELOCITY], 4) == 0 && get_le(v + e[E_VELOCITY_OFFSET], 4) == 0;
    if (mode == 8 || mode == 1)
        return get_le(v + e[E_POSITION], 4) == get_le(v + e[E_DEMAND], 4) &&
               (mode == 1 || (get_le(v + e[E_POSITION_OFFSET], 4) == 0 &&
                              get_le(v + e[E_DEMAND], 4) == get_le(v + e[E_TARGET], 4)));
    if (mode == 10) return !s->joint; /* a torque moves a joint */
    return 1;
}

static inline u64 low_mask(i64 bits) { return bits >= 64 ? ~(u64)0 : ((u64)1 << bits) - 1; }

static void digital_io_step(slave_t *s, i64 t) {
    i64 pattern = (i64)1 << (i64)floormod(floordiv(t, 10000000), 8);
    for (i64 k = 0; k < s->chan_n; k++) {
        const i64 *row = s->chan + k * DIO_WORDS;
        i64 bits = row[3];
        u64 value;
        if (row[4] >= 0) {
            i64 n = row[5] < 8 ? row[5] : 8;
            value = get_le(s->vals + row[4], n);
        } else {
            value = bits == 1 ? (u64)((pattern >> (row[0] % 8)) & 1) : (u64)pattern;
        }
        put_le(s->vals + row[1], row[2], value & low_mask(bits));
    }
}

static void analog_step(slave_t *s, i64 t) {
    i64 sample = (i64)floordiv(t, s->period);
    if (s->has_last && sample == s->last_sample) return;
    s->last_sample = sample;
    s->has_last = 1;
    double angle = 2 * PI * ((double)t / 1e9);
    for (i64 k = 0; k < s->chan_n; k++) {
        const i64 *row = s->chan + k * ANALOG_WORDS;
        double x = sin(angle + s->phase[k]);
        uint8_t *at = s->vals + row[0];
        if (row[2] == 1) {
            float f = (float)(x * s->scale);
            memcpy(at, &f, 4);
        } else if (row[2] == 2) {
            double d = x * s->scale;
            memcpy(at, &d, 8);
        } else {
            i64 r = (i64)rint(x * (double)row[3] * 0.5);
            put_le(at, row[1], ((u64)r + (u64)row[4]) & (u64)row[5]);
        }
    }
}

/* CanGateway.step: each sensor's sample at t from the schedule (CanSchedule.held_at),
 * written as CanGateway._write does when it is not the one held */
static void can_step(slave_t *s, i64 t) {
    i64 *a = s->aux;
    i64 n_sensors = a[A_SENSORS], hyper = a[A_HYPER], n_rows = a[A_ROWS];
    i64 *sensor = a + A_HEADER;
    const i64 *rows = sensor + n_sensors * S_WORDS;
    i64 width = 1 + n_sensors;
    i128 q = 0;
    i64 local = t;
    if (t >= 3 * hyper) {
        q = floordiv(t, hyper) - 2;
        local = (i64)(t - q * hyper);
    }
    i64 lo = 0, hi = n_rows; /* the rows at or before local: [0, lo) */
    while (lo < hi) {
        i64 mid = lo + (hi - lo) / 2;
        if (rows[mid * width] <= local) lo = mid + 1;
        else hi = mid;
    }
    if (lo == 0) return; /* nothing arrived yet */
    const i64 *row = rows + (lo - 1) * width;
    for (i64 i = 0; i < n_sensors; i++) {
        i64 *w = sensor + i * S_WORDS;
        i64 k = row[1 + i];
        if (k < 0) continue;
        k = (i64)(k + q * w[S_SHIFT]);
        if (k == w[S_HELD]) continue;
        w[S_HELD] = k;
        if (w[S_STATUS] >= 0 && s->vals[w[S_STATUS]] != 1) put_le(s->vals + w[S_STATUS], w[S_STATUS_BYTES], 1);
        if (w[S_COUNTER] >= 0) put_le(s->vals + w[S_COUNTER], w[S_COUNTER_BYTES], (u64)(k + 1) & 0xFFFF);
        i128 instant = (i128)w[S_PHASE] + (i128)k * w[S_PERIOD];
        double ts = (double)(i64)floormod(instant, NS_PER_S) / 1e9;
        for (i64 c = 0; c < s->chan_n; c++) {
            const i64 *ch = s->chan + c * CAN_WORDS;
            if (ch[0] != i) continue;
            float f = (float)(s->phase[2 * c + 1] * sin(2 * PI * ts + s->phase[2 * c]));
            memcpy(s->vals + ch[1], &f, 4);
        }
    }
}

/* Esc.cycle + Device.cycle for one slave whose table holds its state */
static void slave_cycle(slave_t *s, i64 t) {
    int state = s->mem[AL_STATUS] & AL_STATE_MASK;
    if (state != AL_SAFEOP && state != AL_OP) return;
    s->cycles += 1;
    const uint8_t *outputs = s->mem + s->out_start;
    i64 n_out = state == AL_OP && s->out_bytes ? s->out_bytes : 0;
    /* a drive with a joint keeps Device.cycle's rest cache: at rest, the same outputs
     * (and no write to its dictionary: Python would have it back) skip the step */
    int rests = s->joint && s->rest && s->rest_n == n_out &&
                (n_out == 0 || memcmp(s->rest_out, outputs, (size_t)n_out) == 0);
    if (!rests) {
        for (i64 k = 0; k < (n_out ? s->omap_n : 0); k++) {
            const i64 *row = s->omap + k * MAP_WORDS;
            get_bits(s->vals + row[2], row[3], outputs, row[0], row[1]);
        }
        if (s->kind == K_CIA402) cia402_step(s, t);
        else if (s->kind == K_DIGITAL_IO) digital_io_step(s, t);
        else if (s->kind == K_ANALOG) analog_step(s, t);
        else if (s->kind == K_CAN_GATEWAY) can_step(s, t);
        if (s->joint) {
            s->rest = cia402_at_rest(s);
            s->rest_n = s->rest ? n_out : 0;
            if (s->rest && n_out) memcpy(s->rest_out, outputs, (size_t)n_out);
        }
    }
    s->dev_t_ns = t;
    if (s->in_bytes) {
        uint8_t *image = s->mem + s->in_start;
        memset(image, 0, (size_t)s->in_bytes);
        for (i64 k = 0; k < s->imap_n; k++) {
            const i64 *row = s->imap + k * MAP_WORDS;
            put_bits(image, row[0], s->vals + row[2], row[3], row[1]);
        }
    }
}

/* The application cycle of the first n slaves (Chain.run_deferred_cycles), for those
 * whose tables hold their device's state; the rest run in Python. (The cycle uses no
 * ESC scalar but the cycle counter, which both sides add to.) */
void lolacli_core_cycles(slave_t *slaves, i64 n, i64 t) {
    for (i64 i = 0; i < n; i++) {
        slave_t *s = &slaves[i];
        if (s->dev_owned && s->kind >= K_GENERIC) slave_cycle(s, t);
    }
}

/* Esc.check_watchdog without its effect: the first of the first n slaves (held here)
 * whose process-data watchdog would expire at t, or -1. */
i64 lolacli_core_watchdog(slave_t *slaves, i64 n, i64 t) {
    for (i64 i = 0; i < n; i++) {
        slave_t *s = &slaves[i];
        if (s->owned && s->mem[AL_STATUS] == AL_OP && s->wd_timeout >= 0 &&
            t - s->last_outputs_ns > s->wd_timeout)
            return i;
    }
    return -1;
}

/* ------------------------------------------------------------------ frame plans */

static void events(slave_t *slaves, const i64 *rows, i64 n, i64 t) {
    for (i64 k = 0; k < n; k++) {
        slave_t *s = &slaves[rows[k * EVENT_WORDS]];
        s->now_ns = t + rows[k * EVENT_WORDS + 1];
        s->outputs_valid = 1;
        s->last_outputs_ns = s->now_ns;
    }
}

static void copies_in(slave_t *slaves, const i64 *rows, i64 n, const uint8_t *data) {
    for (i64 k = 0; k < n; k++) {
        const i64 *row = rows + k * COPY_WORDS;
        memcpy(slaves[row[0]].mem + row[1], data + row[2], (size_t)row[3]);
    }
}

static void count(plan_t *p) {
    const i64 *h = p->prog;
    for (i64 i = 0; i < h[H_N_COUNT]; i++) p->slaves[i].datagrams += h[H_COUNT_K];
}

/* FramePlan.run: the frame answered in p->buf; what waits for later is marked in p->pend.
 * Returns 1 when a slave's watchdog would expire (Python then runs the checks). */
i64 lolacli_core_answer(plan_t *p, const uint8_t *frame, i64 frame_len, i64 t) {
    const i64 *h = p->prog;
    if (frame_len != h[H_FRAME_LEN] || p->pend[0]) return -1;
    uint8_t *buf = p->buf;
    slave_t *slaves = p->slaves;
    memcpy(buf, frame, (size_t)frame_len);
    i64 pending = 0;
    if (h[H_COUNT_DEFERRED]) pending = 1;
    else count(p);
    const i64 *op = p->prog + h[H_OPS];
    for (i64 k = 0; k < h[H_N_OPS]; k++, op += op[1]) {
        uint8_t *data = buf + op[2];
        i64 length = op[3];
        i64 added = 0;
        if (op[0] == OP_LOGICAL) {
            const i64 *writes = op + L_ROWS;
            const i64 *reads = writes + op[L_N_WRITES] * COPY_WORDS;
            const i64 *evs = reads + op[L_N_READS] * COPY_WORDS;
            if (op[L_DEFERRED]) {
                memcpy(p->snap + op[L_SNAP], data, (size_t)length);
                pending = 1;
            } else {
                copies_in(slaves, writes, op[L_N_WRITES], data);
                events(slaves, evs, op[L_N_EVENTS], t);
            }
            for (i64 r = 0; r < op[L_N_READS]; r++) {
                const i64 *row = reads + r * COPY_WORDS;
                memcpy(data + row[2], slaves[row[0]].mem + row[1], (size_t)row[3]);
            }
            added = op[L_FIXED_WKC];
        } else if (op[0] == OP_BRD) {
            uint8_t *merged = p->snap + op[B_CACHE_SNAP];
            if (!(op[B_CACHE] && p->pend[op[B_CACHE_FLAG]])) {
                memset(merged, 0, (size_t)length);
                for (i64 r = 0; r < op[B_N]; r++) {
                    const uint8_t *src = slaves[op[B_ROWS + r]].mem + op[B_LO];
                    for (i64 b = 0; b < length; b++) merged[b] |= src[b];
                }
                if (op[B_CACHE]) p->pend[op[B_CACHE_FLAG]] = 1;
            }
            for (i64 b = 0; b < length; b++) data[b] |= merged[b];
            added = op[B_N];
        } else { /* OP_DC */
            const i64 *seg = op + D_ROWS;
            const i64 *others = seg + op[D_N_SEGMENTS] * SEGMENT_WORDS;
            u64 value = get_le(data, length);
            for (i64 g = 0; g < op[D_N_SEGMENTS]; g++, seg += SEGMENT_WORDS) {
                if (seg[0] >= 0) {
                    put_le(data, length, system_time(&slaves[seg[0]], t + seg[1]));
                    value = get_le(data, length);
                }
                if (seg[2] == 0) continue;
                if (op[D_DEFERRED]) {
                    p->pend[seg[3]] = (i64)value;
                    pending = 1;
                } else {
                    time_loop(slaves, others, seg[2], value, 8 * length, t);
                }
                others += seg[2] * OTHER_WORDS;
            }
            added = op[D_COUNT];
        }
        if (added) {
            uint8_t *w = buf + op[4];
            put_le(w, 2, (get_le(w, 2) + (u64)added) & 0xFFFF);
        }
    }
    const i64 *adp = p->prog + h[H_ADP];
    for (i64 k = 0; k < h[H_N_ADP]; k++) put_le(buf + adp[2 * k], 2, (u64)adp[2 * k + 1]);
    buf[6] |= 0x02; /* SOURCE_MAC_LOCAL_BIT */
    if (pending) {
        p->pend[0] = 1;
        p->pend[1] = t;
    }
    const i64 *watch = p->prog + h[H_WATCH];
    for (i64 k = 0; k < h[H_N_WATCH]; k++) {
        slave_t *s = &slaves[watch[k]];
        if (s->mem[AL_STATUS] == AL_OP && s->wd_timeout >= 0 && t - s->last_outputs_ns > s->wd_timeout)
            return 1;
    }
    return 0;
}

/* The work FramePlan.run left in the chain's deferred list, in its order: the datagram
 * counters, then per op the writes from the datagram copy with their outputs events and
 * the DC time loops. */
void lolacli_core_finish(plan_t *p) {
    if (!p->pend[0]) return;
    const i64 *h = p->prog;
    i64 t = p->pend[1];
    slave_t *slaves = p->slaves;
    p->pend[0] = 0;
    if (h[H_COUNT_DEFERRED]) count(p);
    const i64 *op = p->prog + h[H_OPS];
    for (i64 k = 0; k < h[H_N_OPS]; k++, op += op[1]) {
        if (op[0] == OP_LOGICAL && op[L_DEFERRED]) {
            const i64 *writes = op + L_ROWS;
            const i64 *evs = writes + (op[L_N_WRITES] + op[L_N_READS]) * COPY_WORDS;
            copies_in(slaves, writes, op[L_N_WRITES], p->snap + op[L_SNAP]);
            events(slaves, evs, op[L_N_EVENTS], t);
        } else if (op[0] == OP_DC && op[D_DEFERRED]) {
            const i64 *seg = op + D_ROWS;
            const i64 *others = seg + op[D_N_SEGMENTS] * SEGMENT_WORDS;
            for (i64 g = 0; g < op[D_N_SEGMENTS]; g++, seg += SEGMENT_WORDS) {
                if (seg[2] == 0) continue;
                time_loop(slaves, others, seg[2], (u64)p->pend[seg[3]], 8 * op[3], t);
                others += seg[2] * OTHER_WORDS;
            }
        }
    }
}

/* answer, and when it returns 0 the work it left (finish) and the application cycle of
 * the first n slaves (cycles) at t: Chain.process of a logical frame whose deferred
 * work and cycle run right after its answer, in one call. Not 0: only answer ran (n out
 * of range: nothing ran, -2). */
i64 lolacli_core_answer_cycles(plan_t *p, const uint8_t *frame, i64 frame_len, i64 t, i64 n) {
    if (n < 0 || n > p->n_slaves) return -2;
    i64 code = lolacli_core_answer(p, frame, frame_len, t);
    if (code != 0) return code;
    lolacli_core_finish(p);
    lolacli_core_cycles(p->slaves, n, t);
    return 0;
}

/* ------------------------------------------------------------------ register frames */

/* A frame whose every datagram is an APRD/FPRD/APWR/FPWR, BRD or BWR of registers that
 * stores bytes and nothing the Python objects hold but what the wrapper is told (the SM/FMMU
 * configuration or watchdog times written, AL control requests, addressing), EEPROM reads
 * and error counter clearing included (Chain._run_slots: Esc.read_addressed,
 * Esc.write_addressed, broadcast_read, broadcast_write, SiiInterface._eeprom_command):
 * answered in r->buf.
 * The classes are register_classes() of lolacli/emulator/esc/memory.py, one per register
 * byte. */
enum { R_READONLY = 1, R_CONFIGURATION = 2, R_SYNC_MANAGER = 4, R_DC = 8, R_EEPROM = 16,
       R_AL_CONTROL = 32, R_ADDRESSING = 64, R_CLEAR = 128 };
enum { CMD_APRD = 1, CMD_APWR = 2, CMD_FPRD = 4, CMD_FPWR = 5, CMD_BRD = 7, CMD_BWR = 8 };
#define REGISTER_BYTES 0x1000
#define STATION_ADDRESS 0x0010
#define STATION_ALIAS 0x0012
#define ALIAS_ENABLE_BYTE 0x0103
#define AL_CONTROL 0x0120
#define SII_CONTROL 0x0502
#define SII_ADDRESS 0x0504
#define SII_DATA 0x0508
#define SII_COMMAND_MASK 0x0700
#define SII_READ 0x0100
#define SII_WRITE 0x0200
#define SII_RELOAD 0x0400
#define SII_CLEARED 0xA700 /* command, busy, command error */
#define SII_READ_8_BYTES 0x0040
#define SII_COMMAND_ERROR 0x2000
#define SM_REGISTERS 0x0800
#define SM_BYTES 8
#define SM_STATUS_MAILBOX_FULL 0x08
#define SM_ACTIVATE_ENABLE 0x01
#define DC_SYSTEM_TIME 0x0910
#define DC_RECEIVE_TIME_PORT0 0x0900
#define DC_RECEIVE_TIME_PORT1 0x0904
#define DC_RECEIVE_TIME_PU 0x0918
#define DC_SYSTEM_TIME_DELAY 0x0928
#define MAX_REGISTER_DATAGRAMS 128
#define ALL_SLAVES (-1)
/* per active slave: port 0 offset, mailbox out SM, mailbox in SM, sync managers, SII image
 * address and bytes, 8-byte EEPROM reads, port 1 offset (-1: none, the last in line) */
#define LINE_WORDS 8
/* out: [touched, n_slaves entries (position << 3 | T_*), n_slaves marks (entry + 1, 0:
 * none; all 0 between calls), datagrams, MAX_REGISTER_DATAGRAMS lengths, AL control
 * requests, FIRMWARE_CAP(n) of them (position << 8 | the byte written), in order, the
 * station address or alias enable written (1) or not (0), mailbox SMs written,
 * MAILBOX_CAP(n) of them (position << 8 | SM), in order] */
#define FIRMWARE_CAP(n) (2 * (n) + MAX_REGISTER_DATAGRAMS)
#define MAILBOX_CAP(n) (2 * ((n) + MAX_REGISTER_DATAGRAMS))
#define OUT_WORDS(n) (5 + 2 * (n) + MAX_REGISTER_DATAGRAMS + FIRMWARE_CAP(n) + MAILBOX_CAP(n))
#define OUT_REQUESTS(r) ((r)->out + 2 + 2 * (r)->n_slaves + MAX_REGISTER_DATAGRAMS)
#define OUT_ADDRESSING(r) (OUT_REQUESTS(r) + 1 + FIRMWARE_CAP((r)->n_slaves))
#define OUT_MAILBOX(r) (OUT_ADDRESSING(r) + 1)
enum { T_CONFIGURATION = 1, T_RELEASED = 2, T_CLOCK = 4 };

typedef struct {
    slave_t *slaves; i64 n_slaves;
    i64 n_active;                  /* the first n_active slaves are the ones frames reach */
    const i64 *line; i64 line_len; /* LINE_WORDS per active slave */
    const uint8_t *classes; i64 classes_len;
    uint8_t *buf; i64 buf_len;     /* the answer */
    i64 *out; i64 out_len;
    const i64 *groups; i64 groups_len; /* registers cleared together: [lo, hi) pairs */
    i64 clocks; /* 1: every active slave's table has its clock (the wrapper gave the clocks of
                   those it does not hold), 0: only the held ones */
} regs_t;

/* Chain._station_position: the first active slave answering a configured address */
static i64 station_position(const regs_t *r, i64 adp) {
    for (i64 i = 0; i < r->n_active; i++) {
        const uint8_t *m = r->slaves[i].mem;
        if ((m[STATION_ADDRESS] | m[STATION_ADDRESS + 1] << 8) == adp) return i;
        if ((m[ALIAS_ENABLE_BYTE] & 1) && (m[STATION_ALIAS] | m[STATION_ALIAS + 1] << 8) == adp)
            return i;
    }
    return r->n_active;
}

/* Byte b of slave q's SM i registers as the datagram at h (a write of length bytes at
 * ado) leaves it: the datagram's byte over the slave's memory, read-only bytes kept */
static i64 sm_byte_after(const regs_t *r, i64 q, i64 i, i64 b, const uint8_t *h, i64 ado,
                         i64 length) {
    i64 a = SM_REGISTERS + SM_BYTES * i + b;
    int given = ado <= a && a < ado + length && !(r->classes[a] & R_READONLY);
    return given ? h[10 + a - ado] : r->slaves[q].mem[a];
}

/* SyncManagers._sm_registers_written's range of sync managers for a write [lo, hi) */
static void sm_range(i64 lo, i64 hi, i64 n_sm, i64 *first, i64 *last) {
    *first = lo < SM_REGISTERS ? 0 : (lo - SM_REGISTERS) / SM_BYTES;
    *last = (hi - 1 - SM_REGISTERS) / SM_BYTES + 1;
    if (*last > n_sm) *last = n_sm;
}

/* SiiInterface._eeprom_command for what pass 1 lets through: no command, a read, or a
 * command the ESC refuses */
static void eeprom_command(uint8_t *m, const i64 *row) {
    i64 control = m[SII_CONTROL] | m[SII_CONTROL + 1] << 8;
    i64 command = control & SII_COMMAND_MASK;
    i64 status = control & ~SII_CLEARED;
    if (row[6]) status |= SII_READ_8_BYTES;
    if (command == SII_READ) {
        const uint8_t *sii = (const uint8_t *)(intptr_t)row[4];
        i64 from = 2 * (i64)get_le(m + SII_ADDRESS, 4), chunk = row[6] ? 8 : 4;
        for (i64 b = 0; b < 8; b++)
            m[SII_DATA + b] = b < chunk && from + b < row[5] ? sii[from + b] : 0xFF;
    } else if (command) {
        status |= SII_COMMAND_ERROR;
    }
    m[SII_CONTROL] = (uint8_t)status;
    m[SII_CONTROL + 1] = (uint8_t)(status >> 8);
}

/* DcClock.local_ns, mod 2^64 */
static u64 local_time(const slave_t *s, i64 t) {
    i128 drift = s->clk_drift ? floordiv((i128)t * s->clk_drift, NS_PER_S) : 0;
    return (u64)t + (u64)drift + (u64)s->clk_start + (u64)s->clk_corr;
}

/* What a write of the DC registers sets off in the slave of line row ``row`` (the frame
 * left the master at t): DistributedClock._latch_receive_times for a write into 0x0900-3
 * (receive times of ports 0 and 1, and port 0's as the processing unit's), and the time
 * control loop's step for a write into the system time 0x0910-7 (_system_time_written:
 * the value from 0x0910 up to the write's last byte of it, lower bytes not written 0) */
static void dc_written(slave_t *s, const i64 *row, i64 ado, const uint8_t *data, i64 length,
                       i64 t) {
    i64 end = ado + length;
    if (ado < DC_RECEIVE_TIME_PORT0 + 4 && DC_RECEIVE_TIME_PORT0 < end) {
        u64 local0 = local_time(s, t + row[0]);
        put_le(s->mem + DC_RECEIVE_TIME_PORT0, 4, local0);
        if (row[7] >= 0) put_le(s->mem + DC_RECEIVE_TIME_PORT1, 4, local_time(s, t + row[7]));
        put_le(s->mem + DC_RECEIVE_TIME_PU, 8, local0);
    }
    if (ado < DC_SYSTEM_TIME + 8 && DC_SYSTEM_TIME < end) {
        i64 lo = ado > DC_SYSTEM_TIME ? ado : DC_SYSTEM_TIME;
        i64 hi = end < DC_SYSTEM_TIME + 8 ? end : DC_SYSTEM_TIME + 8;
        u64 value = 0;
        for (i64 a = hi - 1; a >= lo; a--) value = value << 8 | data[a - ado];
        value <<= 8 * (lo - DC_SYSTEM_TIME);
        u64 registers = get_le(s->mem + DC_SYSTEM_TIME_OFFSET, 8) -
                        get_le(s->mem + DC_SYSTEM_TIME_DELAY, 4);
        i64 step[OTHER_WORDS] = {0, row[0], (i64)registers};
        time_loop(s, step, 1, value, 8 * (hi - DC_SYSTEM_TIME), t);
    }
}

/* The write of ``length`` bytes at ``ado`` into slave p: stored, its effects run; the
 * T_* flags it leaves */
static i64 write_one(const regs_t *r, i64 p, i64 ado, const uint8_t *data, i64 length, i64 t) {
    slave_t *s = &r->slaves[p];
    const i64 *row = r->line + p * LINE_WORDS;
    int any = 0;
    for (i64 b = 0; b < length; b++) {
        uint8_t c = r->classes[ado + b];
        if (!(c & R_READONLY)) s->mem[ado + b] = data[b];
        any |= c;
    }
    if (any & R_SYNC_MANAGER) {
        i64 first, last;
        sm_range(ado, ado + length, row[3], &first, &last);
        for (i64 i = first; i < last; i++) {
            uint8_t *sm = s->mem + SM_REGISTERS + SM_BYTES * i;
            if (!(sm[6] & SM_ACTIVATE_ENABLE)) sm[5] &= (uint8_t)~SM_STATUS_MAILBOX_FULL;
            if (i == row[1] || i == row[2]) { /* SyncManagers.mailbox_sm_written, after */
                i64 *written = OUT_MAILBOX(r);
                written[1 + written[0]++] = p << 8 | i;
            }
        }
    }
    if (any & R_CLEAR) /* a write into a group clears all of it */
        for (i64 g = 0; g + 1 < r->groups_len; g += 2) {
            i64 lo = r->groups[g], hi = r->groups[g + 1];
            if (ado < hi && lo < ado + length) memset(s->mem + lo, 0, (size_t)(hi - lo));
        }
    if (any & R_EEPROM) eeprom_command(s->mem, row);
    if (any & R_AL_CONTROL) { /* Esc.al_control_written: queued by the wrapper, in order */
        i64 *requests = OUT_REQUESTS(r);
        requests[1 + requests[0]++] = p << 8 | s->mem[AL_CONTROL];
    }
    if (any & R_ADDRESSING) *OUT_ADDRESSING(r) = 1; /* the wrapper bumps Esc.addressing */
    if (any & R_DC) {
        dc_written(s, row, ado, data, length, t);
        return T_CLOCK | (any & R_CONFIGURATION ? T_CONFIGURATION : 0);
    }
    return any & R_CONFIGURATION ? T_CONFIGURATION : 0;
}

/* slave p took a datagram at frame time t: counted, its time set, noted in out */
static void touch(const regs_t *r, i64 p, i64 t, i64 flags) {
    slave_t *s = &r->slaves[p];
    i64 *out = r->out, *marks = out + 1 + r->n_slaves;
    s->datagrams += 1;
    s->now_ns = t + r->line[p * LINE_WORDS];
    if (!s->owned) flags |= T_RELEASED;
    if (marks[p]) {
        out[marks[p]] |= flags;
    } else {
        out[1 + out[0]] = p << 3 | flags;
        marks[p] = 1 + out[0]++;
    }
}

static void add_wkc(uint8_t *at, i64 added) {
    i64 wkc = (at[0] | at[1] << 8) + added;
    at[0] = (uint8_t)wkc;
    at[1] = (uint8_t)(wkc >> 8);
}

/* The number of register writes (one a slave), or -1 (nothing changed) for a frame this
 * path does not take: not an untagged command frame as Chain's _slots reads it, a datagram
 * of another command, of no data, beyond the registers, reading the DC system time, a
 * write that sets off more than the store, the SM/FMMU configuration and watchdog times,
 * an EEPROM read, an AL control request, a station address or alias enable and the error
 * counters' clearing, an FPRD/FPWR after such an addressing write, a datagram reaching the
 * SM registers of a slave whose mailbox SM registers an earlier one wrote, or more than
 * MAX_REGISTER_DATAGRAMS datagrams. */
i64 lolacli_core_registers(const regs_t *r, const uint8_t *frame, i64 n, i64 t) {
    if (n < 16 || n > r->buf_len || frame[12] != 0x88 || frame[13] != 0xA4) return -1;
    i64 word = frame[14] | frame[15] << 8;
    i64 end = 16 + (word & 0x7FF);
    if (word >> 12 != 1 || end > n) return -1;
    i64 at[MAX_REGISTER_DATAGRAMS], where[MAX_REGISTER_DATAGRAMS];
    i64 count = 0, pos = 16, requests = 0, addressed = 0;
    i64 mailboxes[MAX_REGISTER_DATAGRAMS], n_mailboxes = 0; /* slaves whose mailbox SMs a
        datagram wrote: their mailbox work runs after the frame, so no later datagram may
        reach their SM registers */
    const uint8_t *cls = r->classes;
    for (;;) { /* pass 1: the frame is this path's, nothing written */
        if (pos + 10 > end || count == MAX_REGISTER_DATAGRAMS) return -1;
        const uint8_t *h = frame + pos;
        i64 cmd = h[0], adp = h[2] | h[3] << 8, ado = h[4] | h[5] << 8;
        i64 lenw = h[6] | h[7] << 8, length = lenw & 0x7FF;
        if (pos + 10 + length + 2 > end) return -1;
        if (length == 0 || ado + length > REGISTER_BYTES) return -1;
        i64 p;
        if (cmd == CMD_APRD || cmd == CMD_APWR) p = (-adp) & 0xFFFF;
        else if (cmd == CMD_FPRD || cmd == CMD_FPWR) {
            if (addressed) return -1; /* its station as an earlier datagram left it: Python */
            p = station_position(r, adp);
        }
        else if (cmd == CMD_BRD || cmd == CMD_BWR) p = ALL_SLAVES;
        else return -1;
        if (p > r->n_active) p = r->n_active;
        if (ado < SM_REGISTERS + 16 * SM_BYTES && SM_REGISTERS < ado + length)
            for (i64 k = 0; k < n_mailboxes; k++) {
                if (mailboxes[k] == ALL_SLAVES || mailboxes[k] == p) return -1;
                if (p == ALL_SLAVES && r->n_active > 0) return -1;
            }
        if (cmd == CMD_APRD || cmd == CMD_FPRD || cmd == CMD_BRD) {
            if (ado < DC_SYSTEM_TIME + 8 && DC_SYSTEM_TIME < ado + length) return -1;
        } else {
            int any = 0;
            for (i64 a = ado; a < ado + length; a++) any |= cls[a];
            if ((any & R_DC) && !r->clocks) { /* the clocks of the slaves it reaches */
                i64 q0 = p == ALL_SLAVES ? 0 : p, q1 = p == ALL_SLAVES ? r->n_active : p + 1;
                for (i64 q = q0; q < q1 && q < r->n_active; q++)
                    if (!r->slaves[q].owned) return -2;
            }
            if (any & R_ADDRESSING) addressed = 1;
            if (any & R_AL_CONTROL) {
                requests += p == ALL_SLAVES ? r->n_active : 1;
                if (requests > FIRMWARE_CAP(r->n_slaves)) return -1;
            }
            if (any & R_EEPROM) { /* the command as written: SII writes and reloads in Python */
                i64 command_byte = SII_CONTROL + 1;
                if (!(ado <= command_byte && command_byte < ado + length)) return -1;
                i64 command = (h[10 + command_byte - ado] << 8) & SII_COMMAND_MASK;
                if (command == SII_WRITE || command == SII_RELOAD) return -1;
            }
            if (any & R_SYNC_MANAGER) { /* a slave's mailbox SMs: their work runs after */
                i64 q0 = p == ALL_SLAVES ? 0 : p, q1 = p == ALL_SLAVES ? r->n_active : p + 1;
                int mailbox = 0;
                for (i64 q = q0; q < q1 && q < r->n_active; q++) {
                    const i64 *row = r->line + q * LINE_WORDS;
                    i64 first, last;
                    sm_range(ado, ado + length, row[3], &first, &last);
                    for (i64 i = first; i < last; i++) {
                        mailbox |= i == row[1] || i == row[2];
                        /* the read mailbox's work (a repeat, when enabled) stores and reads
                         * its buffer: one the master put among the registers goes to Python */
                        if (i == row[2] && (sm_byte_after(r, q, i, 6, h, ado, length) & 1) &&
                            (sm_byte_after(r, q, i, 0, h, ado, length) |
                             sm_byte_after(r, q, i, 1, h, ado, length) << 8) < REGISTER_BYTES)
                            return -1;
                    }
                }
                if (mailbox) mailboxes[n_mailboxes++] = p;
            }
        }
        at[count] = pos;
        where[count++] = p;
        pos += 10 + length + 2;
        if (!(lenw & 0x8000)) break;
    }
    uint8_t *buf = r->buf;
    i64 *out = r->out;
    memcpy(buf, frame, (size_t)n);
    out[0] = 0;
    *OUT_REQUESTS(r) = 0;
    *OUT_ADDRESSING(r) = 0;
    *OUT_MAILBOX(r) = 0;
    i64 writes = 0;
    i64 *lengths = out + 2 + 2 * r->n_slaves;
    lengths[-1] = count;
    for (i64 k = 0; k < count; k++) { /* pass 2: datagram by datagram, as the chain does */
        uint8_t *h = buf + at[k];
        i64 cmd = h[0], adp = h[2] | h[3] << 8, ado = h[4] | h[5] << 8;
        i64 length = (h[6] | h[7] << 8) & 0x7FF, p = where[k];
        uint8_t *data = h + 10;
        lengths[k] = length;
        if (p == ALL_SLAVES) {
            for (i64 i = 0; i < r->n_active; i++) {
                const uint8_t *m = r->slaves[i].mem + ado;
                if (cmd == CMD_BRD) {
                    for (i64 b = 0; b < length; b++) data[b] |= m[b];
                    touch(r, i, t, 0);
                } else {
                    touch(r, i, t, write_one(r, i, ado, data, length, t));
                    writes++;
                }
            }
            add_wkc(data + length, r->n_active);
        } else if (p < r->n_active) {
            if (cmd == CMD_APRD || cmd == CMD_FPRD) {
                memcpy(data, r->slaves[p].mem + ado, (size_t)length);
                touch(r, p, t, 0);
            } else {
                touch(r, p, t, write_one(r, p, ado, data, length, t));
                writes++;
            }
            add_wkc(data + length, 1);
        }
        if (cmd != CMD_FPRD && cmd != CMD_FPWR) { /* every slave incremented it */
            adp = (adp + r->n_active) & 0xFFFF;
            h[2] = (uint8_t)adp;
            h[3] = (uint8_t)(adp >> 8);
        }
    }
    i64 *marks = out + 1 + r->n_slaves;
    for (i64 e = 0; e < out[0]; e++) marks[out[1 + e] >> 3] = 0;
    return writes;
}

/* ------------------------------------------------------------------ checks */

static int within(i64 at, i64 n, i64 size) { return at >= 0 && n >= 0 && at <= size - n; }
static int bounded(i64 x) { return x > -LIMIT && x < LIMIT; }

/* 0 when the slave's tables are safe to run (and its values within the bounds the
 * arithmetic assumes), else a code naming the first problem. */
i64 lolacli_core_check_slave(const slave_t *s) {
    if (!s->mem) return 1;
    if (!bounded(s->clk_start) || !bounded(s->clk_drift) || !bounded(s->clk_corr) ||
        !bounded(s->last_outputs_ns) || !bounded(s->now_ns) || !bounded(s->wd_timeout))
        return 2;
    if (s->kind < K_NONE || s->kind > K_CAN_GATEWAY) return 3;
    if (s->kind < K_GENERIC) return 0;
    if (s->kind != K_CIA402 && (s->joint || s->joint_n)) return 19;
    if (!within(s->out_start, s->out_bytes, MEMORY_BYTES) ||
        !within(s->in_start, s->in_bytes, MEMORY_BYTES))
        return 4;
    if (s->vals_len < 0 || (s->vals_len && !s->vals) || !bounded(s->dev_t_ns)) return 5;
    if (s->omap_n < 0 || s->imap_n < 0 || s->chan_n < 0) return 6;
    if ((s->omap_n && !s->omap) || (s->imap_n && !s->imap) || (s->chan_n && !s->chan)) return 6;
    for (i64 k = 0; k < s->omap_n; k++) {
        const i64 *row = s->omap + k * MAP_WORDS;
        i64 want = row[1] > 0 ? (row[1] + 7) / 8 : 1;
        if (row[1] < 0 || !within(row[0], row[1], 8 * s->out_bytes) || row[3] != want ||
            !within(row[2], row[3], s->vals_len))
            return 7;
    }
    for (i64 k = 0; k < s->imap_n; k++) {
        const i64 *row = s->imap + k * MAP_WORDS;
        if (row[1] < 0 || !within(row[0], row[1], 8 * s->in_bytes) ||
            !within(row[2], row[3], s->vals_len))
            return 8;
    }
    if (s->kind == K_CIA402) {
        for (int k = 0; k < N_CYCLIC; k++)
            if (!within(s->e[k], CYCLIC_BYTES[k], s->vals_len)) return 9;
        if (s->prev_cw < 0 || s->prev_cw > 0xFFFF) return 10;
        if (s->qs_option < -0x8000 || s->qs_option > 0x7FFF || s->qs_ramp < 0 ||
            s->qs_ramp > 0xFFFFFFFFLL || s->fr_ramp < 0 || s->fr_ramp > 0xFFFFFFFFLL ||
            s->rated_torque < 0 || s->rated_torque > 0xFFFFFFFFLL)
            return 18;
        if (s->joint_n != (s->joint ? J_WORDS : 0)) return 19;
        if (s->joint) {
            const double *j = s->joint;
            double pending = j[J_PENDING];
            if (!(pending >= 0 && pending < POSITION_PERIOD_NS && pending == floor(pending)) ||
                (j[J_HAS_LAST] != 0.0 && j[J_HAS_LAST] != 1.0) ||
                (j[J_TORQUE] != 0.0 && j[J_TORQUE] != 1.0) ||
                !(j[J_RATED] >= 0 && j[J_RATED] <= 0xFFFFFFFFLL && j[J_RATED] == floor(j[J_RATED])))
                return 19;
            if ((s->rest != 0 && s->rest != 1) || s->rest_n < 0 || s->rest_n > s->out_bytes ||
                (s->out_bytes && !s->rest_out))
                return 20;
        }
        switch (s->power) {
        case NOT_READY: case SWITCH_ON_DISABLED: case READY_TO_SWITCH_ON: case SWITCHED_ON:
        case OPERATION_ENABLED: case QUICK_STOP_ACTIVE: case FAULT_REACTION_ACTIVE: case FAULT:
            break;
        default:
            return 10;
        }
    } else if (s->kind == K_DIGITAL_IO) {
        for (i64 k = 0; k < s->chan_n; k++) {
            const i64 *row = s->chan + k * DIO_WORDS;
            i64 want = row[3] > 0 ? (row[3] + 7) / 8 : 1;
            if (row[0] < 0 || row[3] < 0 || row[3] > 64 || row[2] != want ||
                !within(row[1], row[2], s->vals_len))
                return 11;
            if (row[4] != -1 && !within(row[4], row[5], s->vals_len)) return 11;
        }
    } else if (s->kind == K_ANALOG) {
        if (s->period <= 0 || !bounded(s->period) || !bounded(s->last_sample)) return 12;
        if (s->chan_n && !s->phase) return 12;
        for (i64 k = 0; k < s->chan_n; k++) {
            const i64 *row = s->chan + k * ANALOG_WORDS;
            i64 want = row[2] == 1 ? 4 : row[2] == 2 ? 8 : row[1];
            if (row[2] < 0 || row[2] > 2 || row[1] != want || row[1] < 1 || row[1] > 8 ||
                !within(row[0], row[1], s->vals_len))
                return 13;
        }
    } else if (s->kind == K_CAN_GATEWAY) {
        const i64 *a = s->aux;
        if (!a || s->aux_n < A_HEADER || (s->chan_n && !s->phase)) return 14;
        i64 n_sensors = a[A_SENSORS], hyper = a[A_HYPER], n_rows = a[A_ROWS];
        if (n_sensors < 0 || n_sensors > CAN_MAX_SENSORS || hyper <= 0 || hyper > LIMIT / 4 ||
            n_rows < 0 || n_rows > LIMIT / (1 + CAN_MAX_SENSORS) ||
            s->aux_n != A_HEADER + n_sensors * S_WORDS + n_rows * (1 + n_sensors))
            return 14;
        for (i64 i = 0; i < n_sensors; i++) {
            const i64 *w = a + A_HEADER + i * S_WORDS;
            if ((w[S_STATUS] != -1 && (w[S_STATUS_BYTES] < 1 || w[S_STATUS_BYTES] > 8 ||
                                       !within(w[S_STATUS], w[S_STATUS_BYTES], s->vals_len))) ||
                (w[S_COUNTER] != -1 && (w[S_COUNTER_BYTES] < 2 || w[S_COUNTER_BYTES] > 8 ||
                                        !within(w[S_COUNTER], w[S_COUNTER_BYTES], s->vals_len))))
                return 15;
            if (w[S_SHIFT] < 1 || !bounded(w[S_SHIFT]) || w[S_PERIOD] < 1 || !bounded(w[S_PERIOD]) ||
                !bounded(w[S_PHASE]) || w[S_HELD] < -1 || !bounded(w[S_HELD]))
                return 15;
        }
        const i64 *rows = a + A_HEADER + n_sensors * S_WORDS;
        for (i64 r = 0; r < n_rows; r++) {
            const i64 *row = rows + r * (1 + n_sensors);
            if (row[0] < 0 || row[0] >= 3 * hyper || (r && row[0] < row[-1 - n_sensors])) return 16;
            for (i64 i = 0; i < n_sensors; i++)
                if (row[1 + i] < -1 || !bounded(row[1 + i])) return 16;
        }
        for (i64 k = 0; k < s->chan_n; k++) {
            const i64 *row = s->chan + k * CAN_WORDS;
            if (row[0] < 0 || row[0] >= n_sensors || row[2] != 4 || row[3] != 1 ||
                !within(row[1], 4, s->vals_len))
                return 17;
        }
    }
    return 0;
}

/* 0 when the register path's tables are within their buffers, else a code. */
i64 lolacli_core_check_registers(const regs_t *r) {
    if (!r->slaves || r->n_active < 0 || r->n_active > r->n_slaves) return 1;
    if (r->line_len < r->n_active * LINE_WORDS || (r->n_active && !r->line)) return 2;
    if (r->classes_len != REGISTER_BYTES || !r->classes) return 3;
    if (!r->buf || r->buf_len < 16 || !r->out || r->out_len < OUT_WORDS(r->n_slaves)) return 4;
    if (r->groups_len < 0 || r->groups_len % 2 || (r->groups_len && !r->groups)) return 7;
    if (r->clocks != 0 && r->clocks != 1) return 8;
    for (i64 g = 0; g < r->groups_len; g += 2) {
        i64 lo = r->groups[g], hi = r->groups[g + 1];
        if (lo < 0 || lo >= hi || hi > REGISTER_BYTES) return 7;
    }
    for (i64 i = 0; i < r->n_slaves; i++)
        if (r->out[1 + r->n_slaves + i]) return 4; /* the marks start cleared */
    for (i64 i = 0; i < r->n_active; i++) {
        const i64 *row = r->line + i * LINE_WORDS;
        if (!bounded(row[0]) || row[3] < 0 || row[3] > 16 || !r->slaves[i].mem) return 5;
        if (row[5] < 0 || row[5] > LIMIT || (row[5] && !row[4]) || (row[6] != 0 && row[6] != 1))
            return 6;
        if (row[7] < -1 || !bounded(row[7])) return 5;
    }
    return 0;
}

/* 0 when the plan's program only reaches inside its buffers and slaves, else a code. */
i64 lolacli_core_check_plan(const plan_t *p) {
    const i64 *h = p->prog;
    i64 n = p->prog_len;
    if (n < H_WORDS || h[H_MAGIC] != MAGIC) return 1;
    if (h[H_FRAME_LEN] < 16 || h[H_FRAME_LEN] != p->buf_len || p->pend_len < 2) return 2;
    if (h[H_N_COUNT] < 0 || h[H_N_COUNT] > p->n_slaves || !bounded(h[H_COUNT_K])) return 3;
    if (!within(h[H_WATCH], h[H_N_WATCH], n) || !within(h[H_ADP], 2 * h[H_N_ADP], n)) return 4;
    for (i64 k = 0; k < h[H_N_WATCH]; k++)
        if (h[h[H_WATCH] + k] < 0 || h[h[H_WATCH] + k] >= p->n_slaves) return 4;
    for (i64 k = 0; k < h[H_N_ADP]; k++)
        if (!within(h[h[H_ADP] + 2 * k], 2, p->buf_len)) return 4;
    i64 at = h[H_OPS];
    if (h[H_N_OPS] < 0 || at < H_WORDS) return 5;
    for (i64 k = 0; k < h[H_N_OPS]; k++) {
        if (!within(at, 5, n)) return 5;
        const i64 *op = h + at;
        i64 words = op[1];
        if (words < 5 || !within(at, words, n)) return 5;
        i64 data = op[2], length = op[3];
        if (!within(data, length, p->buf_len) || !within(op[4], 2, p->buf_len)) return 6;
        if (op[0] == OP_LOGICAL) {
            if (words < L_ROWS) return 7;
            i64 nw = op[L_N_WRITES], nr = op[L_N_READS], ne = op[L_N_EVENTS];
            if (nw < 0 || nr < 0 || ne < 0 || !bounded(op[L_FIXED_WKC])) return 7;
            if (words != L_ROWS + (nw + nr) * COPY_WORDS + ne * EVENT_WORDS) return 7;
            if (op[L_DEFERRED] && !within(op[L_SNAP], length, p->snap_len)) return 7;
            for (i64 r = 0; r < nw + nr; r++) {
                const i64 *row = op + L_ROWS + r * COPY_WORDS;
                if (row[0] < 0 || row[0] >= p->n_slaves || !within(row[1], row[3], MEMORY_BYTES) ||
                    !within(row[2], row[3], length))
                    return 8;
            }
            for (i64 r = 0; r < ne; r++) {
                const i64 *row = op + L_ROWS + (nw + nr) * COPY_WORDS + r * EVENT_WORDS;
                if (row[0] < 0 || row[0] >= p->n_slaves || !bounded(row[1])) return 8;
            }
        } else if (op[0] == OP_BRD) {
            if (words < B_ROWS || words != B_ROWS + op[B_N] || op[B_N] < 0) return 9;
            if (!within(op[B_LO], length, MEMORY_BYTES) || !within(op[B_CACHE_SNAP], length, p->snap_len))
                return 9;
            if (op[B_CACHE] && (op[B_CACHE_FLAG] < 2 || op[B_CACHE_FLAG] >= p->pend_len)) return 9;
            for (i64 r = 0; r < op[B_N]; r++)
                if (op[B_ROWS + r] < 0 || op[B_ROWS + r] >= p->n_slaves) return 9;
        } else if (op[0] == OP_DC) {
            if (words < D_ROWS || (length != 4 && length != 8) || op[D_N_SEGMENTS] < 0) return 10;
            i64 others = 0;
            for (i64 g = 0; g < op[D_N_SEGMENTS]; g++) {
                if (!within(D_ROWS + g * SEGMENT_WORDS, SEGMENT_WORDS, words)) return 10;
                const i64 *seg = op + D_ROWS + g * SEGMENT_WORDS;
                if (seg[0] < -1 || seg[0] >= p->n_slaves || !bounded(seg[1]) || seg[2] < 0) return 10;
                if (seg[2] && (seg[3] < 2 || seg[3] >= p->pend_len)) return 10;
                others += seg[2];
            }
            if (words != D_ROWS + op[D_N_SEGMENTS] * SEGMENT_WORDS + others * OTHER_WORDS) return 10;
            const i64 *row = op + D_ROWS + op[D_N_SEGMENTS] * SEGMENT_WORDS;
            for (i64 r = 0; r < others; r++, row += OTHER_WORDS)
                if (row[0] < 0 || row[0] >= p->n_slaves || !bounded(row[1])) return 11;
        } else {
            return 12;
        }
        at += words;
    }
    return 0;
}

/* Layout check for core.py: the sizes and a few offsets of the structs. */
i64 lolacli_core_abi(i64 what) {
    switch (what) {
    case 0: return ABI_VERSION;
    case 1: return (i64)sizeof(slave_t);
    case 2: return (i64)offsetof(slave_t, scale);
    case 3: return (i64)offsetof(slave_t, e);
    case 4: return (i64)sizeof(plan_t);
    case 5: return (i64)sizeof(regs_t);
    case 6: return OUT_WORDS(0);
    }
    return -1;
}

/* ------------------------------------------------------------------ the module */

/* The per-frame entry points as module functions, with the arguments of their ctypes
 * declarations in core.py (addresses and lengths as int, the frame as bytes): a call
 * through ctypes costs ~0.5 us, one of these ~0.05 (three a cycle of the LOLA chain).
 * core.py uses them when this module is the kernel it loaded, else ctypes (a sanitizer
 * build loaded from a path). The GIL stays held: the work is a few microseconds. */
static int int_args(PyObject *const *args, Py_ssize_t nargs, Py_ssize_t want, const char *name,
                    Py_ssize_t bytes_at, i64 *out) {
    if (nargs != want) {
        PyErr_Format(PyExc_TypeError, "%s() takes %zd arguments (%zd given)", name, want, nargs);
        return -1;
    }
    for (Py_ssize_t i = 0; i < want; i++) {
        if (i == bytes_at) { /* the frame: bytes (c_char_p) */
            if (!PyBytes_Check(args[i])) {
                PyErr_Format(PyExc_TypeError, "%s(): argument %zd must be bytes", name, i + 1);
                return -1;
            }
            out[i] = (i64)(intptr_t)PyBytes_AS_STRING(args[i]);
            continue;
        }
        out[i] = (i64)PyLong_AsLongLong(args[i]);
        if (out[i] == -1 && PyErr_Occurred()) return -1;
    }
    return 0;
}

static PyObject *py_answer(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    i64 a[4];
    if (int_args(args, nargs, 4, "lolacli_core_answer", 1, a)) return NULL;
    return PyLong_FromLongLong(
        lolacli_core_answer((plan_t *)(intptr_t)a[0], (const uint8_t *)(intptr_t)a[1], a[2], a[3]));
}

static PyObject *py_answer_cycles(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    i64 a[5];
    if (int_args(args, nargs, 5, "lolacli_core_answer_cycles", 1, a)) return NULL;
    return PyLong_FromLongLong(lolacli_core_answer_cycles(
        (plan_t *)(intptr_t)a[0], (const uint8_t *)(intptr_t)a[1], a[2], a[3], a[4]));
}

static PyObject *py_finish(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    i64 a[1];
    if (int_args(args, nargs, 1, "lolacli_core_finish", -1, a)) return NULL;
    lolacli_core_finish((plan_t *)(intptr_t)a[0]);
    Py_RETURN_NONE;
}

static PyObject *py_cycles(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    i64 a[3];
    if (int_args(args, nargs, 3, "lolacli_core_cycles", -1, a)) return NULL;
    lolacli_core_cycles((slave_t *)(intptr_t)a[0], a[1], a[2]);
    Py_RETURN_NONE;
}

static PyObject *py_watchdog(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    i64 a[3];
    if (int_args(args, nargs, 3, "lolacli_core_watchdog", -1, a)) return NULL;
    return PyLong_FromLongLong(lolacli_core_watchdog((slave_t *)(intptr_t)a[0], a[1], a[2]));
}

static PyObject *py_registers(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    (void)self;
    i64 a[4];
    if (int_args(args, nargs, 4, "lolacli_core_registers", 1, a)) return NULL;
    return PyLong_FromLongLong(lolacli_core_registers(
        (const regs_t *)(intptr_t)a[0], (const uint8_t *)(intptr_t)a[1], a[2], a[3]));
}

static PyMethodDef ccore_methods[] = {
    {"lolacli_core_answer", (PyCFunction)(void (*)(void))py_answer, METH_FASTCALL, NULL},
    {"lolacli_core_answer_cycles", (PyCFunction)(void (*)(void))py_answer_cycles, METH_FASTCALL,
     NULL},
    {"lolacli_core_finish", (PyCFunction)(void (*)(void))py_finish, METH_FASTCALL, NULL},
    {"lolacli_core_cycles", (PyCFunction)(void (*)(void))py_cycles, METH_FASTCALL, NULL},
    {"lolacli_core_watchdog", (PyCFunction)(void (*)(void))py_watchdog, METH_FASTCALL, NULL},
    {"lolacli_core_registers", (PyCFunction)(void (*)(void))py_registers, METH_FASTCALL, NULL},
    {NULL, NULL, 0, NULL}};

/* An importable module, so that the build and the package data find it; core.py calls
 * the functions above through ctypes, the per-frame ones through ccore_methods. */
static struct PyModuleDef ccore_module = {
    PyModuleDef_HEAD_INIT, "_ccore",
    "C core of the emulated chain's cyclic work (called by lolacli.emulator.core).",
    -1, ccore_methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__ccore(void) { return PyModule_Create(&ccore_module); }
