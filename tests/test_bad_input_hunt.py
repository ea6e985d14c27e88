"""Bad input found by a fuzzing hunt over every command: one stderr line and the
documented exit code (2 usage, 3 bad input), never a traceback; library functions raise
LolaError subclasses only."""

from __future__ import annotations

from pathlib import Path

import pytest

from lolacli.errors import EniError
from tests.conftest import CORPUS

LOLA_PCAP = CORPUS / "pcap" / "ethercrab__twincat-run-ek1100-el1004.pcapng"


def _one_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    return lines[0]


# --------------------------------------------------------------------------- XML encodings

BAD_ENCODINGS = ["klingon", "shift_jis", "utf-7", "rot13", "idna", "punycode"]


@pytest.mark.parametrize("encoding", BAD_ENCODINGS)
def test_eni_with_unusable_encoding_is_exit_3(cli, tmp_path: Path, encoding: str) -> None:
    f = tmp_path / "enc.xml"
    f.write_bytes(f"<?xml version='1.0' encoding='{encoding}'?><EtherCATConfig/>".encode())
    code, _out, err = cli("eni", "inspect", f)
    assert code == 3
    assert "encoding" in _one_line(err)


@pytest.mark.parametrize("encoding", BAD_ENCODINGS)
def test_esi_with_unusable_encoding_raises_eni_error(tmp_path: Path, encoding: str) -> None:
    from lolacli.files import load_esi

    f = tmp_path / "enc.xml"
    f.write_bytes(f"<?xml version='1.0' encoding='{encoding}'?><EtherCATInfo/>".encode())
    with pytest.raises(EniError, match="encoding"):
        load_esi(f)


# --------------------------------------------------------------------------- --plot folder


@pytest.mark.parametrize("fmt", ["human", "json"])
def test_plot_pointing_at_a_file_is_usage_error_and_keeps_the_file(
    cli, corpus: Path, tmp_path: Path, fmt: str
) -> None:
    victim = tmp_path / "notes.txt"
    victim.write_text("precious\n")
    code, out, err = cli("capture", "analyze", LOLA_PCAP, "--plot", victim, "-f", fmt)
    assert code == 2
    assert "is a file" in _one_line(err)
    assert out == ""  # failed before the report was written
    assert victim.read_text() == "precious\n"


def test_plot_below_a_file_is_usage_error(cli, corpus: Path, tmp_path: Path) -> None:
    victim = tmp_path / "notes.txt"
    victim.write_text("precious\n")
    code, _out, err = cli("capture", "analyze", LOLA_PCAP, "--plot", victim / "sub")
    assert code == 2
    assert "cannot create" in _one_line(err)
    assert victim.read_text() == "precious\n"


def test_write_plots_into_a_file_raises_usage_error(corpus: Path, tmp_path: Path) -> None:
    from lolacli.capture.analyze import analyze_file
    from lolacli.capture.plots import write_plots
    from lolacli.errors import UsageError

    victim = tmp_path / "notes.txt"
    victim.write_text("precious\n")
    report = analyze_file(LOLA_PCAP, keep_series=True)
    with pytest.raises(UsageError):
        write_plots(report, victim)
    assert victim.read_text() == "precious\n"
