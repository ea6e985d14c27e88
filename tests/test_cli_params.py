"""Parameter conversion: typer's own, through public options only, and without pydantic.

typer 0.29 converts every value through a pydantic ``TypeAdapter`` (importing pydantic
costs a short command about a third of its start-up); pyproject pins the 0.28 line, which
converts with its own types. Checks a range cannot make (``nan``) are ``callback=``s
(lolacli/cli/options.py).
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import typer

ROOT = Path(__file__).resolve().parent.parent


def _typer_pin() -> str:
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (pin,) = [d for d in deps if re.match(r"typer\b", d)]
    return pin


def test_no_module_reaches_into_typer_internals() -> None:
    private = re.compile(
        r"\btyper\._|from typer\.(core|main|models|params)\b|^\s*(import|from) click\b"
    )
    offenders = [
        f"{path.relative_to(ROOT)}:{n}"
        for path in sorted((ROOT / "lolacli").rglob("*.py"))
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if private.search(line) and "TyperGroup" not in line
    ]
    assert offenders == []


def test_a_short_command_does_not_import_pydantic() -> None:
    from packaging.requirements import Requirement

    pin = Requirement(_typer_pin())
    if not pin.specifier.contains(typer.__version__):
        pytest.skip(f"typer {typer.__version__} is installed, pyproject wants {pin}: "
                    "pip install -e . first")
    code = (
        "import sys; sys.argv = ['lolacli', 'sdo', 'read', '5', '0x1000', '--timeout', '2']\n"
        "import lolacli.cli.main as m\n"
        "try:\n    m.main()\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
        "assert 'pydantic' not in sys.modules, 'pydantic imported'\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "5 0x1000:00  Device type  UNSIGNED32 = 131474 (0x00020192)\n"


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (("sdo", "read", "5", "0x1000", "--timeout", "nan"), "--timeout: "),
        (("sdo", "read", "5", "0x1000", "--timeout", "0"), "--timeout: "),
        (("sdo", "read", "5", "0x1000", "--timeout", "soon"), "--timeout: "),
        (("bus", "timing", "--link-mbit", "nan"), "--link-mbit: "),
        (("bus", "timing", "--statistic", "mean"), "--statistic: "),
        (("eni", "inspect", "/nonexistent/lola.xml", "--format", "yaml"), "--format/-f: "),
        (("capture", "list", "x.pcap", "--count", "many"), "-c/--count: "),
        (("sdo", "read", "5"), "Missing argument"),
    ],
)
def test_a_bad_value_is_one_line_and_exit_2(cli, args: tuple[str, ...], said: str) -> None:
    code, out, err = cli(*args)
    assert (code, out) == (2, "")
    assert err.count("\n") == 1 and "Traceback" not in err
    assert said in err and len(err) <= 81, err  # one line of at most 80 columns


def _commands():  # type: ignore[no-untyped-def]
    from typer.main import get_command

    from lolacli.cli.main import app

    todo = [(get_command(app), "lolacli")]
    while todo:
        cmd, path = todo.pop()
        yield cmd, path
        todo += [(sub, f"{path} {name}") for name, sub in getattr(cmd, "commands", {}).items()]


#: flags that mean different things in different commands (so their help differs)
_MEANS_MORE_THAN_ONE_THING = {
    "--count": "frames listed (capture list) or samples watched (bus data)",
    "--rate": "bus data defaults to the ENI's cycle, a simulation to 2 kHz",
    "--watch": "a variable reported at the end (bus simulate) or a sampling rate (bus data)",
    "--bad-link": "the same fault, said of a chain on a wire (bus emulate) or in virtual time",
    "--esi": "eni generate takes folders of ESI files too, and their PDOs, SMs and DC",
    "--plot": "a folder of PNGs (capture analyze) or one PNG (traj plan, joint track/bode)",
    "--mcap": "the same channels, from a capture (capture export) or a run (bus simulate)",
    "--eni": "the chain itself; a reference to check against; bus timing's frame source",
    "--iface": "bus simulate runs in real time on it instead of in virtual time",
    "--duration": "bus simulate's is simulated time, the servers' wall time",
    "--timeout": "per frame, per SDO answer, or when a capture's frame counts as lost",
    "--quiet": "a status line or a progress bar",
    "--realtime-priority": "the emulator's default differs from the master's",
    "--link-down": "counted from serving or from the cyclic run",
    "--eds": "one node's types (sdo) or each node served (sdo serve)",
    "--node": "one node (sdo) or one per --eds (sdo serve)",
    "--can": "the channel to talk on, to serve on, or the gateway's sensors come from",
    "--filter": "variable names or frame terms",
    "--format": "eni vars also writes csv; report writes an html or md page",
    "--capture": "bus timing's measured total, or one of a report's measurements",
    "--output": "where foe read writes the file, where the report's page goes, or where bus "
    "sii read saves the image",
    "--force": "what is overridden: bus simulate's, a configuration register (bus reg write), "
    "an image's checks (bus sii write)",
    "--host-latency-us": "a constant (bus timing) or MEAN[:STD] drawn a frame (bus simulate)",
    "--cable-m": "one length for all segments (bus timing) or M and K=M items (bus simulate)",
    "--ke": "the one joint of joint bode, or every joint of bus simulate (which it switches on)",
}


def test_a_shared_option_has_one_help_text() -> None:
    helps: dict[str, dict[str, list[str]]] = {}
    for cmd, path in _commands():
        for p in cmd.params:
            if p.param_type_name == "option":
                flag = max(p.opts, key=len)
                helps.setdefault(flag, {}).setdefault(p.help or "", []).append(path)
    differing = {flag: texts for flag, texts in helps.items()
                 if len(texts) > 1 and flag not in _MEANS_MORE_THAN_ONE_THING}
    assert differing == {}, "define the option once in lolacli/cli/options.py"


def test_no_command_function_is_long() -> None:
    """A command parses its options and calls the library: ~60 lines at most, options
    included (each a line, defined as an Annotated alias)."""
    import inspect

    long = {}
    for cmd, path in _commands():
        callback = getattr(cmd, "callback", None)
        if callback is None or getattr(cmd, "commands", None):
            continue
        lines = len(inspect.getsource(callback).splitlines())
        if lines > 60:
            long[path] = lines
    assert long == {}


def test_a_servers_duration_is_a_time_as_bus_simulate_spells_it() -> None:
    """``bus emulate``/``sdo serve --duration`` take ``30s`` and ``500ms`` as ``bus
    simulate --duration`` does, and a bare number of seconds as before."""
    import typer

    from lolacli.cli.options import seconds

    assert [seconds(t) for t in ("1.5", "500ms", "2s", "250us", "0")] == [1.5, 0.5, 2.0,
                                                                           0.00025, 0.0]
    for bad in ("-1", "nan", "inf", "soon", "1e400", "5 parsecs"):
        with pytest.raises(typer.BadParameter):
            seconds(bad)
