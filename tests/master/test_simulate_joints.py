"""`bus simulate --joints`: a joint (motor, gear, link, the drive's cascade) behind each
drive the joints file names; a move's following error then carries the joint's dynamics
on top of the bus's delay, and the joint settles on the target. Bad or foreign joints
files are one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

from lolacli.files import joints_path, load_eni
from lolacli.simulate import options_from_cli, simulate

ROOT = Path(__file__).resolve().parents[2]
LOLA = ROOT / "lolacli" / "eni_examples" / "lola.xml"
MOVES = ("L Hip Pitch:20000", "L Knee:-20000", "R Elbow:20000")


def _sim(**kw: object) -> dict:
    return simulate(load_eni(LOLA), options_from_cli(rate_hz=2000.0, duration="0.6s",
                                                     moves=MOVES, **kw)).doc  # type: ignore[arg-type]


def test_joints_follow_with_their_dynamics_and_settle_on_the_target() -> None:
    kinematic, joints = _sim(), _sim(joints=True)
    assert kinematic["joints"] is None
    assert joints["joints"]["file"] == str(joints_path())
    assert len(joints["joints"]["drives"]) == 21
    for doc in (kinematic, joints):
        assert doc["verdict"] == "pass", doc["findings"]
    for k, j in zip(kinematic["moves"], joints["moves"], strict=True):
        assert (k["load"], j["load"]) == ("kinematic", "joint")
        assert k["joint"] == j["joint"] and k["complete"] and j["complete"]
        assert j["following_error_rms"] > 1.1 * k["following_error_rms"], (k, j)
        assert j["following_error_max"] > k["following_error_max"]
        assert k["end_position"] == k["target_position"]
        assert abs(j["end_position"] - j["target_position"]) <= 3, j


def test_a_joints_file_puts_joints_only_behind_the_drives_it_names(tmp_path: Path) -> None:
    text = joints_path().read_text()
    head, _, table = text.partition("[joints]\n")
    knee_only = tmp_path / "knee.toml"
    knee_only.write_text(head + '[joints]\n"Joint04 L Knee" = "knee"\n')
    doc = _sim(joints_file=knee_only)
    assert doc["joints"] == {"file": str(knee_only), "drives": ["Joint04 L Knee"],
                             "k_e": 0.0, "kvel_ff": 1.0}
    assert {m["joint"]: m["load"] for m in doc["moves"]} == {
        "Joint03 L Hip Pitch": "kinematic", "Joint04 L Knee": "joint",
        "Joint21 R Elbow": "kinematic"}


def test_bad_joints_are_one_line_errors(cli, tmp_path: Path) -> None:
    broken = tmp_path / "broken.toml"
    broken.write_text("[class.x]\nmotor_inertia_kgm2 = = 1\n")
    foreign = tmp_path / "foreign.toml"
    foreign.write_text(joints_path().read_text().replace('"Joint', '"Arm'))
    for args, code, said in (
        (("--joints", broken), 3, f"{broken}:2:"),
        (("--joints", tmp_path / "none.toml"), 3, "no such file"),
        (("--joints", foreign), 2, "no drive of"),
        (("--joint-model", "--iface", "lo"), 2, "--joint-model"),
        (("--ke", "0.5", "--iface", "lo"), 2, "--ke"),
        (("--ke", "5.5"), 2, "--ke 5.5: expected -1 to 5"),
        (("--ke", "-1.01"), 2, "--ke -1.01: expected -1 to 5"),
        (("--ke", "nan"), 2, "--ke nan"),
        (("--ke", "much"), 2, "--ke: "),
    ):
        got, out, err = cli("bus", "simulate", "--duration", "10ms", *args)
        assert (got, out) == (code, ""), err
        assert err.count("\n") == 1 and said in err and "Traceback" not in err, err


def test_the_json_says_the_load_of_each_move(cli) -> None:
    code, out, err = cli("bus", "simulate", "--duration", "50ms", "--move", "L Knee:100",
                         "--joint-model", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert [m["load"] for m in doc["moves"]] == ["joint"]


def test_ke_sets_every_joints_velocity_feedforward_and_implies_the_joint_model(cli) -> None:
    """--ke K: k_vel,ff = 1 + K in every joint's cascade (seed 000 eq. 2), the joint model
    on without --joint-model; the JSON's joints say both. A larger velocity feed-forward
    changes how the joints follow: the following errors differ from k_e = 0's."""
    code, out, err = cli("bus", "simulate", "--duration", "300ms", "--move", "L Knee:20000",
                         "--ke", "0.5", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["joints"]["k_e"] == 0.5 and doc["joints"]["kvel_ff"] == 1.5
    assert len(doc["joints"]["drives"]) == 21 and doc["moves"][0]["load"] == "joint"
    plain = _sim(joints=True)
    assert plain["joints"]["k_e"] == 0.0 and plain["joints"]["kvel_ff"] == 1.0
    ahead = _sim(k_e=1.0)
    assert ahead["joints"]["k_e"] == 1.0
    for p, a in zip(plain["moves"], ahead["moves"], strict=True):
        assert a["load"] == "joint"
        assert a["following_error_rms"] != p["following_error_rms"], (p, a)


def test_without_the_c_core_the_joints_run_in_python_and_stderr_says_so_once() -> None:
    """No C core built: the whole chain, joints and all, runs the Python reference (the
    fallback policy of lolacli.emulator.core), and stderr says so in one line, once."""
    import os
    import subprocess
    import sys

    script = (
        "import lolacli.emulator.core as c\n"
        "c.core_available = lambda: False\n"
        "from lolacli.cli.main import main\n"
        "main(['bus', 'simulate', '--duration', '30ms', '--move', 'L Knee:100', '--ke', '0.2',"
        " '--format', 'json'])\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "LOLACLI_CHAIN_ENGINE"}
    env["PYTHONPATH"] = str(ROOT)
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                          text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("is not built") == 1 and done.stderr.count("\n") <= 2, done.stderr
    doc = json.loads(done.stdout)
    assert doc["joints"]["k_e"] == 0.2 and doc["moves"][0]["load"] == "joint"
