import subprocess
import sys


def test_help_lists_command_groups(cli):
    code, out, _ = cli("--help")
    assert code == 0
    for group in ("eni", "bus", "capture"):
        assert group in out


def test_unknown_command_is_usage_error(cli):
    code, _, _ = cli("no-such-command")
    assert code == 2


def test_help_does_not_import_heavy_libraries():
    probe = (
        "import sys\n"
        "from lolacli.cli.main import app\n"
        "heavy = [m for m in ('numpy', 'matplotlib', 'scapy', 'pysoem', 'lxml', 'numba', 'rich')"
        " if m in sys.modules]\n"
        "print(','.join(heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
