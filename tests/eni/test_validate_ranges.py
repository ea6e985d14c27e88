"""Range checks of ENI numbers: a number just outside the width the EtherCAT/CoE specs give
its field (lolacli.eni.limits) makes the file unreadable: exit 3, one line naming the file, the
line of the element and the element; just inside, the file reads and validates clean.

File-level cases mutate one field of ``eni_examples/single_drive.xml`` (text replacement in a
tmp copy) and run the CLI. Model-level cases check ``eni validate``'s own range check
(``value-out-of-range``) on models the parser did not make (built in code, read from the
cache), including the fields a file cannot carry out of range (register blocks decoded from
InitCmd data).
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
    says: str  # what the error names, "{}" the value as written (default: "<El> {} is outside")
    count: int = 1
    base: str = SINGLE_DRIVE
    cascades: frozenset[str] = frozenset()  # validate errors the inside value rightly triggers
    element: str | None = None  # the error names the line of this enclosing element

    def _at(self) -> int:
        if self.anchor is None:
            assert self.base.count(self.old) == self.count, self.old
            return self.base.index(self.old)
        assert self.base.count(self.anchor) == 1, self.anchor
        return self.base.index(self.old, self.base.index(self.anchor))

    def text(self, value: str) -> str:
        new = self.template.format(value)
        if self.anchor is None:
            return self.base.replace(self.old, new)
        at = self._at()
        return self.base[:at] + new + self.base[at + len(self.old) :]

    @property
    def line(self) -> int:
        """The line of the element (or attribute) replaced, or of ``element`` around it."""
        at = self._at()
        if self.element is not None:
            at = self.base.rindex(self.element, 0, at)
        return self.base.count("\n", 0, at) + 1


def el(case_id: str, anchor: str | None, old: str, template: str, outside: str, inside: str,
       **more: object) -> Case:
    """A case whose error reads ``<Element> VALUE is outside ...``."""
    tag = template.split(">", 1)[0] + ">"
    return Case(case_id, anchor, old, template, outside, inside, tag + " {} is outside",
                **more)  # type: ignore[arg-type]


LRW = "cyclic task 1 frame 1 Cmd 1 (LRW):"
BRD = "cyclic task 1 frame 1 Cmd 2 (BRD):"
AL_STATUS = "<Comment>AL status of every slave</Comment>"
PD_CMD = "<Comment>process data: outputs"
WATCHDOG = "<Comment>watchdog divider 100 us</Comment>"
INTERPOLATION = "<Comment>interpolation period: 5 x 10^-4 s</Comment>"
STATUSWORD = "Drive.Inputs.Statusword<"
C = Case
CASES = [
    # slave identity and addresses (negative values within the width are its two's
    # complement: AutoIncAddr -1 is 0xFFFF)
    el("phys-addr", None, "<PhysAddr>1001</PhysAddr>", "<PhysAddr>{}</PhysAddr>", "65536",
       "65535"),
    el("phys-addr-70000", None, "<PhysAddr>1001</PhysAddr>", "<PhysAddr>{}</PhysAddr>",
       "70000", "1"),
    el("auto-inc-addr", None, "<AutoIncAddr>#x0000</AutoIncAddr>",
       "<AutoIncAddr>{}</AutoIncAddr>", "-32769", "-1", cascades=frozenset()),
    el("vendor-id", None, "<VendorId>#x0000009a</VendorId>", "<VendorId>{}</VendorId>",
       "#x100000000", "-1"),
    el("product-code", None, "<ProductCode>#x00030924</ProductCode>",
       "<ProductCode>{}</ProductCode>", "#x100000000", "#xffffffff"),
    el("serial-no", None, "<SerialNo>4097</SerialNo>", "<SerialNo>{}</SerialNo>",
       "-2147483649", "-2147483648"),
    el("cyclic-ado", AL_STATUS, "<Ado>#x0130</Ado>", "<Ado>{}</Ado>", "#x10000", "#xffff"),
    el("cyclic-addr", PD_CMD, "<Addr>#x00010000</Addr>", "<Addr>{}</Addr>", "#x100000000",
       "#xffffffff", cascades=frozenset({"wkc-mismatch"})),
    # PDOs (ETG.1000.6: object index u16, subindex u8; mapping entry u32 = index|sub|bits)
    el("pdo-index", "<TxPdo", "<Index>#x1a00</Index>", "<Index>{}</Index>", "#x10000",
       "#xffff"),
    el("pdo-index-neg", "<TxPdo", "<Index>#x1a00</Index>", "<Index>{}</Index>", "-1", "0"),
    C("pdo-sm", "<TxPdo", 'Sm="3"', 'Sm="{}"', "16", "15", "<TxPdo> Sm {} is outside 0..15"),
    el("entry-index", None, "<Index>#x6041</Index>", "<Index>{}</Index>", "#x10000", "#xffff"),
    el("entry-subindex", "<Index>#x6041</Index>", "<SubIndex>0</SubIndex>",
       "<SubIndex>{}</SubIndex>", "256", "255"),
    el("entry-subindex-neg", "<Index>#x6041</Index>", "<SubIndex>0</SubIndex>",
       "<SubIndex>{}</SubIndex>", "-1", "0"),
    el("entry-bitlen", "<Index>#x6041</Index>", "<BitLen>16</BitLen>", "<BitLen>{}</BitLen>",
       "256", "255", cascades=frozenset({"pdo-overruns-sm"})),
    el("entry-bitlen-padding", "<Index>#x6041</Index>", "<BitLen>16</BitLen>",
       "<BitLen>{}</BitLen>", "-1", "0"),
    # sync managers (ETG.1000.4 Table 58), declared by <SmN> when no InitCmd writes them
    C("sm-index", None, "Sm3>", "Sm{}>", "16", "15", "<Sm{}>: sync manager {} is outside 0..15",
      count=2),
    el("sm-start", "<Type>Outputs</Type>", "<StartAddress>#x1100</StartAddress>",
       "<StartAddress>{}</StartAddress>", "65536", "65535", base=SM2_DECLARED),
    el("sm-length", "<Type>Outputs</Type>", "<DefaultSize>11</DefaultSize>",
       "<DefaultSize>{}</DefaultSize>", "65536", "65535", base=SM2_DECLARED),
    el("sm-control", "<Type>Outputs</Type>", "<ControlByte>#x64</ControlByte>",
       "<ControlByte>{}</ControlByte>", "256", "255", base=SM2_DECLARED),
    # mailbox (the mailbox SMs' start and length are u16)
    el("mbx-send-start", "<Mailbox>", "<Start>#x1800</Start>", "<Start>{}</Start>", "65536",
       "65535"),
    el("mbx-send-length", "<Mailbox>", "<Length>140</Length>", "<Length>{}</Length>", "65536",
       "65535"),
    el("mbx-recv-start", "<Mailbox>", "<Start>#x1900</Start>", "<Start>{}</Start>", "65536",
       "65535"),
    el("mbx-poll-time", "<Mailbox>", "<PollTime>20</PollTime>", "<PollTime>{}</PollTime>", "-1",
       "0"),
    el("coe-index", INTERPOLATION, "<Index>#x60c2</Index>", "<Index>{}</Index>", "#x10000",
       "#xffff"),
    el("coe-subindex", INTERPOLATION, "<SubIndex>1</SubIndex>", "<SubIndex>{}</SubIndex>", "256",
       "255"),
    el("coe-ccs", INTERPOLATION, "<Ccs>1</Ccs>", "<Ccs>{}</Ccs>", "8", "7"),
    el("coe-timeout", INTERPOLATION, "<Timeout>3000</Timeout>", "<Timeout>{}</Timeout>", "-1",
       "0"),
    el("coe-timeout-u32", INTERPOLATION, "<Timeout>3000</Timeout>", "<Timeout>{}</Timeout>",
       "4294967296", "4294967295"),
    # distributed clocks (registers 0x0980 u16, 0x09A0/0x09A4 u32)
    el("dc-cycle0", None, "<CycleTime0>1000000</CycleTime0>", "<CycleTime0>{}</CycleTime0>",
       "4294967296", "4294967295"),
    el("dc-cycle1", None, "<CycleTime1>0</CycleTime1>", "<CycleTime1>{}</CycleTime1>", "-1",
       "0"),
    el("dc-shift-high", None, "<ShiftTime>0</ShiftTime>", "<ShiftTime>{}</ShiftTime>",
       "2147483648", "2147483647"),
    el("dc-shift-low", None, "<ShiftTime>0</ShiftTime>", "<ShiftTime>{}</ShiftTime>",
       "-2147483649", "-2147483648"),
    el("dc-assign-activate", None, "<AssignActivate>#x0300</AssignActivate>",
       "<AssignActivate>{}</AssignActivate>", "#x10000", "#xffff"),
    # process data areas (bits of the logical space; an FMMU maps at most 0xFFFF bytes)
    el("pd-send-bitstart", "<ProcessData>", "<BitStart>0</BitStart>",
       "<BitStart>{}</BitStart>", "-1", "0"),
    el("pd-send-bitlength", "<ProcessData>", "<BitLength>88</BitLength>",
       "<BitLength>{}</BitLength>", "-1", "0"),
    el("pd-send-bitlength-fmmu", "<ProcessData>", "<BitLength>88</BitLength>",
       "<BitLength>{}</BitLength>", "524281", "524280",
       cascades=frozenset({"process-data-outside-image"})),
    # InitCmds (ETG.1000.4 datagram: commands 0..14, WKC u16)
    el("slave-initcmd-cmd", WATCHDOG, "<Cmd>5</Cmd>", "<Cmd>{}</Cmd>", "15", "14"),
    el("slave-initcmd-cmd-u8", WATCHDOG, "<Cmd>5</Cmd>", "<Cmd>{}</Cmd>", "256", "4"),
    el("slave-initcmd-cnt", WATCHDOG, "<Cnt>1</Cnt>", "<Cnt>{}</Cnt>", "65536", "65535"),
    el("slave-initcmd-timeout", "<Comment>request INIT (acknowledge errors)</Comment>",
       "<Timeout>3000</Timeout>", "<Timeout>{}</Timeout>", "-1", "0"),
    el("slave-initcmd-validate-timeout", "<Comment>check INIT</Comment>",
       "<Timeout>3000</Timeout>", "<Timeout>{}</Timeout>", "-1", "0"),
    el("master-initcmd-cmd", "<Comment>count slaves (AL status)</Comment>", "<Cmd>7</Cmd>",
       "<Cmd>{}</Cmd>", "256", "8"),
    # cyclic commands (a datagram in a 1500-byte frame, WKC u16); cycle time > 0
    el("cyclic-cmd", PD_CMD, "<Cmd>12</Cmd>", "<Cmd>{}</Cmd>", "15", "14",
       cascades=frozenset({"wkc-mismatch"})),
    el("cyclic-datalength", PD_CMD, "<DataLength>11</DataLength>",
       "<DataLength>{}</DataLength>", "1487", "1472"),
    C("cyclic-frame-too-long", PD_CMD, "<DataLength>11</DataLength>",
      "<DataLength>{}</DataLength>", "1473", "1472",
      "<Frame> of 2 datagrams needs 1501 bytes: an Ethernet frame carries 1500",
      element="<Frame>"),
    el("cyclic-datalength-neg", AL_STATUS, "<DataLength>2</DataLength>",
       "<DataLength>{}</DataLength>", "-56", "0"),
    el("cyclic-cnt", PD_CMD, "<Cnt>3</Cnt>", "<Cnt>{}</Cnt>", "65536", "65535",
       cascades=frozenset({"wkc-mismatch"})),
    el("cyclic-input-offs", PD_CMD, "<InputOffs>0</InputOffs>", "<InputOffs>{}</InputOffs>",
       "-1", "0"),
    el("cyclic-output-offs", PD_CMD, "<OutputOffs>0</OutputOffs>",
       "<OutputOffs>{}</OutputOffs>", "16777217", "0"),
    C("cycle-time", None, "<CycleTime>1000</CycleTime>", "<CycleTime>{}</CycleTime>", "0",
      "0.001", "<CycleTime> {} µs is outside 0.001.."),
    C("cycle-time-nan", None, "<CycleTime>1000</CycleTime>", "<CycleTime>{}</CycleTime>",
      "NaN", "4294967.295", "<CycleTime> {} µs is outside"),
    # process image (16 MiB at most; every variable inside the <ByteSize> declared)
    el("image-bytesize", "<Inputs>", "<ByteSize>11</ByteSize>", "<ByteSize>{}</ByteSize>", "-1",
       "16777216"),
    C("variable-past-image", STATUSWORD, "<BitSize>16</BitSize>", "<BitSize>{}</BitSize>", "89",
      '88', 'variable "Drive.Inputs.Statusword": bits 0..88 lie past the 11-byte input image',
      element="<Variable>"),
    el("variable-bitsize", STATUSWORD, "<BitSize>16</BitSize>", "<BitSize>{}</BitSize>", "-1",
       "0"),
    el("variable-bitoffs", STATUSWORD, "<BitOffs>0</BitOffs>", "<BitOffs>{}</BitOffs>", "-16",
       "0"),
    # numbers that are none
    C("not-a-number", None, "<PhysAddr>1001</PhysAddr>", "<PhysAddr>{}</PhysAddr>", "#xZZ",
      "#x3E9", "<PhysAddr>: not a number: '{}'"),
    C("empty-required", None, "<PhysAddr>1001</PhysAddr>", "<PhysAddr>{}</PhysAddr>", "",
      "1001", "<PhysAddr> is empty: expected a number"),
]  # fmt: skip


def _validate(cli, tmp_path: Path, text: str) -> tuple[int, str, str]:
    path = tmp_path / "single_drive.xml"
    path.write_text(text)
    return cli("eni", "validate", str(path), "-f", "json")


def _errors(report: dict) -> Counter[tuple[str, str]]:
    return Counter(
        (f["code"], f["message"]) for f in report["findings"] if f["severity"] == "failure"
    )


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_just_outside_is_refused_with_its_line_just_inside_reads(case: Case, cli, tmp_path):
    code, out, _err = _validate(cli, tmp_path, case.base)
    base = json.loads(out)
    assert code == 0 and base["errors"] == 0, base

    code, out, err = _validate(cli, tmp_path, case.text(case.outside))
    assert (code, out) == (3, ""), (code, out, err)
    assert "Traceback" not in err
    (line,) = err.splitlines()
    where = f"{tmp_path / 'single_drive.xml'}:{case.line}: "
    assert line.startswith(f"lolacli: error: {where}"), (line, case.line)
    assert line.count(str(tmp_path)) == 1, line  # the file and line once
    assert case.says.format(case.outside, case.outside) in line, line

    code, out, _err = _validate(cli, tmp_path, case.text(case.inside))
    report = json.loads(out)
    new = _errors(report) - _errors(base)
    assert [f for f in report["findings"] if f["code"] == RANGE_CODE] == []
    assert {c for c, _m in new} <= case.cascades, new
    assert code == (1 if new else 0)


def test_every_command_reading_an_eni_refuses_it_alike(cli, tmp_path, corpus):
    """`eni inspect|vars|validate|diff`, `bus timing|simulate|emulate|scan --eni`, `sdo read
    --eni` and `capture analyze --eni`: the same one line, before any interface is opened."""
    (case,) = [c for c in CASES if c.id == "cyclic-datalength-neg"]
    bad = tmp_path / "bad.xml"
    bad.write_text(case.text(case.outside))
    good = tmp_path / "good.xml"
    good.write_text(case.base)
    expected = f"lolacli: error: {bad}:{case.line}: <DataLength> -56 is outside 0..1486"
    for args in (
        ("eni", "inspect", bad),
        ("eni", "vars", bad),
        ("eni", "validate", bad),
        ("eni", "diff", good, bad),
        ("bus", "timing", "--eni", bad),
        ("bus", "simulate", "--eni", bad, "--cycles", "3"),
        ("bus", "emulate", "-i", "nosuchif0", "--duration", "0.1", "--eni", bad),
        ("bus", "scan", "-i", "nosuchif0", "--eni", bad),
        ("sdo", "read", "1", "0x1018:01", "--eni", bad),
        ("capture", "analyze", corpus / "pcap" / "ethercrab__twincat-run-ek1100-el1004.pcapng",
         "--eni", bad),
    ):
        code, out, err = cli(*args)
        assert code == 3, (args, code, out, err)
        assert err.splitlines() == [err.strip()] and err.startswith(expected), (args, err)


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
     1487, 1486, "(request INIT (acknowledge errors)) data length", DRIVE),
    ("initcmd-cmd", lambda e, v: _slave(e, init_cmds=_init_cmd(e.slaves[0], cmd=v)),
     15, 14, "(request INIT (acknowledge errors)) <Cmd>", DRIVE),
    ("initcmd-retries", lambda e, v: _slave(e, init_cmds=_init_cmd(e.slaves[0], retries=v)),
     0x10000, 0xFFFF, "(request INIT (acknowledge errors)) <Retries>", DRIVE),
    ("cyclic-datalength", lambda e, v: _cyclic_cmd(e, 1, data_length_bytes=v), -56, 0,
     f"{BRD} <DataLength>", None),
    ("image-inputs", lambda e, v: replace(
        e, process_image=replace(e.process_image, inputs_bytes=v)),
     16 * 2**20 + 1, 16 * 2**20, "process image: <Inputs><ByteSize>", None),
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
