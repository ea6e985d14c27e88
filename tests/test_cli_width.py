"""Human output fits an 80-column terminal (DESIGN.md): with COLUMNS=80 no line of a
command's human output is wider than 80 characters, but a line that is only a file path.

Each command runs on the LOLA chain, the other packaged examples and every corpus ENI.
To hold another command to the rule, add it to ``ENI_COMMANDS`` (a function of the ENI
path) or ``OTHER_COMMANDS`` (fixed arguments), or call :func:`human` and
:func:`overlong` from its own test; ``bus scan`` runs in process against the emulated
chain (as tests/master/test_scan.py does) and renders through its CLI renderer.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tests.conftest import corpus_files
from tests.live import EXAMPLES, LOLA

WIDTH = 80

ENIS = [LOLA, EXAMPLES / "single_drive.xml", EXAMPLES / "ek1100_io.xml"]
ENIS += corpus_files("eni", "*.xml")
ENI_IDS = [p.name for p in ENIS]


def human(*args: object, columns: int = WIDTH) -> tuple[int, str]:
    """Run the CLI in process with ``COLUMNS`` set: (exit code, stdout)."""
    from typer.testing import CliRunner

    from lolacli.cli.main import app

    result = CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": str(columns)})
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, result.stdout


def _a_path(line: str) -> bool:
    text = line.strip()
    try:
        return " " not in text and Path(text).is_file()
    except OSError:
        return False


def overlong(text: str, width: int = WIDTH) -> list[str]:
    """The lines of ``text`` wider than ``width`` characters, but those that are only a
    file path."""
    return [line for line in text.splitlines() if len(line) > width and not _a_path(line)]


def assert_fits(code: int, out: str, codes: tuple[int, ...] = (0, 1)) -> None:
    assert code in codes, out
    assert out.strip(), "no output to measure"
    too_wide = overlong(out)
    assert not too_wide, "\n".join(f"{len(line)}: {line}" for line in too_wide)


ENI_COMMANDS: dict[str, Callable[[Path], tuple[object, ...]]] = {
    "eni inspect": lambda eni: ("eni", "inspect", eni),
    "eni vars": lambda eni: ("eni", "vars", eni),
    "eni validate": lambda eni: ("eni", "validate", eni),
    "eni diff LOLA X": lambda eni: ("eni", "diff", LOLA, eni),
    "eni diff X LOLA": lambda eni: ("eni", "diff", eni, LOLA),
    "bus timing --eni": lambda eni: ("bus", "timing", "--eni", eni),
    "bus timing --eni --measured": lambda eni: ("bus", "timing", "--eni", eni, "--measured",
                                                "5ms"),
}


@pytest.mark.parametrize("eni", ENIS, ids=ENI_IDS)
@pytest.mark.parametrize("command", list(ENI_COMMANDS))
def test_eni_commands_fit_80_columns(command: str, eni: Path) -> None:
    assert_fits(*human(*ENI_COMMANDS[command](eni)))


CAPTURES = corpus_files("pcap", "ethercrab__replay-issue-255.pcapng")
CAPTURES += corpus_files("pcap", "ethercrab__replay-dc.pcapng")

OTHER_COMMANDS: dict[str, tuple[object, ...]] = {
    "bus timing": ("bus", "timing"),
    "bus timing --frame-bytes --slaves": ("bus", "timing", "--frame-bytes", "1498",
                                          "--slaves", "120", "--budget-us", "50"),
    "bus timing --measured": ("bus", "timing", "--measured", "124.1us"),
    "eni vars --filter": ("eni", "vars", "--filter", "*Gateway*"),
    **{f"bus timing --capture {p.name}": ("bus", "timing", "--capture", p) for p in CAPTURES},
    **{
        f"{' '.join(c)} --help": (*c, "--help")
        for c in (("eni",), ("eni", "inspect"), ("eni", "vars"), ("eni", "validate"),
                  ("eni", "diff"), ("bus",), ("bus", "timing"), ("bus", "scan"))
    },
}


@pytest.mark.parametrize("command", list(OTHER_COMMANDS))
def test_other_commands_fit_80_columns(command: str) -> None:
    assert_fits(*human(*OTHER_COMMANDS[command]))


def test_the_rule_catches_a_wide_line(tmp_path: Path) -> None:
    """The check itself: a wide line fails it, a lone path does not; and a command asked
    for 200 columns does use them (COLUMNS reaches the console)."""
    assert overlong("x" * 81) == ["x" * 81]
    long_path = tmp_path / ("x" * 90 + ".xml")
    assert overlong(str(long_path)) == [str(long_path)]  # no such file: not a path line
    long_path.write_text("")
    assert overlong(f"  {long_path}") == []
    assert overlong(f"in {long_path}") == [f"in {long_path}"]
    _, wide = human("eni", "inspect", EXAMPLES / "ek1100_io.xml", columns=200)
    _, narrow = human("eni", "inspect", EXAMPLES / "ek1100_io.xml")
    assert max(map(len, wide.splitlines())) > WIDTH >= max(map(len, narrow.splitlines()))


# ------------------------------------------------------------------------------ bus scan
def _scan_output(eni_path: Path, capsys: pytest.CaptureFixture[str], **faults: object) -> str:
    from lolacli.cli.bus_scan import _render
    from lolacli.emulator.run import EmulateOptions, make_chain
    from lolacli.errors import EniError
    from lolacli.files import load_eni
    from lolacli.master.scan import ScanOptions, scan
    from lolacli.master.transport import ChainTransport
    from lolacli.wire.registers import AlState

    eni = load_eni(eni_path)
    state = faults.pop("state", None)
    try:
        chain = make_chain(eni, EmulateOptions(**faults))  # type: ignore[arg-type]
    except EniError as exc:  # the emulator refuses some (the simulate tests say which)
        pytest.skip(f"not emulated: {exc}")
    options = ScanOptions(state=AlState.OP) if state == "op" else ScanOptions()
    report = scan(ChainTransport(chain), eni=eni, options=options, iface="veth0")
    capsys.readouterr()
    _render(report.to_dict())
    return capsys.readouterr().out


@pytest.mark.parametrize("eni", ENIS, ids=ENI_IDS)
def test_bus_scan_fits_80_columns(eni: Path, capsys, monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", str(WIDTH))
    assert_fits(0, _scan_output(eni, capsys))


@pytest.mark.parametrize(
    "faults",
    [{"link_down_after": 10}, {"stuck_safeop": (5,), "state": "op"}],
    ids=["line cut after slave 10", "slave 5 stuck in SAFEOP"],
)
def test_bus_scan_with_faults_fits_80_columns(faults, capsys, monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", str(WIDTH))
    out = _scan_output(LOLA, capsys, **faults)
    assert_fits(1, out)
    assert "differs: " in out and "from the ENI" in out


# ------------------------------------------------------------------------- bus simulate
SIMULATE_CASES = {
    "at 2 kHz": ("--cycles", "200"),
    "a rate the bus cannot hold": ("--rate", "20000", "--cycles", "400"),
    "faults and a watch": ("--cycles", "400", "--drop-p", "0.02", "--stuck-safeop", "3",
                           "--watch", "CAN Gateway (IMU, FTS).IMU.Acceleration X"),
}


@pytest.mark.parametrize("case", list(SIMULATE_CASES))
def test_bus_simulate_fits_80_columns(case: str) -> None:
    code, out = human("bus", "simulate", "-q", *SIMULATE_CASES[case])
    assert_fits(code, out)
    assert "Verdict: " in out


def test_names_are_printed_as_given_not_as_emoji_codes(capsys) -> None:
    """Rich would print ``:100:`` in a name as an emoji; names come from ENIs and
    file names, so the consoles print them as they are."""
    from lolacli.cli.common import stderr_console, stdout_console

    stdout_console().print("slave Drive:100: in OP")
    stderr_console().print("file :smile:.pcapng")
    out, err = capsys.readouterr()
    assert "Drive:100: in OP" in out and ":smile:.pcapng" in err
