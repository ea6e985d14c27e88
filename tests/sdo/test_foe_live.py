"""Acceptance, FoE on a live bus: real masters write a firmware to `lolacli bus emulate`
over a veth pair (in a network namespace of its own, tests/live.py) and read it back.

* pysoem as its own firmware-update example does it: INIT, SM0/SM1 amended to the
  bootstrap mailbox read from the SII, BOOT, ``foe_write`` of 1 MiB with the password;
  INIT, BOOT again, ``foe_read`` gives the same bytes;
* SOEM's ``firm_update`` (built from pysoem's sdist, tests/emulator/soem_tools.py), which
  sends the file's path as its name with password 0; our master reads it back;
* ``lolacli foe write/read --iface`` (our master, and ``--backend soem``) the same;
* a wrong password, and FoE over the standard mailbox in PREOP, get the FoE error: SOEM's
  result -5 (EC_ERR_TYPE_FOE_ERROR: SOEM keeps the code to itself), our master the code
  (0x800A "no rights", 0x8008 "bootstrap only") and exit 1.
"""

from __future__ import annotations

import hashlib
import random
import re
import struct
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.live import (
    LiveBus,
    inside,
    make_bus,
    remove_bus,
    run,
    run_json,
    start_emulator,
    stop_emulator,
)

pytestmark = [pytest.mark.root, pytest.mark.slow, pytest.mark.timeout(600)]
PASSWORD = 0x2A2A_0001
MIB = 1024 * 1024
SLAVE = 3  # a drive of the LOLA chain
SOEM_FOE_ERROR = -5  # EC_ERR_TYPE_FOE_ERROR
TIMEOUT_US = 2_000_000


@pytest.fixture(scope="module")
def bus() -> Iterator[LiveBus]:
    """`bus emulate` (the LOLA chain) whose slaves' bootloaders take PASSWORD."""
    live = make_bus("f")
    try:
        proc = start_emulator(live, "--foe-password", str(PASSWORD))
        try:
            yield live
        finally:
            stop_emulator(proc)
    finally:
        remove_bus(live)


@pytest.fixture
def pysoem():
    return pytest.importorskip("pysoem")


def _firmware(seed: int, size: int = MIB) -> bytes:
    return random.Random(seed).randbytes(size)


class Soem:
    """pysoem on the bus, its slaves scanned (PREOP), SOEM's timeouts raised as
    lolacli.sdo.soem_client raises them for the emulated chain on a loaded host."""

    def __init__(self, pysoem, bus: LiveBus) -> None:
        self.pysoem = pysoem
        t = pysoem.settings.timeouts
        t.ret, t.safe = max(t.ret, 20_000), max(t.safe, 100_000)
        t.tx_mailbox, t.rx_mailbox = max(t.tx_mailbox, TIMEOUT_US), max(t.rx_mailbox, TIMEOUT_US)
        self.master = pysoem.Master()
        with inside(bus):
            self.master.open(bus.master)
        assert self.master.config_init() > SLAVE
        self.slave = self.master.slaves[SLAVE - 1]

    def state(self, state: int) -> None:
        self.slave.state = state
        self.slave.write_state()
        assert self.slave.state_check(state, 5_000_000) == state, hex(self.slave.al_status)

    def boot(self) -> None:
        """As pysoem's examples/firmware_update.py."""
        p = self.pysoem
        self.state(p.INIT_STATE)
        out, out_bytes = struct.unpack("<HH", self.slave.eeprom_read(p.SiiOffset.BOOT_RX_MBX))
        inn, in_bytes = struct.unpack("<HH", self.slave.eeprom_read(p.SiiOffset.BOOT_TX_MBX))
        assert out_bytes == in_bytes == 1024  # the emulated slave's bootstrap mailbox
        self.slave.amend_mbx("out", out, out_bytes)
        self.slave.amend_mbx("in", inn, in_bytes)
        self.state(p.BOOT_STATE)

    def close(self) -> None:
        self.master.close()


def test_pysoem_writes_and_reads_back_a_mebibyte_with_its_password(bus, pysoem) -> None:
    firmware = _firmware(1)
    soem = Soem(pysoem, bus)
    try:
        soem.boot()
        assert soem.slave.foe_write("pysoem.efw", PASSWORD, firmware, TIMEOUT_US) > 0
        soem.state(pysoem.INIT_STATE)  # the bootloader hands over; the file stays
        soem.boot()
        back = soem.slave.foe_read("pysoem.efw", PASSWORD, 2 * MIB, TIMEOUT_US)
        assert len(back) == MIB and back == firmware
        assert soem.slave.foe_write("pysoem.efw", PASSWORD + 1, b"x" * 10, TIMEOUT_US) == (
            SOEM_FOE_ERROR
        )
        soem.state(pysoem.INIT_STATE)
    finally:
        soem.close()
    # our master reads what pysoem wrote, through a BOOT of its own
    out = bus_file(bus, "pysoem.efw")
    code, doc, err = run_json(
        "foe", "read", str(SLAVE), "pysoem.efw", "-o", str(out), "--password", str(PASSWORD),
        "--iface", bus.master, "--timeout", "2", bus=bus,
    )  # fmt: skip
    assert code == 0, err
    assert out.read_bytes() == firmware and doc["sha256"] == hashlib.sha256(firmware).hexdigest()


def test_pysoem_foe_in_preop_gets_the_foe_error(bus, pysoem) -> None:
    soem = Soem(pysoem, bus)
    try:
        soem.state(pysoem.PREOP_STATE)  # the standard mailbox, as config_init set it
        assert soem.slave.foe_write("fw", PASSWORD, b"abc", TIMEOUT_US) == SOEM_FOE_ERROR
    finally:
        soem.close()


def bus_file(bus: LiveBus, name: str) -> Path:
    path = Path("/tmp") / f"{bus.netns}-{name}"
    path.unlink(missing_ok=True)
    return path


@pytest.mark.parametrize("backend", ["lolacli", "soem"])
def test_lolacli_foe_over_iface_round_trips(bus, backend: str) -> None:
    if backend == "soem":
        pytest.importorskip("pysoem")
    firmware = _firmware(7)
    source = bus_file(bus, f"{backend}-fw.bin")
    source.write_bytes(firmware)
    back = bus_file(bus, f"{backend}-back.bin")
    common = ["--password", hex(PASSWORD), "--iface", bus.master, "--backend", backend]
    common += ["--timeout", "2"]
    try:
        code, doc, err = run_json("foe", "write", str(SLAVE), str(source), *common, bus=bus)
        assert code == 0, err
        assert doc["size_bytes"] == MIB and doc["backend"] == backend
        if backend == "lolacli":
            assert doc["packets"] == MIB // 1012 + 1 and doc["busy_answers"] == 1
        code, doc, err = run_json(
            "foe", "read", str(SLAVE), source.name, "-o", str(back), *common, bus=bus
        )
        assert code == 0, err
        assert back.read_bytes() == firmware
        done = run("foe", "read", str(SLAVE), source.name, "-o", str(back), *common, bus=bus)
        assert done.returncode == 0 and len(done.stdout.splitlines()) == 3
        assert all(len(line) <= 80 for line in done.stdout.splitlines())
        assert "KiB/s" in done.stdout and " s, " in done.stdout
    finally:
        source.unlink(missing_ok=True)
        back.unlink(missing_ok=True)


def test_lolacli_wrong_password_and_not_in_boot_are_exit_1(bus) -> None:
    source = bus_file(bus, "small.bin")
    source.write_bytes(b"firmware")
    try:
        code, doc, err = run_json(
            "foe", "write", str(SLAVE), str(source), "--password", "1",
            "--iface", bus.master, bus=bus,
        )  # fmt: skip
        assert code == 1, err
        assert doc["error"]["code"] == "0x800A"
        done = run("foe", "write", str(SLAVE), str(source), "--password", "1",
                   "--iface", bus.master, bus=bus)  # fmt: skip
        assert done.returncode == 1
        assert "FoE error 0x800A: no rights: the password is wrong" in done.stderr
    finally:
        source.unlink(missing_ok=True)
    # our master's FoE client over the standard mailbox in PREOP, as a master that skips
    # BOOT would try: the bootloader's error, its code
    from lolacli.errors import FoeError
    from lolacli.master.foe import FoeClient
    from lolacli.sdo.foe import LolaFoeSession, open_foe
    from lolacli.sdo.session import TransportOptions

    with inside(bus):  # the raw socket is opened in the bus's namespace
        session = open_foe(TransportOptions(iface=bus.master, timeout_s=2.0))
    assert isinstance(session, LolaFoeSession)
    with session:
        lola = session.bus
        slave = lola.bus.bring_up(lola.eni.slaves[SLAVE - 1])  # PREOP
        mailbox = lola.bus.master.mailbox(slave)
        mailbox.port = lola.port
        with pytest.raises(FoeError) as refused:
            FoeClient(mailbox, f"slave {SLAVE}").write("fw", b"abc", PASSWORD)
        assert refused.value.code == 0x8008 and refused.value.exit_code == 1


@pytest.fixture
def firm_update() -> Path:
    from tests.emulator.soem_tools import soem_tools

    tools, why = soem_tools()
    if tools is None:
        pytest.skip(f"SOEM's tools not built: {why}")
    return tools["firm_update"]


def test_soem_firm_update_writes_what_our_master_reads_back(firm_update: Path) -> None:
    """firm_update sends password 0: a chain of its own, without a password."""
    live = make_bus("u")
    try:
        proc = start_emulator(live)
        try:
            firmware = _firmware(11)
            source = bus_file(live, "firm.bin")
            source.write_bytes(firmware)
            done = subprocess.run(
                live.command(str(firm_update), live.master, str(SLAVE), str(source)),
                capture_output=True, text=True, timeout=300,
            )  # fmt: skip
            result = re.search(r"result (-?\d+)", done.stdout)
            assert result is not None and int(result.group(1)) > 0, done.stdout + done.stderr
            assert "SM0 A:" in done.stdout and "L:1024" in done.stdout
            back = bus_file(live, "firm-back.bin")
            name = str(source)  # firm_update names the file by its path
            code, _doc, err = run_json(
                "foe", "read", str(SLAVE), name, "-o", str(back), "--iface", live.master,
                "--timeout", "2", bus=live,
            )  # fmt: skip
            assert code == 0, (err, _doc)
            assert back.read_bytes() == firmware
            source.unlink(missing_ok=True)
            back.unlink(missing_ok=True)
        finally:
            stop_emulator(proc)
    finally:
        remove_bus(live)
