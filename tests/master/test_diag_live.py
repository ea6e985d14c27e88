"""Acceptance of `lolacli bus diag` over a veth pair: `bus emulate --bad-link K:P` in its
own process, `bus diag` as a whole process naming the link; a clean bus says "no errors".
Needs root; skipped cleanly otherwise."""

from __future__ import annotations

import pytest

from tests.live import run, run_json, start_emulator, stop_emulator

pytestmark = [pytest.mark.root, pytest.mark.slow]


@pytest.mark.parametrize("k", [1, 13, 25])
def test_names_the_bad_link(bus, k: int) -> None:
    proc = start_emulator(bus, "--bad-link", f"{k}:0.05")
    try:
        code, doc, err = run_json(
            "bus", "diag", "--iface", bus.master, "--interval", "1s", "--reset", bus=bus
        )
        human = run("bus", "diag", "--iface", bus.master, "--interval", "0.3s", bus=bus)
    finally:
        stop_emulator(proc)
    assert code == 1, err
    assert doc["schema"] == "lolacli.diag/1"
    link = doc["suspect_link"]
    assert (link["upstream"], link["downstream"], link["port"]) == (k - 1, k, 0)
    assert doc["probe_frames_lost"] > 0
    assert human.returncode == 1, human.stderr
    upstream = "the master" if k == 1 else f"slave {k - 1} ("
    assert f"suspect link: {upstream}" in " ".join(human.stdout.split())
    assert max(len(line) for line in human.stdout.splitlines()) <= 80


def test_a_clean_bus_says_no_errors(bus) -> None:
    proc = start_emulator(bus)
    try:
        human = run("bus", "diag", "--iface", bus.master, "--interval", "0.5s", bus=bus)
    finally:
        stop_emulator(proc)
    assert human.returncode == 0, human.stderr
    assert "no errors: no error counter rose in" in human.stdout


def test_bad_input_is_one_line(bus) -> None:
    done = run("bus", "diag", "--iface", bus.master, "--interval", "soon", bus=bus)
    assert done.returncode == 2 and "--interval" in done.stderr
    assert "Traceback" not in done.stderr
    done = run("bus", "diag", "--iface", bus.master, "--interval", "0.2s", "--timeout",
               "5ms", "--retries", "0", bus=bus)  # fmt: skip
    assert done.returncode == 4 and len(done.stderr.strip().splitlines()) == 1
