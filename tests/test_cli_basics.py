import subprocess
import sys


def test_help_lists_command_groups(cli):
    code, out, _ = cli("--help")
    assert code == 0
    for group in ("eni", "bus", "capture", "sdo"):
        assert group in out


def test_unknown_command_is_usage_error(cli):
    code, _, _ = cli("no-such-command")
    assert code == 2


def test_a_group_without_its_command_shows_its_help(cli):
    """``lolacli bus`` (no command): the group's help as it is laid out, exit 2, as
    ``lolacli`` alone does; not the help squeezed into one error line."""
    for group in ("eni", "bus", "capture", "sdo", "foe"):
        code, _, err = cli(group)
        assert code == 2
        assert err.startswith(f"Usage: lolacli {group} ") and "\nCommands:\n" in err, err
        assert "error:" not in err


def test_the_command_named_is_built_alone():
    """``lolacli capture analyze F`` builds the click command of ``analyze`` alone (its
    siblings' options cost start-up); the group's help, a misspelt command and the whole
    app have every command, and the module's app keeps them all."""
    import typer.main

    from lolacli.cli import capture, main

    def built(command: str | None) -> list[str]:
        root = typer.main.get_command(main._build(("capture",), command))
        return sorted(root.commands["capture"].commands)

    every = sorted(str(c.name) for c in capture.app.registered_commands)
    assert len(every) > 1
    assert built("analyze") == ["analyze"]
    assert built("list") == ["list"]
    assert built("--help") == built(None) == built("analyse") == every
    assert sorted(str(c.name) for c in capture.app.registered_commands) == every


def test_help_does_not_import_heavy_libraries():
    probe = (
        "import sys\n"
        "from lolacli.cli.main import app\n"
        "heavy = [m for m in ('numpy', 'matplotlib', 'scapy', 'pysoem', 'lxml', 'numba', 'rich',"
        " 'canopen', 'can', 'yaml', 'msgpack')"
        " if m in sys.modules]\n"
        "print(','.join(heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def _closed_early(*args: str) -> tuple[int, str]:
    """Run the CLI with a reader that takes 10 bytes and closes the pipe (`| head -c 10`)."""
    p = subprocess.Popen(
        [sys.executable, "-m", "lolacli", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    assert p.stdout is not None and p.stderr is not None
    p.stdout.read(10)
    p.stdout.close()
    err = p.stderr.read().decode()
    return p.wait(), err


def test_a_reader_that_goes_away_does_not_change_the_exit_code():
    """Outputs larger than a pipe buffer (64 KiB): the write fails with EPIPE; the
    command still exits with what it found, silently."""
    lola = "eni_examples/lola.xml"
    assert _closed_early("eni", "inspect", lola) == (0, "")  # rich tables
    assert _closed_early("eni", "inspect", lola, "--format", "json") == (0, "")
    # diff finds differences (exit 1) and says so in ~100 kB
    other = "eni_examples/ek1100_io.xml"
    assert _closed_early("eni", "diff", lola, other, "--format", "json") == (1, "")


def test_every_usage_error_has_the_one_prefix_and_one_line():
    """Wrong arguments at the root, to a command, or a missing argument: one line,
    "lolacli: error:", exit 2, however the program was started (python -m lolacli)."""
    import subprocess
    import sys

    for args in (["--bogus"], ["nosuch"], ["sdo", "read"], ["capture", "list", "x", "-c", "-5"]):
        done = subprocess.run([sys.executable, "-m", "lolacli", *args], capture_output=True,
                              text=True, check=False)
        assert done.returncode == 2 and done.stdout == "", args
        assert done.stderr.count("\n") == 1, (args, done.stderr)
        assert done.stderr.startswith("lolacli: error: "), (args, done.stderr)
        assert len(done.stderr.rstrip("\n")) <= 80, (args, done.stderr)
