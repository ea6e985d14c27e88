"""`bus simulate` with the line and host inputs of :mod:`lolacli.simulate.variation`: the
round trip is the formula with everything off, the seed's 124.1 ± 10.2 µs with the seed's
host figures, moved by port physics and cable lengths as the ESC/cable figures say,
reproducible for a seed; bad values are one-line usage errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from lolacli.files import load_eni
from lolacli.simulate import SimulateOptions, simulate
from lolacli.timing.model import SEED_HOST_LATENCY_US, HostLatency, wire_time_ns

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "lolacli" / "eni_examples"
LOLA = EXAMPLES / "lola.xml"
#: the seed's measured round trip (seed 000 §VI-B): mean and standard deviation, µs
SEED_ROUND_TRIP_US = (124.1, 10.2)


def _sim(name: str = "lola.xml", **fields: object) -> dict:
    options = SimulateOptions(**{"cycles": 2000, "middleware": False, **fields})  # type: ignore[arg-type]
    result = simulate(load_eni(EXAMPLES / name), options)
    assert not result.failed, result.doc["findings"]
    return result.doc


def _host(mean_us: float, std_us: float) -> HostLatency:
    return HostLatency(round(mean_us * 1000), round(std_us * 1000))


def test_everything_off_is_the_formula_every_cycle() -> None:
    doc = _sim()
    rt = doc["round_trip_us"]
    # 846 B at 100 Mbit/s + 25 × 1000 ns + 25 segments × 2 × 1 m × 5 ns/m
    formula = (wire_time_ns(846) + 25 * 1000 + 25 * 2 * 5) / 1000
    assert formula == 92.93
    assert rt["min"] == rt["max"] == rt["mean"] == formula and rt["std"] == 0
    assert doc["host_latency_us"] is None
    src = doc["timing_sources"]
    assert src["host_latency"] is None and src["seed"] is None
    assert src["forwarding"]["mode"] == "model"
    assert src["forwarding"]["slaves_by_delay_ns"] == {"1000": 25}
    assert src["cable"] == {
        **src["cable"], "m_per_segment": 1.0, "ns_per_m": 5.0, "delay_ns": 250
    }
    assert src["formula_bus_round_trip_us"] == src["formula_round_trip_us"] == formula


def test_the_seeds_host_figures_give_the_seeds_round_trip() -> None:
    """31.2 ± 10.2 µs of host (the seed's 124.1 µs less the 92.93 µs bus) on the LOLA
    chain: mean within 10 % of 124.1 µs, spread within 20 % of 10.2 µs; every frame at
    least the bus's own 92.93 µs."""
    doc = _sim(cycles=4000, host_latency=_host(*SEED_HOST_LATENCY_US), seed=3)
    rt = doc["round_trip_us"]
    mean, std = SEED_ROUND_TRIP_US
    assert abs(rt["mean"] - mean) <= 0.1 * mean, rt
    assert 0.8 * std <= rt["std"] <= 1.2 * std, rt
    assert rt["min"] >= 92.93 and rt["max"] > rt["p99"] > rt["median"]
    assert doc["host_latency_us"] == {
        "mean": 31.2, "std": 10.2, "distribution": "lognormal", "source": "--host-latency-us"
    }
    assert doc["timing_sources"]["seed"] == 3
    assert doc["timing_sources"]["formula_round_trip_us"] == round(92.93 + 31.2, 3)
    assert doc["lost_frames"] == doc["late_frames"] == 0


def test_a_constant_host_latency_moves_the_round_trip_not_its_spread() -> None:
    rt = _sim(host_latency=_host(25, 0))["round_trip_us"]
    assert rt["min"] == rt["max"] == round(92.93 + 25, 3) and rt["std"] == 0


def test_the_same_seed_gives_the_same_round_trips_another_seed_others() -> None:
    host = _host(31.2, 10.2)
    a, b = (_sim(host_latency=host, seed=11)["round_trip_us"] for _ in range(2))
    c = _sim(host_latency=host, seed=12)["round_trip_us"]
    assert a == b
    assert c != a


def test_port_physics_sets_each_slaves_delay() -> None:
    """ek1100_io: an EK1100-like coupler (YYK) then three E-bus terminals (KK): 100BASE-TX
    link in (500 ns) and E-bus out (150 ns) for the coupler, 2 × 150 ns for each terminal."""
    eni = load_eni(EXAMPLES / "ek1100_io.xml")
    assert [s.physics for s in eni.slaves] == ["YYK", "KK", "KK", "KK"]
    doc = _sim("ek1100_io.xml", forwarding="physics")
    src = doc["timing_sources"]["forwarding"]
    assert src["per_slave_delay_ns"] == [650, 300, 300, 300]
    assert "ethercrab__replay-dc.pcapng" in src["source"]
    wire = wire_time_ns(doc["frame_bytes"])
    expected = (wire + 650 + 3 * 300 + 4 * 2 * 5) / 1000
    rt = doc["round_trip_us"]
    assert rt["min"] == rt["max"] == expected
    model = _sim("ek1100_io.xml")["round_trip_us"]
    assert model["max"] == (wire + 4 * 1000 + 4 * 2 * 5) / 1000


def test_lola_by_port_physics() -> None:
    """22 drives and the gateway on 100BASE-TX, a coupler, two E-bus terminals."""
    doc = _sim(forwarding="physics")
    src = doc["timing_sources"]["forwarding"]
    assert src["slaves_by_delay_ns"] == {"300": 2, "650": 1, "1000": 22}
    assert doc["round_trip_us"]["max"] == round(92.93 - (25_000 - 23_250) / 1000, 3)


def test_cable_lengths_per_segment_and_for_all() -> None:
    longer = _sim(cable_m=("3=50",))
    # segment 3 at 50 m instead of 1: 49 m × 5 ns/m, out and back
    assert longer["round_trip_us"]["max"] == round(92.93 + 2 * 49 * 5 / 1000, 3)
    assert longer["timing_sources"]["cable"]["m_per_segment"][2] == 50.0
    every = _sim(cable_m=("10",))
    assert every["round_trip_us"]["max"] == round(92.93 + 25 * 2 * 9 * 5 / 1000, 3)
    assert every["timing_sources"]["cable"]["m_per_segment"] == 10.0


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "lolacli", "bus", "simulate", "--duration", "0.5s", *args],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
        env={**__import__("os").environ, "COLUMNS": "80"},
    )  # fmt: skip


def test_cli_json_and_human_say_which_inputs_made_the_round_trip() -> None:
    out = run("--host-latency-us", "31.2:10.2", "--seed", "5", "--format", "json")
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["schema"] == "lolacli.simulate/1"
    assert doc["host_latency_us"]["mean"] == 31.2 and doc["round_trip_us"]["std"] > 0
    again = json.loads(run("--host-latency-us", "31.2:10.2", "--seed", "5",
                           "--format", "json").stdout)
    assert again["round_trip_us"] == doc["round_trip_us"]
    human = run("--host-latency-us", "31.2:10.2", "--forwarding", "physics")
    assert human.returncode == 0, human.stderr
    lines = human.stdout.splitlines()
    assert any(line.startswith("host latency") and "mean 31.2 µs, std 10.2 µs" in line
               for line in lines)
    assert any(line.startswith("slave delays") and "22 × 1,000 ns" in line for line in lines)
    assert max(len(line.rstrip()) for line in lines) <= 80
    default = run()
    assert "host latency         none (the round trip is the bus alone)" in default.stdout
    assert "formula              92.93 µs bus" in default.stdout


@pytest.mark.parametrize(
    "args",
    [
        ("--host-latency-us", "-5"),
        ("--host-latency-us", "abc"),
        ("--host-latency-us", "5:-1"),
        ("--host-latency-us", "1e9"),
        ("--host-latency-us", "0:5"),
        ("--host-latency-us", "nan"),
        ("--host-latency-us", "1:2:3"),
        ("--cable-m", "101"),
        ("--cable-m", "26=5"),
        ("--cable-m", "x=5"),
        ("--forwarding", "esc"),
        ("--host-latency-us", "30", "--iface", "lo"),
    ],
)
def test_bad_values_are_one_line_usage_errors(args: tuple[str, ...]) -> None:
    out = run(*args)
    assert out.returncode == 2, out.stderr
    assert out.stdout == ""
    assert out.stderr.count("\n") == 1 and out.stderr.startswith("lolacli: error: ")
    assert args[0] in out.stderr
