"""`eni validate` range checks: a number just outside the width the EtherCAT/CoE specs give
its field is one ``value-out-of-range`` error naming slave and element; just inside, none.

File-level cases mutate one field of ``eni_examples/single_drive.xml`` (text replacement in a
tmp copy) and run the CLI; model-level cases also cover the fields a file cannot carry out of
range (register blocks decoded from InitCmd data) and models built in code.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import pytest

from lolacli.eni.model import Eni, Slave
from lolacli.eni.parser import parse_eni
from lolacli.eni.validate import RANGE_CODE, check_field_ranges, validate_eni
from lolacli.findings import Finding, Severity

EXAMPLES = Path(__file__).resolve().parents[2] / "lolacli" / "eni_examples"
SINGLE_DRIVE = (EXAMPLES / "single_drive.xml").read_text()

#: single_drive.xml without the InitCmd that writes SM2, so <Sm2> itself configures it.
_SM2_INIT_CMD = (
    "\t\t\t\t<InitCmd>\n\t\t\t\t\t<Transition>PS</Transition>\n"
    "\t\t\t\t\t<Comment>SM2 outputs</Comment>\n\t\t\t\t\t<Cmd>5</Cmd>\n"
    "\t\t\t\t\t<Adp>1001</Adp>\n\t\t\t\t\t<Ado>2064</Ado>\n"
    "\t\t\t\t\t<Data>00110b0064000100</Data>\n\t\t\t\t\t<Cnt>1</Cnt>\n"
    "\t\t\t\t</InitCmd>\n"
)
assert SINGLE_DRIVE.count(_SM2_INIT_CMD) == 1
SM2_DECLARED = SINGLE_DRIVE.replace(_SM2_INIT_CMD, "")

DRIVE = 1  # the only slave of single_drive.xml


@dataclass(frozen=True)
class Case:
    """Replace the first ``old`` after ``anchor`` (all ``count`` of them when no anchor)."""

    id: str
    anchor: str | None
    old: str
    template: str  # "{}" takes the value
    outside: str
    inside: str
    label: str  # the element as the finding names it
    slave: int | None = DRIVE
    count: int = 1
    base: str = SINGLE_DRIVE
    cascades: frozenset[str] = frozenset()  # other errors the value rightly triggers

    def text(self, value: str) -> str:
        new = self.template.format(value)
        if self.anchor is None:
            assert self.base.count(self.old) == self.count, self.old
            return self.base.replace(self.old, new)
        assert self.base.count(self.anchor) == 1, self.anchor
        at = self.base.index(self.old, self.base.index(self.anchor))
        return self.base[:at] + new + self.base[at + len(self.old) :]


ENTRY = "TxPdo 0x1A00 Entry 1 (Statusword)"
LRW = "cyclic task 1 frame 1 Cmd 1 (LRW):"
BRD = "cyclic task 1 frame 1 Cmd 2 (BRD):"
AL_STATUS = "<Comment>AL status of every slave</Comment>"
PD_CMD = "<Comment>process data: outputs"
WATCHDOG = "<Comment>watchdog divider 100 us</Comment>"
INTERPOLATION = "<Comment>interpolation period: 5 x 10^-4 s</Comment>"
C = Case
CASES = [
    # slave identity and addresses: kept as written by the parser (not folded into 16 or 32
    # bits), except negative values within the width (AutoIncAddr -1 is 0xFFFF)
    C("phys-addr", None, "<PhysAddr>1001</PhysAddr>", "<PhysAddr>{}</PhysAddr>", "65536",
      "65535", "<Info><PhysAddr>"),
    C("auto-inc-addr", None, "<AutoIncAddr>#x0000</AutoIncAddr>",
      "<AutoIncAddr>{}</AutoIncAddr>", "-32769", "-1", "<Info><AutoIncAddr>"),
    C("vendor-id", None, "<VendorId>#x0000009a</VendorId>", "<VendorId>{}</VendorId>",
      "#x100000000", "-1", "<Info><VendorId>"),
    C("product-code", None, "<ProductCode>#x00030924</ProductCode>",
      "<ProductCode>{}</ProductCode>", "#x100000000", "#xffffffff", "<Info><ProductCode>"),
    C("serial-no", None, "<SerialNo>4097</SerialNo>", "<SerialNo>{}</SerialNo>",
      "-2147483649", "-2147483648", "<Info><SerialNo>"),
    C("cyclic-ado", AL_STATUS, "<Ado>#x0130</Ado>", "<Ado>{}</Ado>", "#x10000", "#xffff",
      f"{BRD} <Ado>", slave=None),
    C("cyclic-addr", PD_CMD, "<Addr>#x00010000</Addr>", "<Addr>{}</Addr>", "#x100000000",
      "#xffffffff", f"{LRW} <Addr>", slave=None, cascades=frozenset({"wkc-mismatch"})),
    # PDOs (ETG.1000.6: object index u16, subindex u8; mapping entry u32 = index|sub|bits)
    C("pdo-index", "<TxPdo", "<Index>#x1a00</Index>", "<Index>{}</Index>", "#x10000", "#xffff",
      "TxPdo 0x10000 <Index>"),
    C("pdo-index-neg", "<TxPdo", "<Index>#x1a00</Index>", "<Index>{}</Index>", "-1", "0",
      "TxPdo -1 <Index>"),
    C("pdo-sm", "<TxPdo", 'Sm="3"', 'Sm="{}"', "16", "15", "TxPdo 0x1A00 Sm"),
    C("entry-index", None, "<Index>#x6041</Index>", "<Index>{}</Index>", "#x10000", "#xffff",
      f"{ENTRY} <Index>"),
    C("entry-subindex", "<Index>#x6041</Index>", "<SubIndex>0</SubIndex>",
      "<SubIndex>{}</SubIndex>", "256", "255", f"{ENTRY} <SubIndex>"),
    C("entry-subindex-neg", "<Index>#x6041</Index>", "<SubIndex>0</SubIndex>",
      "<SubIndex>{}</SubIndex>", "-1", "0", f"{ENTRY} <SubIndex>"),
    C("entry-bitlen", "<Index>#x6041</Index>", "<BitLen>16</BitLen>", "<BitLen>{}</BitLen>",
      "256", "255", f"{ENTRY} <BitLen>", cascades=frozenset({"pdo-overruns-sm"})),
    C("entry-bitlen-padding", "<Index>#x6041</Index>", "<BitLen>16</BitLen>",
      "<BitLen>{}</BitLen>", "-1", "0", f"{ENTRY} <BitLen>"),
    # sync managers (ETG.1000.4 Table 58), declared by <SmN> when no InitCmd writes them
    C("sm-index", None, "Sm3>", "Sm{}>", "16", "15", "SM16 index", count=2),
    C("sm-start", "<Type>Outputs</Type>", "<StartAddress>#x1100</StartAddress>",
      "<StartAddress>{}</StartAddress>", "65536", "65535", "SM2 start address",
      base=SM2_DECLARED),
    C("sm-length", "<Type>Outputs</Type>", "<DefaultSize>11</DefaultSize>",
      "<DefaultSize>{}</DefaultSize>", "65536", "65535", "SM2 length", base=SM2_DECLARED),
    C("sm-control", "<Type>Outputs</Type>", "<ControlByte>#x64</ControlByte>",
      "<ControlByte>{}</ControlByte>", "256", "255", "SM2 control byte", base=SM2_DECLARED),
    # mailbox (the mailbox SMs' start and length are u16)
    C("mbx-send-start", "<Mailbox>", "<Start>#x1800</Start>", "<Start>{}</Start>", "65536",
      "65535", "<Mailbox><Send><Start>"),
    C("mbx-send-length", "<Mailbox>", "<Length>140</Length>", "<Length>{}</Length>", "65536",
      "65535", "<Mailbox><Send><Length>"),
    C("mbx-recv-start", "<Mailbox>", "<Start>#x1900</Start>", "<Start>{}</Start>", "65536",
      "65535", "<Mailbox><Recv><Start>"),
    C("mbx-poll-time", "<Mailbox>", "<PollTime>20</PollTime>", "<PollTime>{}</PollTime>", "-1",
      "0", "<Mailbox><Recv><PollTime>"),
    C("coe-index", INTERPOLATION, "<Index>#x60c2</Index>", "<Index>{}</Index>", "#x10000",
      "#xffff", "(interpolation period: 5 x 10^-4 s) <Index>"),
    C("coe-subindex", INTERPOLATION, "<SubIndex>1</SubIndex>", "<SubIndex>{}</SubIndex>", "256",
      "255", "(interpolation period: 5 x 10^-4 s) <SubIndex>"),
    C("coe-ccs", INTERPOLATION, "<Ccs>1</Ccs>", "<Ccs>{}</Ccs>", "8", "7",
      "(interpolation period: 5 x 10^-4 s) <Ccs>"),
    C("coe-timeout", INTERPOLATION, "<Timeout>3000</Timeout>", "<Timeout>{}</Timeout>", "-1",
      "0", "(interpolation period: 5 x 10^-4 s) <Timeout>"),
    # distributed clocks (registers 0x0980 u16, 0x09A0/0x09A4 u32)
    C("dc-cycle0", None, "<CycleTime0>1000000</CycleTime0>", "<CycleTime0>{}</CycleTime0>",
      "4294967296", "4294967295", "<DC><CycleTime0>"),
    C("dc-cycle1", None, "<CycleTime1>0</CycleTime1>", "<CycleTime1>{}</CycleTime1>", "-1", "0",
      "<DC><CycleTime1>"),
    C("dc-shift-high", None, "<ShiftTime>0</ShiftTime>", "<ShiftTime>{}</ShiftTime>",
      "2147483648", "2147483647", "<DC><ShiftTime>"),
    C("dc-shift-low", None, "<ShiftTime>0</ShiftTime>", "<ShiftTime>{}</ShiftTime>",
      "-2147483649", "-2147483648", "<DC><ShiftTime>"),
    C("dc-assign-activate", None, "<AssignActivate>#x0300</AssignActivate>",
      "<AssignActivate>{}</AssignActivate>", "#x10000", "#xffff", "<DC><AssignActivate>"),
    # process data areas (bits of the image)
    C("pd-send-bitstart", "<ProcessData>", "<BitStart>0</BitStart>", "<BitStart>{}</BitStart>",
      "-1", "0", "<ProcessData><Send><BitStart>"),
    C("pd-send-bitlength", "<ProcessData>", "<BitLength>88</BitLength>",
      "<BitLength>{}</BitLength>", "-1", "0", "<ProcessData><Send><BitLength>"),
    # InitCmds (ETG.1000.4 datagram: Cmd u8, WKC u16)
    C("slave-initcmd-cmd", WATCHDOG, "<Cmd>5</Cmd>", "<Cmd>{}</Cmd>", "256", "255",
      "(watchdog divider 100 us) <Cmd>"),
    C("slave-initcmd-cnt", WATCHDOG, "<Cnt>1</Cnt>", "<Cnt>{}</Cnt>", "65536", "65535",
      "(watchdog divider 100 us) <Cnt>"),
    C("slave-initcmd-timeout", "<Comment>request INIT (acknowledge errors)</Comment>",
      "<Timeout>3000</Timeout>", "<Timeout>{}</Timeout>", "-1", "0",
      "(request INIT (acknowledge errors)) <Timeout>"),
    C("slave-initcmd-validate-timeout", "<Comment>check INIT</Comment>",
      "<Timeout>3000</Timeout>", "<Timeout>{}</Timeout>", "-1", "0",
      "(check INIT) <Validate><Timeout>"),
    C("master-initcmd-cmd", "<Comment>count slaves (AL status)</Comment>", "<Cmd>7</Cmd>",
      "<Cmd>{}</Cmd>", "256", "255", "master: InitCmd 1 (count slaves (AL status)) <Cmd>",
      slave=None),
    # cyclic commands (datagram header: Cmd u8, 11-bit length, WKC u16); cycle time > 0
    C("cyclic-cmd", PD_CMD, "<Cmd>12</Cmd>", "<Cmd>{}</Cmd>", "256", "255",
      "cyclic task 1 frame 1 Cmd 1 (CMD256): <Cmd>", slave=None,
      cascades=frozenset({"wkc-mismatch"})),
    C("cyclic-datalength", PD_CMD, "<DataLength>11</DataLength>", "<DataLength>{}</DataLength>",
      "2048", "2047", f"{LRW} <DataLength>", slave=None),
    C("cyclic-datalength-neg", AL_STATUS, "<DataLength>2</DataLength>",
      "<DataLength>{}</DataLength>", "-1", "0", f"{BRD} <DataLength>", slave=None),
    C("cyclic-cnt", PD_CMD, "<Cnt>3</Cnt>", "<Cnt>{}</Cnt>", "65536", "65535", f"{LRW} <Cnt>",
      slave=None, cascades=frozenset({"wkc-mismatch"})),
    C("cyclic-input-offs", PD_CMD, "<InputOffs>0</InputOffs>", "<InputOffs>{}</InputOffs>", "-1",
      "0", f"{LRW} <InputOffs>", slave=None),
    C("cyclic-output-offs", PD_CMD, "<OutputOffs>0</OutputOffs>", "<OutputOffs>{}</OutputOffs>",
      "-1", "0", f"{LRW} <OutputOffs>", slave=None),
    C("cycle-time", None, "<CycleTime>1000</CycleTime>", "<CycleTime>{}</CycleTime>", "0",
      "0.001", "cyclic task 1: <CycleTime> (ns)", slave=None),
    # process image
    C("image-bytesize", "<Inputs>", "<ByteSize>11</ByteSize>", "<ByteSize>{}</ByteSize>", "-1",
      "0", "process image: <Inputs><ByteSize>", slave=None,
      cascades=frozenset({"variable-outside-image", "process-data-outside-image"})),
    C("variable-bitsize", "Drive.Inputs.Statusword<", "<BitSize>16</BitSize>",
      "<BitSize>{}</BitSize>", "-1", "0", "'Drive.Inputs.Statusword' <BitSize>", slave=None),
]  # fmt: skip


def _run(cli, tmp_path: Path, text: str) -> tuple[int, dict]:
    path = tmp_path / "single_drive.xml"
    path.write_text(text)
    code, out, _err = cli("eni", "validate", str(path), "-f", "json")
    return code, json.loads(out)


def _errors(report: dict) -> Counter[tuple[str, str]]:
    return Counter(
        (f["code"], f["message"]) for f in report["findings"] if f["severity"] == "failure"
    )


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_just_outside_is_one_error_just_inside_none(case: Case, cli, tmp_path):
    code, base = _run(cli, tmp_path, case.base)
    assert code == 0 and base["errors"] == 0, base
    code, out = _run(cli, tmp_path, case.text(case.outside))
    new = _errors(out) - _errors(base)
    ranged = [f for f in out["findings"] if f["code"] == RANGE_CODE]
    assert len(ranged) == 1, ranged
    (finding,) = ranged
    assert case.label in finding["message"], finding
    assert f"{case.label} {_as_int(case.outside)} is outside" in finding["message"]
    assert finding["slave"] == case.slave
    assert {c for c, _m in new} - {RANGE_CODE} <= case.cascades, new
    assert code == 1  # any error: exit 1
    assert out["schema"] == "lolacli.eni-validate/2"

    code, out = _run(cli, tmp_path, case.text(case.inside))
    new = _errors(out) - _errors(base)
    assert [f for f in out["findings"] if f["code"] == RANGE_CODE] == []
    assert {c for c, _m in new} <= case.cascades, new
    assert code == (1 if new else 0)


def _as_int(text: str) -> int:
    if text.startswith("#x"):
        return int(text[2:], 16)
    if "." in text:
        return int(float(text) * 1000)  # <CycleTime> is µs, the finding says ns
    return int(text)


# --------------------------------------------------------------------------- model level

BASE = parse_eni(SINGLE_DRIVE.encode(), "single_drive.xml")
Mutate = Callable[[Eni, int], Eni]


def _slave(eni: Eni, **changes: object) -> Eni:
    return replace(eni, slaves=(replace(eni.slaves[0], **changes),))


def _identity(eni: Eni, **changes: int) -> Eni:
    return _slave(eni, identity=replace(eni.slaves[0].identity, **changes))


def _first(items: tuple, **changes: object) -> tuple:
    return (replace(items[0], **changes), *items[1:])


def _first_fmmu(eni: Eni, **changes: object) -> Eni:
    fmmus = eni.slaves[0].fmmus
    return _slave(eni, fmmus=_first(fmmus, fmmu=replace(fmmus[0].fmmu, **changes)))


def _first_sm(eni: Eni, **changes: object) -> Eni:
    sms = eni.slaves[0].sync_managers
    sm = replace(sms[0].sync_manager, **changes)
    return _slave(eni, sync_managers=_first(sms, sync_manager=sm))


def _cyclic_cmd(eni: Eni, n: int, **changes: object) -> Eni:
    task = eni.cyclic[0]
    frame = task.frames[0]
    cmds = list(frame.commands)
    cmds[n] = replace(cmds[n], **changes)
    frames = (replace(frame, commands=tuple(cmds)),)
    return replace(eni, cyclic=(replace(task, frames=frames),))


def _init_cmd(slave: Slave, **changes: object) -> tuple:
    return _first(slave.init_cmds, **changes)


MODEL_CASES: list[tuple[str, Mutate, int, int, str, int | None]] = [
    ("phys-addr", lambda e, v: _slave(e, station_address=v), 0x10000, 0xFFFF,
     "<Info><PhysAddr>", DRIVE),
    ("auto-inc-addr", lambda e, v: _slave(e, auto_inc_address=v), 0x10000, 0,
     "<Info><AutoIncAddr>", DRIVE),
    ("previous-port", lambda e, v: _slave(e, previous_station_address=v), 0x10000, 0xFFFF,
     "<PreviousPort><PhysAddr>", DRIVE),
    ("vendor-id", lambda e, v: _identity(e, vendor_id=v), 2**32, 2**32 - 1,
     "<Info><VendorId>", DRIVE),
    ("product-code", lambda e, v: _identity(e, product_code=v), 2**32, 2**32 - 1,
     "<Info><ProductCode>", DRIVE),
    ("revision", lambda e, v: _identity(e, revision=v), 2**32, 2**32 - 1,
     "<Info><RevisionNo>", DRIVE),
    ("serial", lambda e, v: _identity(e, serial=v), -1, 0, "<Info><SerialNo>", DRIVE),
    ("fmmu-logical-start",
     lambda e, v: _first_fmmu(e, logical_start=v),
     2**32, 2**32 - 1, "FMMU0 logical start", DRIVE),
    ("fmmu-physical-start",
     lambda e, v: _first_fmmu(e, physical_start=v),
     0x10000, 0xFFFF, "FMMU0 physical start", DRIVE),
    ("fmmu-length",
     lambda e, v: _first_fmmu(e, length_bytes=v),
     0x10000, 0xFFFF, "FMMU0 length", DRIVE),
    ("sm-start-from-initcmd",
     lambda e, v: _first_sm(e, physical_start=v),
     0x10000, 0xFFFF, "SM0 start address", DRIVE),
    ("initcmd-adp", lambda e, v: _slave(e, init_cmds=_init_cmd(e.slaves[0], adp=v)),
     0x10000, 0xFFFF, "(request INIT (acknowledge errors)) <Adp>", DRIVE),
    ("initcmd-ado", lambda e, v: _slave(e, init_cmds=_init_cmd(e.slaves[0], ado=v)),
     -1, 0, "(request INIT (acknowledge errors)) <Ado>", DRIVE),
    ("initcmd-addr",
     lambda e, v: _slave(e, init_cmds=_init_cmd(e.slaves[0], logical_address=v)),
     2**32, 2**32 - 1, "(request INIT (acknowledge errors)) <Addr>", DRIVE),
    ("initcmd-data", lambda e, v: _slave(e, init_cmds=_init_cmd(e.slaves[0], data=bytes(v))),
     0x800, 0x7FF, "(request INIT (acknowledge errors)) data length", DRIVE),
    ("cyclic-addr", lambda e, v: _cyclic_cmd(e, 0, logical_address=v), 2**32, 2**32 - 1,
     f"{LRW} <Addr>", None),
    ("cyclic-adp", lambda e, v: _cyclic_cmd(e, 1, adp=v), 0x10000, 0xFFFF,
     f"{BRD} <Adp>", None),
    ("cyclic-ado", lambda e, v: _cyclic_cmd(e, 1, ado=v), 0x10000, 0xFFFF,
     f"{BRD} <Ado>", None),
    ("mbx-status-bit", lambda e, v: _slave(
        e, mailbox=replace(e.slaves[0].mailbox, status_bit_address=v)),
     2**35, 2**35 - 1, "<Mailbox><Recv><StatusBitAddr>", DRIVE),
    ("master-cycle-time", lambda e, v: replace(e, master=replace(e.master, cycle_time_ns=v)),
     0, 1, "master: <CycleTime> (ns)", None),
]  # fmt: skip


def _ranged(eni: Eni) -> list[Finding]:
    return list(check_field_ranges(eni))


def test_the_base_model_is_in_range():
    assert _ranged(BASE) == []


@pytest.mark.parametrize(
    ("mutate", "outside", "inside", "label", "slave"),
    [c[1:] for c in MODEL_CASES],
    ids=[c[0] for c in MODEL_CASES],
)
def test_model_field_just_outside_and_inside(mutate, outside, inside, label, slave):
    (finding,) = _ranged(mutate(BASE, outside))
    assert finding.severity is Severity.FAILURE and finding.kind == RANGE_CODE
    assert f"{label} {outside} is outside" in finding.message, finding.message
    assert finding.slave == slave
    assert _ranged(mutate(BASE, inside)) == []
    assert finding in validate_eni(mutate(BASE, outside))  # part of the full run
