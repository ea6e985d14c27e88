"""The joint behind a drive (lolacli.motion.joint, .targets, .tracking, .bode) and the
`lolacli joint` commands: seed 000 §V's cascade, Table III's trend, the k_e learning
against a fine sweep, the bandwidth against a closed form."""

from __future__ import annotations

import dataclasses
import json
import math
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lolacli.motion.bode import chirp_response
from lolacli.motion.joint import DEFAULT_JOINT, JointParams, find_joint, parse_joints
from lolacli.motion.targets import BusTiming, Chirp, HipWalk, drive_input
from lolacli.motion.tracking import (
    fine_minimiser,
    learn_ke,
    learning_cost,
    track,
)
from tests.live import LOLA
from tests.test_cli_width import assert_fits, human

JOINTS = Path(__file__).resolve().parents[2] / "lolacli" / "motion" / "joints.toml"
SLOW = BusTiming(1_000_000, 1_000_000, False)
FAST = BusTiming(1_000_000, 500_000, True)


def _joints() -> dict[str, JointParams]:
    return parse_joints(JOINTS.read_text(), str(JOINTS))


def _hip() -> JointParams:
    hip = find_joint(_joints(), DEFAULT_JOINT)
    assert hip is not None
    return hip


def _json(cli, *args: str) -> dict:
    code, out, err = cli(*args, "--format", "json")
    assert code == 0, err
    return json.loads(out)


# ---------------------------------------------------------------- parameters


def test_every_joint_of_the_lola_eni_has_parameters():
    """The packaged file names exactly the ENI's joint slaves (read by ElementTree)."""
    import xml.etree.ElementTree as ET

    names = {s.findtext("Info/Name") for s in ET.parse(LOLA).getroot().iter("Slave")}
    joint_names = {n for n in names if n and n.startswith("Joint")}
    assert len(joint_names) == 21
    assert set(_joints()) == joint_names
    assert find_joint(_joints(), "l knee").name == "Joint04 L Knee"
    assert find_joint(_joints(), "Joint10").name == "Joint10 R Hip Pitch"


def test_a_joints_file_with_a_missing_key_is_bad_input(tmp_path, cli):
    text = JOINTS.read_text().replace("gravity_nm = 41.0\n", "", 1)
    bad = tmp_path / "joints-missing-gravity.toml"
    bad.write_text(text)
    code, _, err = cli("joint", "tune", "--joints", str(bad))
    assert code == 3
    assert err.count("\n") == 1 and "gravity_nm" in err and str(bad) in err
    broken = tmp_path / "joints-broken.toml"
    broken.write_text("[class.x]\nmotor_inertia_kgm2 = = 1\n")
    code, _, err = cli("joint", "tune", "--joints", str(broken))
    assert code == 3 and f"{broken}:2:" in err


# ---------------------------------------------------------------- integration, targets


def test_halving_the_step_changes_the_tracking_error_by_under_one_percent():
    hip, walk = _hip(), HipWalk()
    for timing, k_e in ((SLOW, 0.0), (SLOW, 1.0), (FAST, 0.5)):
        rms = [track(hip, walk, timing, k_e=k_e, window_s=1.2, substeps=s).rms_rad
               for s in (1, 2)]
        assert abs(rms[0] - rms[1]) < 0.01 * rms[1], (timing, k_e, rms)


def test_the_bus_delivers_targets_one_cycle_late_and_extrapolates_between_updates():
    hip = _hip()
    ramp = lambda t: (2.0 * t, 2.0 + 0 * t, 0 * t)  # noqa: E731  θ = 2 rad/s · t
    held = drive_input(hip, ramp, BusTiming(1_000_000, 500_000, False), 0.01,
                       current_ff=False)
    extra = drive_input(hip, ramp, FAST, 0.01, current_ff=False)
    t = np.arange(100) * 1e-4
    sent = np.maximum(np.floor(t / 5e-4 + 1e-9) - 1, 0) * 5e-4  # the cycle applied
    control = np.floor(sent / 1e-3 + 1e-9) * 1e-3  # the control update it carries
    assert np.allclose(held.position, 2.0 * control)
    assert np.allclose(extra.position, 2.0 * sent)  # a ramp is extrapolated exactly
    assert not np.allclose(extra.position, held.position)


def test_learn_ke_follows_the_seed_policy():
    calls = []

    def cost(k: float) -> float:
        calls.append(k)
        return abs(k - 0.73)

    learning = learn_ke(cost)
    assert learning.k_e == 0.7
    assert [k for k, _ in learning.steps] == pytest.approx([0.1 * i for i in range(9)])
    assert learn_ke(lambda k: 1.0 + k).k_e == 0.0  # rising at once: stays at 0


# ---------------------------------------------------------------- acceptance


def test_joint_track_reproduces_table_iii_trend(cli, tmp_path):
    png = tmp_path / "fig9.png"
    doc = _json(cli, "joint", "track", "--plot", str(png))
    assert doc["schema"] == "lolacli.joint/1"
    ref, ff, fast = doc["cases"]
    assert (ref["bus_hz"], ff["bus_hz"], fast["bus_hz"]) == (1000, 1000, 2000)
    assert (ref["k_e"], fast["extrapolation"], ff["extrapolation"]) == (0.0, True, False)
    # an order of magnitude with the learned feed-forward, and lower again at 2 kHz
    assert ref["rms_error_rad"] / ff["rms_error_rad"] > 8
    assert fast["rms_error_rad"] < ff["rms_error_rad"]
    assert fast["max_error_rad"] < ff["max_error_rad"] < ref["max_error_rad"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(("joint", "timing", "bus"), [(DEFAULT_JOINT, SLOW, "1000"),
                                                       ("L Knee", FAST, "2000")])
def test_joint_tune_converges_to_the_minimiser_of_a_fine_sweep(cli, joint, timing, bus):
    doc = _json(cli, "joint", "tune", "--joint", joint, "--bus-hz", bus)
    assert doc["schema"] == "lolacli.joint-tune/1"
    errors = [s["rms_error_rad"] for s in doc["steps"]]
    assert errors[:-1] == sorted(errors[:-1], reverse=True) and errors[-1] >= errors[-2]
    params = find_joint(_joints(), joint)
    cost = learning_cost(params, HipWalk(), timing, 0.6)
    coarse, _ = fine_minimiser(cost, 0.0, 2.0, 0.1)
    best, best_cost = fine_minimiser(cost, max(0.0, coarse - 0.1), coarse + 0.1, 0.005)
    assert abs(doc["k_e"] - best) <= 0.1, (doc["k_e"], best)
    assert best_cost <= min(errors) + 1e-12


def _second_order_joint(a: float, kp: float) -> JointParams:
    """A pure inertia (no friction, no gravity) whose velocity loop is P only and whose
    current loop is fast (2 kHz): velocity follows its command as a/(s + a), a = N k_t Kv/J;
    with the position P: θ/θd = a Kp / (s² + a s + a Kp), and with the velocity
    feed-forward (Kp + s) a / (s² + a s + a Kp)."""
    n, kt, jm, jl = 100.0, 0.1, 1e-4, 1.0
    r, ind = 0.3, 0.3e-3
    return JointParams(
        name="inertia", motor_inertia_kgm2=jm, torque_constant_nm_per_a=kt,
        resistance_ohm=r, inductance_h=ind, supply_v=1e6, max_current_a=1e6,
        gear_ratio=n, load_inertia_kgm2=jl, viscous_nm_s_per_rad=0.0, coulomb_nm=0.0,
        gravity_nm=0.0, position_kp_per_s=kp,
        velocity_kp_a_s_per_rad=(jl + n * n * jm) * a / (n * kt), velocity_ki_per_s=0.0,
        current_kp_v_per_a=ind * 2 * math.pi * 2000, current_ki_per_s=r / ind)


def _closed_form_bandwidth(a: float, kp: float, velocity_ff: bool) -> float:
    def gain(f: float) -> float:
        s = 2j * math.pi * f
        return abs(a * (kp + (s if velocity_ff else 0)) / (s * s + a * s + a * kp))

    lo, hi = 1.0, 1000.0  # gain(lo) > 1/√2 > gain(hi); bisect on log f
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if gain(mid) > 1 / math.sqrt(2) else (lo, mid)
    return lo


@pytest.mark.parametrize("velocity_ff", [False, True])
def test_joint_bode_finds_a_known_bandwidth_within_5_percent(velocity_ff):
    a = 2 * math.pi * 60
    kp = a / 2  # ζ = 0.707: without feed-forward the -3 dB bandwidth is ωn = a/√2
    joint = _second_order_joint(a, kp)
    expected = _closed_form_bandwidth(a, kp, velocity_ff)
    if not velocity_ff:
        assert expected == pytest.approx(a / math.sqrt(2) / (2 * math.pi), rel=1e-6)
    bode = chirp_response(joint, Chirp(10, 500, 4.0, 0.0002),
                          BusTiming(500_000, 500_000, False),
                          velocity_ff=velocity_ff, current_ff=False)
    assert bode.bandwidth_hz == pytest.approx(expected, rel=0.05)


def test_joint_bode_command_on_a_joints_file(cli, tmp_path):
    """The same closed-form joint through the CLI and a joints file of its own."""
    a = 2 * math.pi * 60
    joint = _second_order_joint(a, a / 2)
    rows = "\n".join(f"{f.name} = {float(getattr(joint, f.name))!r}"
                     for f in dataclasses.fields(joint) if f.name != "name")
    path = tmp_path / "inertia.toml"
    path.write_text(f'[class.inertia]\n{rows}\n[joints]\n"Joint99 Inertia" = "inertia"\n')
    png = tmp_path / "fig10.png"
    doc = _json(cli, "joint", "bode", "--joints", str(path), "--joint", "Joint99",
                "--feedforward", "none", "--plot", str(png))
    assert doc["schema"] == "lolacli.joint-bode/1"
    assert doc["bandwidth_hz"] == pytest.approx(a / math.sqrt(2) / (2 * math.pi), rel=0.05)
    assert {"freq_hz", "gain_db", "phase_deg"} <= set(doc["points"][0])
    assert png.read_bytes()[:4] == b"\x89PNG"


# ---------------------------------------------------------------- the commands' contract


@pytest.mark.parametrize("args", [
    ("joint", "track", "--control-hz", "3000"),
    ("joint", "track", "--fast-bus-hz", "1500"),
    ("joint", "tune", "--joint", "no such joint"),
    ("joint", "tune", "--step-s", "nan"),
    ("joint", "bode", "--f-stop", "1500"),
    ("joint", "bode", "--f-start", "300", "--f-stop", "400"),
    ("joint", "bode", "--plot", "/no/such/folder/x.png"),
])
def test_bad_values_are_one_line_usage_errors(cli, args):
    code, out, err = cli(*args)
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("args", [("joint", "tune"), ("joint", "bode")])
def test_human_output_fits_80_columns(args):
    assert_fits(*human(*args), codes=(0,))


def test_track_human_output_fits_80_columns():
    code, out = human("joint", "track", "--steps", "2")
    assert_fits(code, out, codes=(0,))
    assert "mrad" in out and "kHz ref" in out


def test_ctrl_c_stops_a_long_run_within_a_second():
    proc = subprocess.Popen([sys.executable, "-m", "lolacli", "joint", "track", "--steps",
                             "50"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    time.sleep(1.5)  # started, and simulating
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == 130, err
    assert time.monotonic() - sent < 1.0
    assert err.decode().strip() == "lolacli: stopped by SIGINT"
