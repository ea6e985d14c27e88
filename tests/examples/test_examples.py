"""Our example ENIs, checked with independent ElementTree reads (not lolacli's parser), then
through the parser and the CLI.

The LOLA numbers come from the seed ("B. Bus Performance"): 25 slaves, 294 bus variables,
1026 bytes of input/output data, one 846-byte frame (67.7 us at 100 Mbit/s).
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from lolacli.wire.commands import addressed_wkc, wkc_increment

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "lolacli" / "eni_examples"
NAMES = ["lola.xml", "single_drive.xml", "ek1100_io.xml"]
LRW, ARMW, BRD, FPWR = 12, 13, 7, 5


def num(text: str | None) -> int:
    t = (text or "").strip()
    return int(t[2:], 16) if t.lower().startswith("#x") else int(t)


def config(name: str) -> ET.Element:
    root = ET.parse(EXAMPLES / name).getroot()
    assert root.tag == "EtherCATConfig"
    cfg = root.find("Config")
    assert cfg is not None
    return cfg


def variables(cfg: ET.Element, part: str) -> list[tuple[str, int, int]]:
    return [
        (v.findtext("Name"), num(v.findtext("BitOffs")), num(v.findtext("BitSize")))
        for v in cfg.findall(f"ProcessImage/{part}/Variable")
    ]


def fmmus(slave: ET.Element) -> list[tuple[int, int, int, int]]:
    """(logical start, length, physical start, type) of each FMMU InitCmd (FPWR 0x06n0)."""
    out = []
    for cmd in slave.findall("InitCmds/InitCmd"):
        ado = num(cmd.findtext("Ado"))
        data = bytes.fromhex(cmd.findtext("Data") or "")
        if num(cmd.findtext("Cmd")) == FPWR and 0x600 <= ado < 0x700 and any(data):
            assert len(data) == 16, "an FMMU register set is 16 bytes"
            logical, length, sbit, ebit, phys, pbit, kind, act = struct.unpack(
                "<IHBBHBBB", data[:13]
            )
            assert (sbit, ebit, pbit, act) == (0, 7, 0, 1)
            out.append((logical, length, phys, kind))
    return out


def sm_registers(slave: ET.Element) -> dict[int, tuple[int, int, int]]:
    out = {}
    for cmd in slave.findall("InitCmds/InitCmd"):
        ado = num(cmd.findtext("Ado"))
        data = bytes.fromhex(cmd.findtext("Data") or "")
        if num(cmd.findtext("Cmd")) == FPWR and 0x800 <= ado < 0x880 and any(data):
            start, length, control = struct.unpack("<HHB", data[:5])
            out[(ado - 0x800) // 8] = (start, length, control)
    return out


def cyclic_cmds(cfg: ET.Element) -> list[ET.Element]:
    frames = cfg.findall("Cyclic/Frame")
    assert len(frames) == 1
    return frames[0].findall("Cmd")


def wire_bytes(cmds: list[ET.Element]) -> int:
    return max(64, 14 + 2 + sum(12 + num(c.findtext("DataLength")) for c in cmds) + 4)


def test_lola_totals_match_the_seed():
    cfg = config("lola.xml")
    slaves = cfg.findall("Slave")
    assert len(slaves) == 25
    ins, outs = variables(cfg, "Inputs"), variables(cfg, "Outputs")
    assert len(ins) + len(outs) == 294
    in_bytes = num(cfg.findtext("ProcessImage/Inputs/ByteSize"))
    out_bytes = num(cfg.findtext("ProcessImage/Outputs/ByteSize"))
    assert in_bytes + out_bytes == 1026
    cmds = cyclic_cmds(cfg)
    assert [num(c.findtext("Cmd")) for c in cmds] == [LRW, ARMW, BRD]
    assert wire_bytes(cmds) == 846
    assert 8 * wire_bytes(cmds) / 100e6 == pytest.approx(67.68e-6)
    assert num(cfg.findtext("Cyclic/CycleTime")) == 500


def test_lola_chain_identity_and_dc():
    slaves = config("lola.xml").findall("Slave")
    drives = [s for s in slaves if num(s.findtext("Info/VendorId")) == 0x9A]
    assert len(drives) == 21
    assert {num(s.findtext("Info/ProductCode")) for s in drives} == {0x30924}
    assert {num(s.findtext("Info/RevisionNo")) for s in drives} == {0x10420}
    refs = [s for s in slaves if s.findtext("DC/ReferenceClock") == "true"]
    assert refs == [slaves[0]]  # the first motion controller is the reference clock
    for s in drives:
        assert num(s.findtext("DC/CycleTime0")) == 500_000
        assert num(s.findtext("DC/AssignActivate")) == 0x0300
        coe = {(num(c.findtext("Index")), num(c.findtext("SubIndex"))): c.findtext("Data")
               for c in s.findall("Mailbox/CoE/InitCmds/InitCmd")}  # fmt: skip
        assert coe[(0x6060, 0)] == "08"  # cyclic synchronous position
        assert coe[(0x1C12, 1)] == "0016" and coe[(0x1C13, 1)] == "001a"
    names = [s.findtext("Info/Name") for s in slaves]
    assert any("CAN Gateway" in n for n in names)
    assert sum(num(s.findtext("Info/ProductCode")) == 0x044C2C52 for s in slaves) == 1


@pytest.mark.parametrize("name", NAMES)
def test_addresses_and_chain(name):
    slaves = config(name).findall("Slave")
    for i, s in enumerate(slaves):
        assert num(s.findtext("Info/PhysAddr")) == 1001 + i
        assert num(s.findtext("Info/AutoIncAddr")) == (-i) & 0xFFFF
        station = [c for c in s.findall("InitCmds/InitCmd") if num(c.findtext("Ado")) == 0x10]
        assert bytes.fromhex(station[0].findtext("Data")) == struct.pack("<H", 1001 + i)
        if i:
            assert num(s.findtext("PreviousPort/PhysAddr")) == 1000 + i


@pytest.mark.parametrize("name", NAMES)
def test_fmmus_process_data_and_image_agree(name):
    """Read and write FMMUs of a slave share a logical start; Send/Recv and every variable
    sit at (FMMU logical start - LRW address) in the images; lengths agree; no two slaves
    overlap in the logical area."""
    cfg = config(name)
    lrw = next(c for c in cyclic_cmds(cfg) if num(c.findtext("Cmd")) == LRW)
    base, length = num(lrw.findtext("Addr")), num(lrw.findtext("DataLength"))
    assert num(lrw.findtext("InputOffs")) == 0 and num(lrw.findtext("OutputOffs")) == 0
    ins, outs = variables(cfg, "Inputs"), variables(cfg, "Outputs")
    areas = []
    for s in cfg.findall("Slave"):
        mapped = fmmus(s)
        sms = sm_registers(s)
        for part, kind, var_list in (("Recv", 1, ins), ("Send", 2, outs)):
            bit_start = s.findtext(f"ProcessData/{part}/BitStart")
            f = [m for m in mapped if m[3] == kind]
            if bit_start is None:
                assert not f
                continue
            ((logical, n, phys, _),) = f
            assert num(bit_start) == (logical - base) * 8
            assert num(s.findtext(f"ProcessData/{part}/BitLength")) == n * 8
            assert any(start == phys and size == n for start, size, _ in sms.values())
            prefix = s.findtext("Info/Name") + "."
            own = [v for v in var_list if v[0].startswith(prefix)]
            assert own and all(num(bit_start) <= o and o + b <= num(bit_start) + n * 8
                               for _, o, b in own)  # fmt: skip
        starts = {m[0] for m in mapped}
        assert len(starts) <= 1, "read and write FMMU share the logical start"
        if mapped:
            areas.append((min(starts), max(m[1] for m in mapped)))
    areas.sort()
    for (a, n), (b, _) in zip(areas, areas[1:], strict=False):
        assert a + n <= b
    assert areas[0][0] == base and areas[-1][0] + areas[-1][1] == base + length
    assert sum(n for _, n in areas) == length


@pytest.mark.parametrize("name", NAMES)
def test_images_are_gap_free_windows_of_the_lrw(name):
    cfg = config(name)
    for part in ("Inputs", "Outputs"):
        size = num(cfg.findtext(f"ProcessImage/{part}/ByteSize"))
        bits = sorted((o, b) for _, o, b in variables(cfg, part))
        for (o1, b1), (o2, _) in zip(bits, bits[1:], strict=False):
            assert o1 + b1 <= o2, "variables do not overlap"
        assert bits[-1][0] + bits[-1][1] <= size * 8


def test_lola_images_are_dense():
    cfg = config("lola.xml")
    for part in ("Inputs", "Outputs"):
        size = num(cfg.findtext(f"ProcessImage/{part}/ByteSize"))
        assert sum(b for _, _, b in variables(cfg, part)) == size * 8


@pytest.mark.parametrize("name", NAMES)
def test_cnt_follows_the_expected_wkc_rule(name):
    """LRW: each slave by its FMMUs' types; ARMW and BRD: 1 per slave (wire's one rule)."""
    cfg = config(name)
    slaves = cfg.findall("Slave")
    want_lrw = 0
    for s in slaves:
        kinds = {m[3] for m in fmmus(s)}
        want_lrw += wkc_increment(LRW, read=1 in kinds, write=2 in kinds)
    for c in cyclic_cmds(cfg):
        cmd, cnt = num(c.findtext("Cmd")), num(c.findtext("Cnt"))
        assert cnt == (want_lrw if cmd == LRW else addressed_wkc(cmd, len(slaves)))


@pytest.mark.parametrize("name", NAMES)
def test_sync_manager_sizes_match_the_pdos(name):
    for s in config(name).findall("Slave"):
        for sm in s.findall("ProcessData/*"):
            if not sm.tag.startswith("Sm") or sm.findtext("Type") not in ("Inputs", "Outputs"):
                continue
            assigned = {num(p.text) for p in sm.findall("Pdo")}
            tag = "TxPdo" if sm.findtext("Type") == "Inputs" else "RxPdo"
            pdos = [
                p for p in s.findall(f"ProcessData/{tag}") if num(p.findtext("Index")) in assigned
            ]
            bits = sum(num(e.findtext("BitLen")) for p in pdos for e in p.findall("Entry"))
            assert (bits + 7) // 8 == num(sm.findtext("DefaultSize"))
            index = int(sm.tag[2:])
            start, length, _ = sm_registers(s)[index]
            assert (start, length) == (num(sm.findtext("StartAddress")), (bits + 7) // 8)


def test_generator_output_is_committed_and_deterministic(tmp_path):
    out = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "make_examples.py"), "--out", str(tmp_path)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert "variables=294" in out.stdout and "frame_bytes=846" in out.stdout
    for name in NAMES:
        assert (tmp_path / name).read_bytes() == (EXAMPLES / name).read_bytes(), name


def test_packaged_default_is_the_lola_chain():
    from lolacli.cli.common import default_eni

    assert default_eni().resolve() == (EXAMPLES / "lola.xml").resolve()
    assert (ROOT / "eni_examples" / "lola.xml").resolve() == (EXAMPLES / "lola.xml").resolve()


# --------------------------------------------------------------------------- lolacli itself


def test_parser_reads_lola():
    from lolacli.files import load_eni

    eni = load_eni(EXAMPLES / "lola.xml")
    assert len(eni.slaves) == 25
    assert len(eni.process_image.variables) == 294
    assert eni.process_image.inputs_bytes + eni.process_image.outputs_bytes == 1026
    assert [f.frame_bytes for f in eni.cyclic_frames] == [846]
    assert eni.cycle_time_ns == 500_000


def test_cli_inspect_lola(cli):
    code, out, _ = cli("eni", "inspect", str(EXAMPLES / "lola.xml"), "--format", "json")
    assert code == 0
    doc = json.loads(out)
    assert len(doc["slaves"]) == 25
    pi = doc["process_image"]
    assert len(pi["variables"]) == 294 and pi["inputs_bytes"] + pi["outputs_bytes"] == 1026
    (frame,) = doc["cyclic_frames"]
    assert frame["frame_bytes"] == 846 and frame["wire_time_us"] == pytest.approx(67.68)
    assert [d["expected_wkc"] for d in frame["datagrams"]] == [70, 25, 25]


@pytest.mark.parametrize("name", NAMES)
def test_cli_validate_has_no_findings(cli, name):
    code, out, _ = cli("eni", "validate", str(EXAMPLES / name), "--format", "json")
    doc = json.loads(out)
    assert code == 0, doc["findings"]
    assert doc["findings"] == []
