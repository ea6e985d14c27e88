"""`bus data`: the live process image by ENI variable name, over the emulated chain in
process (fast), one live run over veth (`bus emulate` in its own process)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest
from typer.testing import CliRunner

from lolacli.cli.main import app
from lolacli.eni.model import Direction
from lolacli.errors import UsageError
from lolacli.files import load_eni
from lolacli.master.data import LiveData, parse_setting, select
from lolacli.simulate import VirtualBus
from tests.live import LOLA, ROOT

runner = CliRunner()
CONTROLWORD = "Joint04 L Knee.Outputs.Controlword"
TARGET = "Joint04 L Knee.Outputs.Target position"


@pytest.fixture(scope="module")
def lola():
    return load_eni(LOLA)


def _in_slave(bus: VirtualBus, eni, name: str) -> bytes:
    """The bytes of output ``name`` as the emulated slave holds them in its output SM."""
    v = next(x for x in eni.process_image.variables if x.name == name)
    slave_name = name.split(".")[0]
    slave = next(s for s in eni.slaves if s.name == slave_name)
    first = min(
        x.bit_offset
        for x in eni.process_image.variables
        if x.direction is Direction.OUTPUT and x.name.startswith(slave_name + ".")
    )
    sm = next(c.sync_manager for c in slave.sync_managers if c.kind == "Outputs")
    at = sm.physical_start + (v.bit_offset - first) // 8
    esc = bus.chain.slaves[slave.position - 1]
    return bytes(esc.mem[at : at + v.bit_size // 8])


def test_set_reaches_the_emulated_slave_and_the_drive_answers(lola) -> None:
    bus = VirtualBus(lola)
    live = LiveData(lola, bus.transport, select(lola, ["Joint04*"]))
    live.bring_up()
    before = live.values()["Joint04 L Knee.Inputs.Statusword"]
    live.write([parse_setting(lola, f"{CONTROLWORD}=6"), parse_setting(lola, f"{TARGET}=-123456")])
    live.run_for(20 * live.master.cycle_time_ns)
    assert _in_slave(bus, lola, CONTROLWORD) == (6).to_bytes(2, "little")
    assert _in_slave(bus, lola, TARGET) == (-123456).to_bytes(4, "little", signed=True)
    values = live.values()
    assert values[CONTROLWORD] == 6 and values[TARGET] == -123456
    # CiA 402: "shutdown" (6) takes the drive to "ready to switch on" (0x21 in bits 0-6)
    after = values["Joint04 L Knee.Inputs.Statusword"]
    assert after & 0x6F == 0x21 and after != before
    assert all(s["state"] == "OP" for s in live.states())
    live.leave()
    assert {s for _p, s in live.master.al_states()} == {1}  # INIT again


def test_cli_snapshot_is_typed_by_name(lola) -> None:
    r = runner.invoke(app, ["bus", "data", "--filter", "Joint04*", "--set", f"{TARGET}=0x10",
                            "--format", "json"])  # fmt: skip
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["schema"] == "lolacli.data/1" and doc["bus"] == "emulated"
    names = [v["name"] for v in doc["variables"]]
    want = [v.name for v in lola.process_image.variables if v.name.startswith("Joint04 L Knee.")]
    assert names == want
    types = {v["name"]: v["type"] for v in doc["variables"]}
    assert types[TARGET] == "DINT" and types["Joint04 L Knee.Inputs.Statusword"] == "UINT"
    assert doc["values"][TARGET] == 16 and doc["written"] == [{"name": TARGET, "value": 16}]
    assert len(doc["states"]) == len(lola.slaves)


def test_human_table_fits_80_columns(lola) -> None:
    r = runner.invoke(app, ["bus", "data", "--filter", "Statusword"], env={"COLUMNS": "80"})
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert max(len(line) for line in lines) <= 80
    assert "25 slaves on the emulated chain (lola.xml), 25 in OP" in lines[0]
    want = sum("Statusword" in v.name for v in lola.process_image.variables)
    assert sum("Statusword" in line for line in lines) == want > 1


def test_watch_prints_json_lines_and_stops_at_count(lola) -> None:
    r = runner.invoke(app, ["bus", "data", "--filter", "*Position actual*", "--watch", "50",
                            "--count", "3"])  # fmt: skip
    assert r.exit_code == 0, r.output
    samples = [json.loads(line) for line in r.stdout.splitlines()]
    assert len(samples) == 3
    assert all(s["schema"] == "lolacli.data/1" for s in samples)
    assert samples[0]["cycle"] < samples[1]["cycle"] < samples[2]["cycle"]
    want = {v.name for v in lola.process_image.variables if "Position actual" in v.name}
    assert set(samples[0]["values"]) == want and len(want) > 1


@pytest.mark.parametrize(
    ("item", "words"),
    [
        ("Joint04 L Knee.Outputs.Controlwrd=6", ["no variable", f"did you mean '{CONTROLWORD}'"]),
        (f"{CONTROLWORD}=70000", ["outside 0..65535"]),
        (f"{CONTROLWORD}=six", ["not an integer"]),
        ("Joint04 L Knee.Inputs.Statusword=1", ["is an input"]),
        ("Controlword", ["expected NAME=VALUE"]),
    ],
)
def test_bad_set_is_one_line_and_nothing_runs(lola, item: str, words: list[str]) -> None:
    with pytest.raises(UsageError) as err:
        parse_setting(lola, item)
    for w in words:
        assert w in str(err.value)
    r = runner.invoke(app, ["bus", "data", "--set", item])
    assert r.exit_code == 2
    assert len(r.stderr.strip().splitlines()) == 1 and r.stdout == ""


def test_filter_matching_nothing_and_count_without_watch() -> None:
    r = runner.invoke(app, ["bus", "data", "--filter", "no such thing"])
    assert r.exit_code == 2 and "matches none" in r.stderr
    r = runner.invoke(app, ["bus", "data", "--count", "2"])
    assert r.exit_code == 2 and "--watch" in r.stderr


def test_ctrl_c_leaves_within_a_second_with_130() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "lolacli", "bus", "data", "--filter", "*Statusword",
         "--watch", "5"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert proc.stdout is not None
    first = proc.stdout.readline()  # in OP, sampling
    assert json.loads(first)["schema"] == "lolacli.data/1"
    proc.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    out, err = proc.communicate(timeout=20)
    assert time.monotonic() - t0 < 1.0
    assert proc.returncode == 130, err
    assert len(err.strip().splitlines()) <= 1
    for line in out.splitlines():
        json.loads(line)  # whole lines only


@pytest.mark.root
@pytest.mark.slow
def test_live_data_over_veth_set_and_read_back() -> None:
    from tests.live import make_bus, remove_bus, run, start_emulator, stop_emulator

    bus = make_bus("d")
    try:
        proc = start_emulator(bus)
        try:
            done = run("bus", "data", "--iface", bus.master, "--filter", "Joint04*",
                       "--set", f"{CONTROLWORD}=6", "--format", "json", bus=bus,
                       timeout=180)  # fmt: skip
            watch = run("bus", "data", "--iface", bus.master, "--filter", "*Statusword",
                        "--watch", "20", "--count", "3", bus=bus, timeout=180)  # fmt: skip
        finally:
            stop_emulator(proc)
    finally:
        remove_bus(bus)
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert doc["bus"] == "live" and all(s["state"] == "OP" for s in doc["states"])
    assert doc["values"][CONTROLWORD] == 6
    assert doc["values"]["Joint04 L Knee.Inputs.Statusword"] & 0x6F == 0x21
    assert watch.returncode == 0, watch.stderr
    assert len([json.loads(x) for x in watch.stdout.splitlines()]) == 3
