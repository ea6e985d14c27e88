"""Acceptance, EtherCAT through pysoem: ``lolacli sdo … --iface IF --backend soem`` against
``lolacli bus emulate`` at the other end of a veth pair, each in its own process.

The emulator answers from the device models' dictionaries (devices/od.py, cia402.py); the
values asserted are the ones those models define (0x1000 = 0x00020192, the ENI's vendor
in 0x1018:01, the long name in 0x1008 that needs a segmented upload).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lolacli.devices.cia402 import Cia402Drive

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "lolacli" / "eni_examples"
PREFIX = os.environ.get("LOLACLI_TEST_NETNS_PREFIX", "lcs")
pytestmark = [pytest.mark.root, pytest.mark.slow, pytest.mark.timeout(300)]


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True)


@pytest.fixture(scope="module")
def bus():
    """A veth pair with `bus emulate` (LOLA chain) on one end: yields the master's end."""
    pytest.importorskip("pysoem")
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("needs root and iproute2 for a veth pair")
    tag = f"{os.getpid() % 10000}{time.monotonic_ns() % 100:02d}"
    master, emulator = f"{PREFIX}m{tag}", f"{PREFIX}e{tag}"
    _ip("link", "add", master, "type", "veth", "peer", "name", emulator)
    proc = None
    try:
        for name in (master, emulator):
            subprocess.run(
                ["sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"], capture_output=True
            )
            _ip("link", "set", name, "up")
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "lolacli",
                "bus",
                "emulate",
                "--iface",
                emulator,
                "--eni",
                str(EXAMPLES / "lola.xml"),
                "--quiet",
            ],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert proc.stderr is not None
        line = proc.stderr.readline()
        assert "emulating" in line, line + proc.stderr.read()
        yield master
    finally:
        if proc is not None:
            proc.send_signal(2)
            proc.communicate(timeout=20)
        subprocess.run(["ip", "link", "del", master], capture_output=True, check=False)


def sdo(iface: str, *args: str) -> tuple[int, str, str]:
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "lolacli",
            "sdo",
            *args,
            "--iface",
            iface,
            "--backend",
            "soem",
            "--timeout",
            "2",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    return p.returncode, p.stdout, p.stderr


def value(iface: str, *args: str) -> dict:
    code, out, err = sdo(iface, *args, "-f", "json")
    assert code == 0, err
    return json.loads(out)


def _eni():
    from lolacli.files import load_eni

    return load_eni(EXAMPLES / "lola.xml")


def test_identity_and_strings(bus) -> None:
    eni = _eni()
    assert value(bus, "read", "5", "0x1000")["value"] == 0x00020192
    identity = value(bus, "read", "5", "0x1018:01")
    assert (identity["value"], identity["data_type"]) == (
        eni.slaves[4].identity.vendor_id,
        "UNSIGNED32",
    )
    product = value(bus, "read", "25", "0x1018:02")["value"]
    assert product == eni.slaves[24].identity.product_code
    name = value(bus, "read", "5", "0x1008")  # longer than the mailbox: segmented upload
    assert name["value"] == Cia402Drive.LONG_NAME and name["data_type"] == "VISIBLE_STRING"
    assert len(bytes.fromhex(name["raw_hex"])) > 128


def test_write_then_read_in_another_process(bus) -> None:
    code, _out, err = sdo(bus, "write", "5", "0x607F", "250000", "--type", "UNSIGNED32")
    assert code == 0, err
    read = value(bus, "read", "5", "0x607F", "--type", "u32")
    assert (read["value"], read["raw_hex"]) == (250000, "90d00300")
    assert sdo(bus, "write", "5", "0x607F", "0", "--type", "u32")[0] == 0


def test_slave_by_name_and_station_address(bus) -> None:
    eni = str(EXAMPLES / "lola.xml")
    by_name = value(bus, "read", "CAN Gateway", "0x1008", "--eni", eni)
    assert by_name["value"] == "CAN Gateway (IMU, FTS)"
    # @1022 is the gateway's PhysAddr in the ENI
    assert value(bus, "read", "@1022", "0x1018:02", "--eni", eni)["value"] == 0xC01


def test_the_three_aborts(bus) -> None:
    for args, codes in (
        (("read", "5", "0x2345"), {"0x06020000"}),
        (("write", "5", "0x1000", "1"), {"0x06010002"}),
        # the emulator names the direction (too high/too low); 0x06070010 is the general code
        (("write", "5", "0x607F", "1", "--type", "u16"), {"0x06070010", "0x06070013"}),
        (("write", "5", "0x607F", "1", "--type", "u64"), {"0x06070010", "0x06070012"}),
    ):
        code, out, err = sdo(bus, *args, "-f", "json")
        doc = json.loads(out)
        assert code == 1 and doc["error"]["abort_code"] in codes, (args, doc, err)
        assert doc["error"]["message"]
        code, out, err = sdo(bus, *args)
        assert code == 1 and doc["error"]["abort_code"] in err and doc["error"]["message"] in err


def test_complete_access_and_list(bus) -> None:
    identity = value(bus, "read", "5", "0x1018", "--complete")
    assert identity["complete_access"] and identity["value"][0] == {"subindex": 0, "value": 4}
    assert identity["value"][1] == {"subindex": 1, "value": _eni().slaves[4].identity.vendor_id}
    code, out, err = sdo(bus, "list", "5", "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["source"] == "sdo_info"
    indexes = {o["index"] for o in doc["objects"]}
    assert {0x1000, 0x1008, 0x1018, 0x6040, 0x6041} <= indexes


def test_no_such_interface_and_no_slave(bus) -> None:
    code, _out, err = sdo("e11nosuch0", "read", "1", "0x1000")
    assert code == 4 and "e11nosuch0" in err
    code, _out, err = sdo(bus, "read", "26", "0x1000")
    assert code == 2 and "position 26" in err


def test_the_check_file_of_the_docs(bus, tmp_path) -> None:
    text = (ROOT / "docs" / "sdo.md").read_text(encoding="utf-8")
    example = text.split("```yaml\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "drive5.yaml"
    path.write_text(example)
    eni = str(EXAMPLES / "lola.xml")
    code, out, err = sdo(bus, "check", str(path), "--eni", eni, "-f", "json")
    doc = json.loads(out)
    assert code == 0, (err, [r for r in doc["results"] if not r["ok"]])
    assert doc["checks"] == 7 and doc["failed"] == 0
