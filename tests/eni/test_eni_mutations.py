"""Every number of an ENI mutated, through every command that reads an ENI: no exception
but the documented ones (LolaError subclasses; an EniError for the file itself names the
file and the line), never a traceback.

The targets are every numeric element text and numeric attribute of the LOLA ENI and of
each corpus ENI ($LOLACLI_CORPUS/eni), found once per file with their byte spans, so a
mutation is a splice of the file's own bytes (its lines stay where they were). The values:
negative, 0, huge (2**31, 2**64), off by one past the widths of EtherCAT fields, not a
number, empty, hex forms, the original off by one.

Each example runs the library entry points of the commands: parse (every command),
`eni inspect|vars|validate|diff`, `bus timing --eni`; then, for the tier the example draws,
`bus emulate`'s chain (make_chain) with `bus scan --eni`'s comparison, `capture analyze
--eni` of a small corpus capture, or the master: `bus simulate --eni` where the mutation is
in the process image, else our master's bring-up to OP and a few cycles over the emulated
chain in virtual time, and `sdo read --eni` on the in-process chain.
"""

from __future__ import annotations

import gc
import os
import re
from collections import Counter
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from xml.sax.saxutils import escape

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lolacli.eni.model import Eni
from lolacli.eni.parser import parse_eni, parse_number
from lolacli.errors import EniError, LolaError
from tests.conftest import CORPUS, corpus_files

ROOT = Path(__file__).resolve().parents[2]
LOLA = ROOT / "lolacli" / "eni_examples" / "lola.xml"
#: smallest first: Hypothesis shrinks towards the first, so a failure is shown in the file
#: quickest to read
FILES = sorted([LOLA, *corpus_files("eni", "*.xml")], key=lambda p: p.stat().st_size)
CAPTURE = CORPUS / "pcap" / "ethercrab__twincat-run-ek1100-el1004.pcapng"

#: examples in CI; more for a longer hunt: LOLACLI_MUTATION_EXAMPLES=20000
EXAMPLES = int(os.environ.get("LOLACLI_MUTATION_EXAMPLES", "2000"))
#: what an example runs past the model commands, and how often: the emulated chain (1 in
#: 12), a capture analysed against the ENI (1 in 20), the master's bring-up and an SDO read
#: (1 in 60; a one-off hunt ran them for every field of every file with 10 values each)
TIERS = ("model",) * 52 + ("chain",) * 5 + ("capture",) * 3 + ("bus",)


@dataclass(frozen=True)
class Target:
    """One number of a file: an element's text or an attribute's value, and where."""

    field: str  # "Config/Slave/Info/PhysAddr", "Config/Slave/ProcessData/TxPdo@Sm"
    line: int
    start: int  # byte span of the value in the file
    end: int
    original: str

    def mutated(self, raw: bytes, value: str) -> bytes:
        quoted = escape(value, {'"': "&quot;"}) if "@" in self.field else escape(value)
        return raw[: self.start] + quoted.encode("ascii", "xmlcharrefreplace") + raw[self.end :]


def _numeric(text: str | None) -> bool:
    if text is None or not text.strip():
        return False
    try:
        parse_number(text)
    except ValueError:
        try:
            float(text)  # <CycleTime> in µs: 0.5
        except ValueError:
            return False
    return True


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _targets(raw: bytes) -> dict[str, list[Target]]:
    """The numbers of a file by field, each with its byte span: the start tag of each
    element is found from its line on (lxml gives lines, not offsets), and a span is kept
    only where the bytes there read as lxml read them."""
    from lxml import etree

    root = etree.fromstring(raw, etree.XMLParser(resolve_entities=False))
    line_starts = [0] + [m.end() for m in re.finditer(b"\n", raw)]
    found: dict[str, list[Target]] = {}
    cursor = 0
    for el in root.iter():
        if not isinstance(el.tag, str):
            continue
        name = _local(el.tag)
        start_tag = re.compile(rb"<(?:[\w.-]+:)?" + re.escape(name.encode()) + rb"(?=[\s/>])")
        m = start_tag.search(raw, max(cursor, line_starts[el.sourceline - 1]))
        if m is None:
            continue
        tag_end = raw.index(b">", m.end())
        cursor = tag_end + 1
        path = "/".join([_local(a.tag) for a in reversed(list(el.iterancestors()))][1:] + [name])
        for attr, value in el.attrib.items():
            if not _numeric(value):
                continue
            a = re.compile(rb"\s" + re.escape(_local(attr).encode()) + rb"\s*=\s*([\"'])")
            am = a.search(raw, m.end(), tag_end)
            if am is None:
                continue
            end = raw.index(am.group(1), am.end())
            if raw[am.end() : end].decode("latin-1") == value:
                field = f"{path}@{_local(attr)}"
                target = Target(field, el.sourceline, am.end(), end, value)
                found.setdefault(field, []).append(target)
        if len(el) or not _numeric(el.text) or raw[tag_end - 1 : tag_end] == b"/":
            continue
        end = raw.index(b"<", tag_end + 1)
        if raw[tag_end + 1 : end].decode("latin-1") == el.text:
            found.setdefault(path, []).append(
                Target(path, el.sourceline, tag_end + 1, end, str(el.text))
            )
    return found


@dataclass(frozen=True)
class Subject:
    """One ENI file: its bytes, its model, its numbers by field."""

    path: Path
    raw: bytes
    eni: Eni
    targets: dict[str, list[Target]]
    fields: tuple[str, ...]


@cache
def subject(path: Path) -> Subject:
    raw = path.read_bytes()
    targets = _targets(raw)
    return Subject(path, raw, parse_eni(raw, path.name), targets, tuple(sorted(targets)))


#: widths of EtherCAT and CoE fields and lolacli's limits, each as its last value and the
#: first past it (u8, u16, u32, i32, commands, datagram data, FMMU bits, image bytes)
EDGES = [
    0, 1, 7, 8, 14, 15, 16, 255, 256, 1486, 1487, 1500, 2047, 2048, 32767, 32768, 65535, 65536,
    524280, 524281, 2**24, 2**24 + 1, 2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**35, 2**64, 10**30,
]  # fmt: skip
JUNK = ["", " ", "abc", "#xZZ", "#x", "0x", "-", "+", "1.5", "1e3", "NaN", "inf", "-inf",
        "١٢", "²", "0x-1", "--5", "1_000", "#x1_0", " 12 ", "9" * 5000, "1e999999999"]


def _hex(n: int) -> str:
    return f"#x{n:X}" if n >= 0 else f"-#x{-n:X}"


@st.composite
def values(draw: st.DrawFn, original: str) -> str:
    """A value for a number: an edge of some field's width (as decimal, hex or negative),
    junk, or the original nudged."""
    kind = draw(st.sampled_from(["edge", "negative", "junk", "nudge", "integer"]))
    if kind == "junk":
        return draw(st.sampled_from(JUNK))
    if kind == "nudge":
        try:
            n = parse_number(original)
        except ValueError:
            return draw(st.sampled_from(["0", "-0.001", "0.0001", "4294967.296"]))
        n += draw(st.sampled_from([-1, 1, -(n + 1), n * 1000 + 1]))
    elif kind == "integer":
        n = draw(st.integers(min_value=-(2**70), max_value=2**70))
    else:
        n = draw(st.sampled_from(EDGES))
        n = -n if kind == "negative" else n
    return draw(st.sampled_from([str(n), _hex(n)]))


@dataclass(frozen=True)
class Mutation:
    file: Path
    target: Target
    value: str
    tier: str


@st.composite
def mutations(draw: st.DrawFn) -> Mutation:
    path = draw(st.sampled_from(FILES))
    s = subject(path)
    targets = s.targets[draw(st.sampled_from(s.fields))]
    target = targets[draw(st.integers(min_value=0, max_value=len(targets) - 1))]
    return Mutation(path, target, draw(values(target.original)), draw(st.sampled_from(TIERS)))


# --------------------------------------------------------------------------- the commands


@cache
def _scanned(path: Path) -> tuple:
    """The bus `bus scan` sees: the original file's chain, scanned once."""
    from lolacli.emulator.run import EmulateOptions, make_chain
    from lolacli.master.scan import scan
    from lolacli.master.transport import ChainTransport

    chain = make_chain(subject(path).eni, EmulateOptions())
    return tuple(scan(ChainTransport(chain)).slaves)


def _model_commands(eni: Eni, original: Eni) -> None:
    """`eni inspect|vars|validate|diff` and `bus timing --eni`."""
    from lolacli.eni.diff import diff_eni, diff_report
    from lolacli.eni.report import inspect_report, vars_report
    from lolacli.eni.validate import validate_eni, validate_report
    from lolacli.timing.model import estimate

    inspect_report(eni)
    vars_report(eni)
    vars_report(eni, "*.Inputs.*")
    validate_report(eni, validate_eni(eni))
    diff_report(original, eni, diff_eni(original, eni))
    diff_eni(eni, original)
    for frame in eni.cyclic_frames:
        estimate(frame.frame_bytes, len(eni.slaves)).to_dict()


def _chain_commands(eni: Eni, path: Path) -> None:
    """`bus emulate --eni` (its chain) and `bus scan --eni` (the comparison)."""
    from lolacli.emulator.run import EmulateOptions, make_chain
    from lolacli.master.scan import compare_with_eni

    make_chain(eni, EmulateOptions())
    for difference in compare_with_eni(_scanned(path), eni):
        difference.to_dict()


#: the master's bring-up at a 10 ms cycle, polling every 10 ms: a mutation that keeps the
#: slaves from a state costs each slave its ENI timeout (10 s) in virtual time, one slave
#: after the other (Master.transition): 1000 polls and cycles each, not the 120 000 of the
#: defaults (LOLA with its LRW made a NOP: 3.9 s here, 2 min 17 s as `bus simulate`)
BRING_UP = {"cycle_time_ns": 10_000_000, "poll_ns": 10_000_000, "dc_drift_frames": 10}


def _bus_commands(m: Mutation, eni: Eni, data: bytes, folder: Path) -> None:
    """`bus simulate --eni` where the mutation leaves the bring-up alone (the process image
    and its variables: 3 cycles with the drives' middleware), else our master's bring-up
    to OP and 3 cycles (lolacli.master.Master over the emulated chain); then `sdo read
    --eni` on the in-process chain (through the file, so the model cache takes part)."""
    from lolacli.emulator.run import EmulateOptions, make_chain
    from lolacli.master.core import Master, MasterOptions
    from lolacli.master.transport import ChainTransport
    from lolacli.sdo.client import read
    from lolacli.sdo.session import TransportOptions, open_session
    from lolacli.simulate import SimulateOptions, simulate
    from lolacli.wire.registers import AlState

    if m.target.field.startswith("Config/ProcessImage/"):
        simulate(eni, SimulateOptions(cycles=3))
    else:
        chain = make_chain(eni, EmulateOptions())
        master = Master(eni, ChainTransport(chain), options=MasterOptions(**BRING_UP))
        master.bring_up(AlState.OP, strict=False)
        for _ in range(3):
            master.cycle()
        master.drain()
    mailbox = next((s.position for s in subject(m.file).eni.slaves if s.mailbox), None)
    if mailbox is None:
        return
    copy = folder / m.file.name
    copy.write_bytes(data)
    with open_session(TransportOptions(eni=copy, timeout_s=0.05)) as session:
        target = session.target(str(mailbox))
        read(target.client, 0x1018, 1, slave=target.label, dictionary=target.dictionary)


def run_commands(m: Mutation, data: bytes, folder: Path) -> None:
    original = subject(m.file).eni
    eni = parse_eni(data, m.file.name)
    _model_commands(eni, original)
    if m.tier == "chain":
        _chain_commands(eni, m.file)
    elif m.tier == "capture":
        from lolacli.capture.analyze import analyze_file

        analyze_file(CAPTURE, eni=eni).to_dict()
    elif m.tier == "bus":
        _bus_commands(m, eni, data, folder)


# --------------------------------------------------------------------------- the test

OUTCOMES: Counter[str] = Counter()


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory):
    """A folder for the files `sdo read` opens."""
    return tmp_path_factory.mktemp("mutations")


@pytest.fixture(scope="module")
def frozen_heap():
    """The files read and their models built, then left out of garbage collection, and
    full collections made rare: with those models and Hypothesis' growing state in the
    heap, the full collections walked it all 270 times: 6 to 8 s of a 45 to 50 s run."""
    for path in FILES:
        subject(path)
    gc.collect()
    gc.freeze()
    thresholds = gc.get_threshold()
    gc.set_threshold(thresholds[0], thresholds[1], 1000)
    yield
    gc.set_threshold(*thresholds)
    gc.unfreeze()


@pytest.mark.skipif(not CAPTURE.is_file(), reason=f"corpus not found at {CORPUS}")
@settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(m=mutations())
def test_a_mutated_number_is_an_eni_error_or_runs(
    m: Mutation, folder: Path, frozen_heap: None
) -> None:
    data = m.target.mutated(subject(m.file).raw, m.value)
    try:
        run_commands(m, data, folder)
    except EniError as exc:
        assert exc.path == m.file.name or exc.path == str(folder / m.file.name), exc
        text = str(exc)
        assert "\n" not in text and text.count(m.file.name) == 1, text
        if exc.path == m.file.name and "no <Slave>" not in text:
            assert exc.line is not None, text  # a defect of the file: its line
        OUTCOMES[f"{m.tier}: EniError"] += 1
        return
    except LolaError as exc:
        assert "\n" not in str(exc), str(exc)
        OUTCOMES[f"{m.tier}: {type(exc).__name__}"] += 1
        return
    OUTCOMES[f"{m.tier}: ran"] += 1


def test_the_hunt_reached_every_tier_with_files_run_and_refused() -> None:
    """The examples above ran every tier to its end with some mutated file, and the parser
    refused others."""
    if not OUTCOMES:
        pytest.skip("the mutation test did not run in this session")
    for tier in set(TIERS):
        assert OUTCOMES[f"{tier}: ran"] > 0, OUTCOMES
    assert OUTCOMES["model: EniError"] > 0, OUTCOMES


def test_every_file_has_its_numbers_found() -> None:
    """The targets are real: every file gives numbers in its slaves, cyclic frames and
    process image, and each span holds the number lxml reads there."""
    for path in FILES:
        s = subject(path)
        assert any("/Slave/Info/PhysAddr" in f for f in s.fields), path
        assert any("/Cyclic/Frame/Cmd/DataLength" in f for f in s.fields), path
        assert any("/ProcessImage/" in f for f in s.fields), path
        for targets in s.targets.values():
            for t in targets:
                assert s.raw[t.start : t.end].decode("latin-1") == t.original
    assert len(FILES) >= 2 or not CORPUS.is_dir()
