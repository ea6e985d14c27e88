"""FoE through our master against the emulated chain in this process: `lolacli foe
write/read` without --iface, the library session under it (lolacli.sdo.foe), and the
master's FoE client (lolacli.master.foe) on the bootstrap mailbox the SII states.

The acceptance's figure is a 1 MiB firmware with its password, written and read back
equal after the slave's return from BOOT to INIT; the errors a drive's bootloader answers
with (wrong password, a write outside BOOT, a file it does not have) reach the user as
FoE errors with their codes (exit 1).
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest

from lolacli.emulator.registers import AlState
from lolacli.errors import FoeError, UsageError
from lolacli.sdo.foe import LolaFoeSession, open_foe
from lolacli.sdo.session import TransportOptions

PASSWORD = 0xC0FFEE
MIB = 1024 * 1024


def _session(password: int = PASSWORD) -> LolaFoeSession:
    session = open_foe(TransportOptions())
    assert isinstance(session, LolaFoeSession)
    for esc in session.bus.transport.processor.slaves:  # type: ignore[attr-defined]
        if esc.app.foe is not None:
            esc.app.foe.password = password
    return session


def _esc(session: LolaFoeSession, position: int):
    return session.bus.transport.processor.slaves[position - 1]  # type: ignore[attr-defined]


def test_a_mebibyte_with_its_password_reads_back_after_boot_to_init() -> None:
    firmware = random.Random(24).randbytes(MIB)
    with _session() as session:
        target = session.target("3")
        written = target.write("drive.efw", firmware, PASSWORD)
        esc = _esc(session, 3)
        assert esc.al_state == AlState.INIT and not esc.al_error  # back from BOOT
        assert esc.app.files.files["drive.efw"] == firmware
        step = 1024 - 12  # the emulated slave's bootstrap mailbox: 1 KiB each way
        assert written.packets == MIB // step + 1 and written.busy == 1
        assert written.bytes == MIB and written.direction == "write"
        data, read = target.read("drive.efw", PASSWORD)
        assert data == firmware and read.packets == written.packets
        assert esc.al_state == AlState.INIT
        others = [_esc(session, p).app.files.files for p in (1, 2, 4)]
        assert others == [{}, {}, {}]  # a file is the slave's own


def test_wrong_password_and_unknown_file_are_foe_errors() -> None:
    with _session() as session:
        target = session.target("2")
        with pytest.raises(FoeError) as wrong:
            target.write("fw", b"abc", PASSWORD + 1)
        assert wrong.value.code == 0x800A and "password" in str(wrong.value)
        assert wrong.value.exit_code == 1
        assert _esc(session, 2).al_state == AlState.INIT  # left BOOT all the same
        with pytest.raises(FoeError) as missing:
            target.read("fw", PASSWORD)
        assert missing.value.code == 0x8001


def test_a_write_outside_boot_gets_bootstrap_only() -> None:
    """FoE over the standard mailbox in PREOP, as a master that skips BOOT would try."""
    from lolacli.master.foe import FoeClient
    from lolacli.sdo.address import resolve_ref

    with _session() as session:
        bus = session.bus
        ref = resolve_ref("4", bus.slaves(), source="test")
        slave = bus.bus.bring_up(bus.eni.slaves[ref.position - 1])  # PREOP
        mailbox = bus.bus.master.mailbox(slave)
        mailbox.port = bus.port
        with pytest.raises(FoeError) as refused:
            FoeClient(mailbox, "slave 4").write("fw", b"abc", PASSWORD)
        assert refused.value.code == 0x8008
        assert "only in BOOT" in str(refused.value)
        assert _esc(session, 4).al_state == AlState.PREOP


def test_a_slave_without_bootloader_is_a_usage_error(tmp_path: Path) -> None:
    from lolacli.files import load_eni

    eni = Path(__file__).resolve().parents[2] / "lolacli" / "eni_examples" / "ek1100_io.xml"
    coupler = next(s for s in load_eni(eni).slaves if s.mailbox is None)
    with open_foe(TransportOptions(eni=eni)) as session:
        with pytest.raises(UsageError, match="no bootstrap mailbox"):
            session.target(str(coupler.position)).write("fw", b"x")


def _json(cli, *args: str) -> tuple[int, dict]:
    code, out, _err = cli("foe", *args, "-f", "json")
    return code, json.loads(out) if out.strip() else {}


def test_the_commands_in_process(cli, tmp_path: Path) -> None:
    firmware = tmp_path / "app.bin"
    firmware.write_bytes(random.Random(5).randbytes(5000))
    code, doc = _json(cli, "write", "1", str(firmware))
    assert code == 0, doc
    assert doc["schema"] == "lolacli.foe/1" and doc["name"] == "app.bin"
    assert doc["size_bytes"] == 5000 and doc["packets"] == 5 and doc["busy_answers"] == 1
    assert doc["backend"] == "lolacli" and len(doc["sha256"]) == 64
    code, out, _err = cli("foe", "write", "1", str(firmware), "--name", "x")
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == "slave 1: wrote 'x', 5,000 bytes" and "slave back in INIT" in lines[1]
    assert all(len(line) <= 80 for line in lines)
    # each command is a chain of its own: the file written above is gone
    code, doc = _json(cli, "read", "1", "app.bin", "-o", str(tmp_path / "back.bin"))
    assert code == 1 and doc["error"]["code"] == "0x8001"
    code, doc = _json(cli, "write", "1", str(firmware), "--password", "0x10")
    assert code == 1 and doc["error"]["code"] == "0x800A"


@pytest.mark.parametrize(
    ("args", "code"),
    [
        (["write", "1", "/no/such/file"], 3),
        (["write", "1", "{fw}", "--password", "-1"], 2),
        (["write", "1", "{fw}", "--password", "0x100000000"], 2),
        (["write", "1", "{fw}", "--password", "secret"], 2),
        (["read", "1", "fw"], 2),  # no -o
        (["write", "1", "{fw}", "--backend", "soem"], 2),  # soem needs --iface
        (["write", "99", "{fw}"], 2),
    ],
)
def test_bad_usage_and_input(cli, tmp_path: Path, args: list[str], code: int) -> None:
    fw = tmp_path / "fw.bin"
    fw.write_bytes(b"x")
    got, _out, err = cli("foe", *[a.replace("{fw}", str(fw)) for a in args])
    assert got == code, err
    assert len(err.strip().splitlines()) == 1


def test_a_file_without_end_is_refused_at_the_limit(cli) -> None:
    """/dev/zero as the firmware: read up to the limit and refused (exit 3), not read
    until memory runs out."""
    from lolacli.cli.foe import MAX_WRITE_BYTES

    code, out, err = cli("foe", "write", "3", "/dev/zero")
    assert code == 3 and out == ""
    assert f"larger than {MAX_WRITE_BYTES:,} bytes" in err


def test_ctrl_c_is_exit_130(tmp_path: Path) -> None:
    """SIGINT in the middle of a transfer (60 MiB, about 6 s here; the signal comes once
    the process has used 0.8 s of CPU, past its start-up): one line, exit 130."""
    import os
    import signal
    import subprocess
    import sys
    import time

    big = tmp_path / "big.bin"
    big.write_bytes(random.Random(3).randbytes(60 * MIB))
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen(
        [sys.executable, "-m", "lolacli", "foe", "write", "2", str(big)],
        cwd=root, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    tick = os.sysconf("SC_CLK_TCK")
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        with open(f"/proc/{proc.pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        if (int(fields[11]) + int(fields[12])) / tick >= 0.8:  # utime + stime
            break
        time.sleep(0.02)
    assert proc.poll() is None, proc.communicate()
    start = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert time.monotonic() - start < 1.0
    assert out == "" and err.strip().splitlines() == ["lolacli: stopped by SIGINT"]
