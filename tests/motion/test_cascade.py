"""The one cascade (lolacli.motion.joint.Cascade): run_cascade and the emulated drives'
joint load step it; both reproduce, bit for bit, the loop run_cascade had before the
stepper was taken out of it (kept here as the reference), whole or a bus cycle at a time.
And the encoder resolution a joints file may give."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from lolacli.motion.joint import (
    COULOMB_SMOOTHING_RAD_S,
    CURRENT_PERIOD_NS,
    DEFAULT_ENCODER_INCREMENTS_PER_REV,
    POSITION_PERIOD_NS,
    Cascade,
    DriveInput,
    JointParams,
    discretize,
    find_joint,
    parse_joints,
    run_cascade,
)

JOINTS = Path(__file__).resolve().parents[2] / "lolacli" / "motion" / "joints.toml"


def _reference(p: JointParams, tt: list[float], vt: list[float], it: list[float],
               kvel_ff: float, substeps: int, initial: tuple[float, float]) -> list[float]:
    """run_cascade's loop as it was before the Cascade stepper (commit e76a842)."""
    phi, gam = discretize(p, CURRENT_PERIOD_NS * 1e-9 / substeps)
    (p00, p01, p02), (p10, p11, p12), (p20, p21, p22) = phi.tolist()
    (g0v, g0t), (g1v, g1t), (g2v, g2t) = gam.tolist()
    tp, tc = POSITION_PERIOD_NS * 1e-9, CURRENT_PERIOD_NS * 1e-9
    kp, kv, ki = p.position_kp_per_s, p.velocity_kp_a_s_per_rad, p.velocity_ki_per_s
    kpc, kic = p.current_kp_v_per_a, p.current_ki_per_s
    imax, vmax = p.max_current_a, p.supply_v
    fc, ws, grav = p.coulomb_nm, COULOMB_SMOOTHING_RAD_S, p.gravity_nm
    kvi_tp, kci_tc = kv * ki * tp, kpc * kic * tc
    th, w = initial
    cur, vint = 0.0, 0.0
    iint = p.torque_constant_nm_per_a * p.gear_ratio * w
    out = []
    for n in range(len(tt)):
        out.append(th)
        ev = kp * (tt[n] - th) + kvel_ff * vt[n] - w
        icmd = kv * ev + vint + it[n]
        if icmd > imax:
            icmd = imax
        elif icmd < -imax:
            icmd = -imax
        else:
            vint += kvi_tp * ev
        for _ in range(POSITION_PERIOD_NS // CURRENT_PERIOD_NS):
            ei = icmd - cur
            volts = kpc * ei + iint
            if volts > vmax:
                volts = vmax
            elif volts < -vmax:
                volts = -vmax
            else:
                iint += kci_tc * ei
            for _ in range(substeps):
                tau = fc * math.tanh(w / ws) + grav * math.sin(th)
                cur, th, w = (p00 * cur + p01 * th + p02 * w + g0v * volts + g0t * tau,
                              p10 * cur + p11 * th + p12 * w + g1v * volts + g1t * tau,
                              p20 * cur + p21 * th + p22 * w + g2v * volts + g2t * tau)
    return out


def _joints() -> dict[str, JointParams]:
    return parse_joints(JOINTS.read_text(), str(JOINTS))


@pytest.mark.parametrize(("name", "substeps"), [("Joint03", 1), ("Joint04", 2), ("Joint07", 1)])
def test_the_stepper_reproduces_the_original_loop_bit_for_bit(name: str, substeps: int) -> None:
    p = find_joint(_joints(), name)
    assert p is not None
    rng = np.random.default_rng(26)
    n = 3000  # 0.3 s: large steps that saturate current and voltage, and small ones
    tt = np.cumsum(rng.normal(0, 2e-4, n)) + np.where(np.arange(n) > 1500, 0.3, 0.0)
    vt, it = rng.normal(0, 0.5, n), rng.normal(0, 2.0, n)
    want = _reference(p, tt.tolist(), vt.tolist(), it.tolist(), 1.3, substeps, (0.1, 0.2))
    got = run_cascade(p, DriveInput(tt, vt, it), kvel_ff=1.3, substeps=substeps,
                      initial=(0.1, 0.2))
    assert got.tolist() == want  # exactly: the same operations in the same order
    # a bus cycle at a time, as the emulated drive steps it (chunks of 1 to 7 periods)
    cascade = Cascade(p, kvel_ff=1.3, substeps=substeps, initial=(0.1, 0.2))
    out: list[float] = []
    k = 0
    while k < n:
        m = int(rng.integers(1, 8))
        cascade.run(tt[k:k + m].tolist(), vt[k:k + m].tolist(), it[k:k + m].tolist(), out)
        k += m
    assert out == want


def test_the_encoder_resolution_is_optional_with_a_19_bit_default(tmp_path: Path) -> None:
    hip = find_joint(_joints(), "Joint03")
    assert hip is not None and hip.encoder_increments_per_rev == DEFAULT_ENCODER_INCREMENTS_PER_REV
    assert hip.increments_per_rad == pytest.approx(2**19 * 100 / (2 * math.pi))
    text = JOINTS.read_text().replace("[class.knee]\n",
                                      "[class.knee]\nencoder_increments_per_rev = 4096\n")
    knee = find_joint(parse_joints(text, "x.toml"), "L Knee")
    assert knee is not None and knee.increments_per_rad == pytest.approx(4096 * 200 / (2 * math.pi))
    from lolacli.errors import InputError

    with pytest.raises(InputError, match="encoder_increments_per_rev must be > 0"):
        parse_joints(text.replace("= 4096", "= 0"), "x.toml")
