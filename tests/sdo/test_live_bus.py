"""Acceptance, EtherCAT on a live bus: ``lolacli sdo … --iface IF`` through our master
(``--backend lolacli``, the default) and through pysoem (``--backend soem``) against
``lolacli bus emulate`` at the other end of a veth pair, each in its own process (the
pair in a network namespace of its own: tests/live.py).

The emulator answers from the device models' dictionaries (lolacli/od, devices/cia402.py); the
values asserted are the ones those models define (0x1000 = 0x00020192, the ENI's vendor
in 0x1018:01, the long name in 0x1008 that needs a segmented upload). Every test runs
with both masters, and one compares what the two print for the same commands.

A wrong length, too long or too short, is 0x06070010 ("length of service parameter does
not match", CiA 301), the code every backend and the CANopen stacks give.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

from lolacli.devices.cia402 import Cia402Drive
from tests.live import (
    LOLA,
    ROOT,
    LiveBus,
    json_of,
    make_bus,
    remove_bus,
    run,
    start_emulator,
    stop_emulator,
)

pytestmark = [pytest.mark.root, pytest.mark.slow, pytest.mark.timeout(600)]
BACKENDS = ("lolacli", "soem")
WRONG_LENGTH_LOW = WRONG_LENGTH_HIGH = {"0x06070010"}


@pytest.fixture(scope="module")
def bus() -> Iterator[LiveBus]:
    """A veth pair with `bus emulate` (the LOLA chain) on one end."""
    live = make_bus("s")
    try:
        proc = start_emulator(live)
        try:
            yield live
        finally:
            stop_emulator(proc)
    finally:
        remove_bus(live)


@pytest.fixture(params=BACKENDS)
def backend(request: pytest.FixtureRequest) -> str:
    if request.param == "soem":
        pytest.importorskip("pysoem")
    return str(request.param)


def sdo(bus: LiveBus, backend: str, *args: str, iface: str | None = None) -> tuple[int, str, str]:
    done = run(
        "sdo", *args, "--iface", iface or bus.master, "--backend", backend, "--timeout", "2",
        bus=bus,
    )
    return done.returncode, done.stdout, done.stderr


def value(bus: LiveBus, backend: str, *args: str) -> dict:
    code, out, err = sdo(bus, backend, *args, "-f", "json")
    assert code == 0, err
    return json_of(out)


def _eni():
    from lolacli.files import load_eni

    return load_eni(LOLA)


def test_identity_and_strings(bus, backend) -> None:
    eni = _eni()
    assert value(bus, backend, "read", "5", "0x1000")["value"] == 0x00020192
    identity = value(bus, backend, "read", "5", "0x1018:01")
    assert (identity["value"], identity["data_type"]) == (
        eni.slaves[4].identity.vendor_id,
        "UNSIGNED32",
    )
    product = value(bus, backend, "read", "25", "0x1018:02")["value"]
    assert product == eni.slaves[24].identity.product_code
    name = value(bus, backend, "read", "5", "0x1008")  # longer than the mailbox: segmented
    assert name["value"] == Cia402Drive.LONG_NAME and name["data_type"] == "VISIBLE_STRING"
    assert len(bytes.fromhex(name["raw_hex"])) > 128


def test_write_then_read_in_another_process(bus, backend) -> None:
    written = 250000 if backend == "soem" else 250001
    code, _out, err = sdo(bus, backend, "write", "5", "0x607F", str(written), "--type", "u32")
    assert code == 0, err
    read = value(bus, backend, "read", "5", "0x607F", "--type", "u32")
    assert (read["value"], read["raw_hex"]) == (written, written.to_bytes(4, "little").hex())
    assert sdo(bus, backend, "write", "5", "0x607F", "0", "--type", "u32")[0] == 0


def test_what_one_master_writes_the_other_reads(bus) -> None:
    pytest.importorskip("pysoem")
    assert sdo(bus, "lolacli", "write", "7", "0x607F", "123456", "--type", "u32")[0] == 0
    assert value(bus, "soem", "read", "7", "0x607F", "--type", "u32")["value"] == 123456
    assert sdo(bus, "soem", "write", "7", "0x607F", "654321", "--type", "u32")[0] == 0
    assert value(bus, "lolacli", "read", "7", "0x607F", "--type", "u32")["value"] == 654321
    assert sdo(bus, "lolacli", "write", "7", "0x607F", "0", "--type", "u32")[0] == 0


def test_slave_by_name_and_station_address_of_the_eni(bus, backend) -> None:
    eni = str(LOLA)
    by_name = value(bus, backend, "read", "CAN Gateway", "0x1008", "--eni", eni)
    assert by_name["value"] == "CAN Gateway (IMU, FTS)"
    # @1022 is the gateway's PhysAddr in the ENI
    assert value(bus, backend, "read", "@1022", "0x1018:02", "--eni", eni)["value"] == 0xC01


def test_slave_by_name_and_station_address_of_the_bus(bus, backend) -> None:
    """Without an ENI both masters give stations 0x1001… in line order and read the names
    from the SII."""
    serial = value(bus, backend, "read", "@0x1005", "0x1018:04")["value"]
    assert serial == _eni().slaves[4].identity.serial
    by_name = value(bus, backend, "read", "CAN Gateway", "0x1018:02")
    assert by_name["value"] == 0xC01


def test_the_three_aborts(bus, backend) -> None:
    for args, codes in (
        (("read", "5", "0x2345"), {"0x06020000"}),
        (("write", "5", "0x1000", "1"), {"0x06010002"}),
        (("write", "5", "0x607F", "1", "--type", "u16"), WRONG_LENGTH_LOW),
        (("write", "5", "0x607F", "1", "--type", "u64"), WRONG_LENGTH_HIGH),
    ):
        code, out, err = sdo(bus, backend, *args, "-f", "json")
        doc = json_of(out)
        assert code == 1 and doc["error"]["abort_code"] in codes, (args, doc, err)
        assert doc["error"]["message"]
        code, out, err = sdo(bus, backend, *args)
        assert code == 1 and doc["error"]["abort_code"] in err and doc["error"]["message"] in err


def test_complete_access_and_list(bus, backend) -> None:
    identity = value(bus, backend, "read", "5", "0x1018", "--complete")
    assert identity["complete_access"] and identity["value"][0]["value"] == 4
    assert identity["value"][1]["value"] == _eni().slaves[4].identity.vendor_id
    assert identity["value"][1]["data_type"] == "UNSIGNED32"
    code, out, err = sdo(bus, backend, "list", "5", "-f", "json")
    assert code == 0, err
    doc = json_of(out)
    assert doc["source"] == "sdo-info"
    indexes = {o["index"] for o in doc["objects"]}
    assert {0x1000, 0x1008, 0x1018, 0x6040, 0x6041} <= indexes
    entry = next(o for o in doc["objects"] if o["index"] == 0x6041)["entries"][0]
    assert entry["data_type"] == "UNSIGNED16" and entry["name"] == "Statusword"


def test_no_such_interface_and_no_slave(bus, backend) -> None:
    code, _out, err = sdo(bus, backend, "read", "1", "0x1000", iface="e11nosuch0")
    assert code == 4 and "e11nosuch0" in err
    code, _out, err = sdo(bus, backend, "read", "26", "0x1000")
    assert code == 2 and "position 26" in err


def test_the_check_file_of_the_docs(bus, backend, tmp_path) -> None:
    text = (ROOT / "docs" / "sdo.md").read_text(encoding="utf-8")
    example = text.split("```yaml\n", 1)[1].split("```", 1)[0]
    path = tmp_path / "drive5.yaml"
    path.write_text(example)
    code, out, err = sdo(bus, backend, "check", str(path), "--eni", str(LOLA), "-f", "json")
    doc = json_of(out)
    assert code == 0, (err, [r for r in doc["results"] if not r["ok"]])
    assert doc["checks"] == 7 and doc["failed"] == 0


#: commands whose output must be the same through both masters
SAME = (
    ("read", "5", "0x1000"),
    ("read", "5", "0x1018:01"),
    ("read", "5", "0x1008"),
    ("read", "22", "0x1008"),
    ("read", "5", "0x1018", "--complete"),
    ("read", "5", "0x6060"),
    ("read", "25", "0x1018:02"),
    ("read", "5", "0x2345"),
    ("read", "5", "0x1018:09"),
    ("write", "5", "0x1000", "1"),
    ("write", "5", "0x607F", "1", "--type", "u16"),
    ("write", "5", "0x607F", "77", "--type", "u32"),
    ("read", "5", "0x607F", "--type", "u32"),
    ("write", "5", "0x607F", "0", "--type", "u32"),
)


def _transfer(doc: dict) -> dict:
    """What a master moved: the document without the name and where the type came from,
    which differ where our master asks the slave's SDO Information (pysoem reads it only
    whole) and pysoem's is CiA 301's or none; the type too unless --type gave it."""
    dropped = ("name", "type_source")
    if doc.get("type_source") != "--type":
        dropped += ("data_type",)
    kept = {k: v for k, v in doc.items() if k not in dropped}
    if isinstance(kept.get("value"), list):
        kept["value"] = [item["value"] for item in kept["value"]]
    return kept


def test_both_masters_print_the_same(bus) -> None:
    pytest.importorskip("pysoem")
    for args in SAME:
        ours = sdo(bus, "lolacli", *args, "-f", "json")
        theirs = sdo(bus, "soem", *args, "-f", "json")
        assert ours[0] == theirs[0], (args, ours, theirs)
        assert _transfer(json_of(ours[1])) == _transfer(json_of(theirs[1])), args
        typed = sdo(bus, "lolacli", *args, "--eni", str(LOLA), "-f", "json")
        by_soem = sdo(bus, "soem", *args, "--eni", str(LOLA), "-f", "json")
        mine, soem = json_of(typed[1]), json_of(by_soem[1])
        if mine.get("type_source") == "eni":  # the same source, the same words
            assert mine == soem, args
    ours_list = sdo(bus, "lolacli", "list", "22", "-f", "json")
    theirs_list = sdo(bus, "soem", "list", "22", "-f", "json")
    assert ours_list[0] == theirs_list[0] == 0
    mine, soem = json_of(ours_list[1]), json_of(theirs_list[1])
    assert [o["index"] for o in mine["objects"]] == [o["index"] for o in soem["objects"]]
    assert [o["name"] for o in mine["objects"]] == [o["name"] for o in soem["objects"]]


@pytest.fixture(scope="module")
def silent() -> Iterator[LiveBus]:
    """A veth pair with nothing at the other end."""
    live = make_bus("q")
    try:
        yield live
    finally:
        remove_bus(live)


def test_a_bus_that_does_not_answer_is_exit_4(silent, backend) -> None:
    t0 = time.monotonic()
    done = run(
        "sdo", "read", "5", "0x1000", "--iface", silent.master, "--backend", backend,
        "--timeout", "0.5",
        bus=silent,
    )
    code, err = done.returncode, done.stderr
    assert code == 4, err
    assert err.startswith("lolacli: error:") and err.count("\n") == 1
    assert time.monotonic() - t0 < 60


def _has_socket(pid: int) -> bool:
    """Whether the process has opened a raw packet socket: our master's, on the bus.
    (Not any socket: ``ip netns exec``, which execs into it, opens a netlink socket.)"""
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
        with open(f"/proc/{pid}/net/packet") as table:  # the namespace's packet sockets
            packet = {line.split()[-1] for line in table.readlines()[1:]}
    except (FileNotFoundError, ProcessLookupError):
        return False
    for fd in fds:
        try:
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:  # closed meanwhile
            continue
        if link.startswith("socket:[") and link[8:-1] in packet:
            return True
    return False


@pytest.mark.parametrize(
    ("command", "signum"),
    [
        (("list", "5"), signal.SIGINT),
        (("read", "5", "0x1000"), signal.SIGTERM),
        (("check", "CHECK"), signal.SIGINT),
    ],
    ids=["list", "read", "check"],
)
def test_a_stop_while_the_bus_does_not_answer(silent, tmp_path, command, signum) -> None:
    """Our master waiting on a bus where nothing answers (each frame up to 50 ms, sent
    again for --timeout 30 s): Ctrl-C or SIGTERM ends it within a second, exit 130/143;
    ``sdo check`` still reports (no item done)."""
    check = tmp_path / "drive5.yaml"
    check.write_text("slave: 5\nreads:\n  - {object: '0x1000', expect: 0x00020192}\n")
    args = [str(check) if a == "CHECK" else a for a in command]
    argv = [sys.executable, "-m", "lolacli", "sdo", *args, "--iface", silent.master]
    proc = subprocess.Popen(
        silent.command(*argv, "--eni", str(LOLA), "--timeout", "30"),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not _has_socket(proc.pid) and time.monotonic() < deadline:
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        time.sleep(0.5)  # into the frames' waits
        assert proc.poll() is None
        start = time.monotonic()
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    took = time.monotonic() - start
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum and took < 1.0, (took, err)
    assert "Traceback" not in err
    if command[0] == "check":
        assert out == f"stopped by {name} after 0 checks of 1: 0 passed, 0 failed\n", err
    else:
        assert out == "" and err == f"lolacli: stopped by {name}\n"
