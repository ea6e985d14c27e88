"""`bus simulate` with a drive whose following-error monitor is on (0x6065/0x6066 written
by the ENI's CoE InitCmds, as a configurator writes them): the joint motion outruns the
drive's velocity limit (0x607F), the drive faults with 0x8611 in 0x603F, and the run's
findings say so (``drive-fault``, failure: exit 1)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SINGLE = ROOT / "lolacli" / "eni_examples" / "single_drive.xml"
ANCHOR = "<CoE>\n\t\t\t\t\t<InitCmds>\n"


def _init_cmd(index: int, data: bytes, comment: str) -> str:
    return (
        "\t\t\t\t\t\t<InitCmd>\n"
        "\t\t\t\t\t\t\t<Transition>PS</Transition>\n"
        f"\t\t\t\t\t\t\t<Comment>{comment}</Comment>\n"
        "\t\t\t\t\t\t\t<Timeout>3000</Timeout>\n"
        "\t\t\t\t\t\t\t<Ccs>1</Ccs>\n"
        f"\t\t\t\t\t\t\t<Index>#x{index:04x}</Index>\n"
        "\t\t\t\t\t\t\t<SubIndex>0</SubIndex>\n"
        f"\t\t\t\t\t\t\t<Data>{data.hex()}</Data>\n"
        "\t\t\t\t\t\t</InitCmd>\n"
    )


def _eni(tmp_path: Path, max_velocity: int) -> Path:
    text = SINGLE.read_text()
    assert text.count(ANCHOR) == 1
    cmds = (
        _init_cmd(0x6065, (1000).to_bytes(4, "little"), "following error window")
        + _init_cmd(0x6066, (10).to_bytes(2, "little"), "following error time out (ms)")
        + _init_cmd(0x607F, max_velocity.to_bytes(4, "little"), "max profile velocity")
    )
    path = tmp_path / f"drive_{max_velocity}.xml"
    path.write_text(text.replace(ANCHOR, ANCHOR + cmds))
    return path


def _simulate(eni: Path) -> tuple[int, dict]:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "lolacli",
            "bus",
            "simulate",
            "--eni",
            str(eni),
            "--duration",
            "1s",
            "--format",
            "json",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    return done.returncode, json.loads(done.stdout)


def test_a_following_error_past_its_window_is_a_drive_fault_finding(tmp_path: Path) -> None:
    code, doc = _simulate(_eni(tmp_path, 1_000))  # 1 increment a ms: the motion outruns it
    assert code == 1 and doc["verdict"] == "fail"
    assert doc["drive_faults"] == [{"slave": 1, "name": "Drive", "faults": 1, "error_code": 0x8611}]
    found = [f for f in doc["findings"] if f["kind"] == "drive-fault"]
    assert len(found) == 1 and found[0]["slave"] == 1 and found[0]["severity"] == "failure"
    assert "0x8611 (following error)" in found[0]["message"]
    assert "Drive" in found[0]["message"]


def test_a_drive_that_keeps_up_has_no_fault(tmp_path: Path) -> None:
    code, doc = _simulate(_eni(tmp_path, 10_000_000))  # fast enough to follow
    assert code == 0, doc["findings"]
    assert doc["drive_faults"] == [] and doc["drives_enabled"] == 1
    assert not [f for f in doc["findings"] if f["kind"] == "drive-fault"]
