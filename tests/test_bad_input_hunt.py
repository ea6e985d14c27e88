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


# --------------------------------------------------------------------------- bus timing numbers


@pytest.mark.parametrize(
    "args",
    [
        ("--measured", "1e400us"),
        ("--measured", "1e18s"),
        ("--budget-us", "inf"),
        ("--budget-us", "1e308"),
        ("--link-mbit", "inf"),
        ("--link-mbit", "1e308"),
        ("--cable-m", "inf"),
        ("--cable-m", "1e308"),
        ("--frame-bytes", "10", "--slaves", "99999999999999999999999"),
        ("--frame-bytes", "99999999999999999999999", "--slaves", "1"),
        ("--per-slave-ns", "99999999999999999999999"),
    ],
)
@pytest.mark.parametrize("fmt", ["human", "json"])
def test_timing_huge_numbers_are_usage_errors(cli, args: tuple[str, ...], fmt: str) -> None:
    code, out, err = cli("bus", "timing", *args, "-f", fmt)
    assert code == 2
    assert out == ""
    assert _one_line(err).startswith("lolacli: error:")


def test_estimate_refuses_out_of_range_values() -> None:
    from lolacli.errors import UsageError
    from lolacli.timing.model import estimate, parse_duration_ns

    for kwargs in (
        {"cable_m_per_segment": float("inf")},
        {"cable_m_per_segment": float("nan")},
        {"cable_m_per_segment": 1e308},
        {"budget_ns": 10**30},
        {"measured_total_ns": 10**30},
        {"per_slave_delay_ns": 10**30},
        {"link_bit_s": 10**30},
    ):
        with pytest.raises(UsageError):
            estimate(846, 25, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(UsageError):
        estimate(846, 10**23)
    with pytest.raises(UsageError):
        estimate(10**400, 1)
    with pytest.raises(UsageError):
        parse_duration_ns("1e400us")


def test_timing_capture_with_zero_round_trips_is_exit_3(cli, corpus: Path) -> None:
    # the classic-pcap copy has equal timestamps on each out/return pair
    path = corpus / "pcap" / "DERIVED__ethercrab__twincat-run-ek1100-el1004.classic.pcap"
    code, out, err = cli("bus", "timing", "--capture", path)
    assert code == 3
    assert "0 µs" in _one_line(err)


# --------------------------------------------------------------------------- endless "files"


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero")
def test_endless_eni_file_is_refused_not_read_forever(cli) -> None:
    from lolacli.files import load_eni, load_esi

    with pytest.raises(EniError, match="too large"):
        load_eni("/dev/zero")
    with pytest.raises(EniError, match="too large"):
        load_esi("/dev/zero")
    code, _out, err = cli("eni", "validate", "/dev/zero")
    assert code == 3
    assert "too large" in _one_line(err)


# --------------------------------------------------------------------------- negative counts


@pytest.mark.parametrize(
    "args",
    [
        ("capture", "list", LOLA_PCAP, "-c", "-5"),
        ("capture", "analyze", LOLA_PCAP, "--max-lost", "-1"),
        ("capture", "analyze", LOLA_PCAP, "--max-wkc-mismatches", "-1"),
        ("bus", "emulate", "-i", "nosuchif0", "--duration", "-1"),
        ("bus", "emulate", "-i", "nosuchif0", "--duration", "nan"),
        ("bus", "emulate", "-i", "nosuchif0", "--realtime-priority", "100"),
        ("bus", "emulate", "-i", "nosuchif0", "--realtime-priority", "-1"),
    ],
)
def test_negative_or_out_of_range_option_is_usage_error(cli, corpus: Path, args) -> None:
    code, out, err = cli(*args)
    assert code == 2
    assert out == ""
    option = {"-c": "-c/--count"}.get(args[-2], args[-2])
    assert f"error: {option}: " in err and "Traceback" not in err
    assert len(err.rstrip("\n").splitlines()) == 1 and len(err.rstrip("\n")) <= 80, err


def test_list_frames_refuses_a_negative_count(corpus: Path) -> None:
    from lolacli.capture.listing import list_frames
    from lolacli.errors import UsageError

    with pytest.raises(UsageError):
        next(iter(list_frames(LOLA_PCAP, count=-5)))
    assert list(list_frames(LOLA_PCAP, count=0)) == []


# --------------------------------------------------------------------------- ENI numbers


def _lola_with(old: str, new: str) -> str:
    from lolacli.cli.common import default_eni

    text = default_eni().read_text(encoding="utf-8")
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize("length", ["-1", "18446744073709551616", "2000000000"])
def test_init_cmd_data_length_out_of_range_is_eni_error(
    cli, tmp_path: Path, length: str
) -> None:
    from lolacli.eni.parser import parse_eni

    doc = (
        "<EtherCATConfig><Config><Slave><Info><Name>s</Name></Info><InitCmds><InitCmd>"
        "<Transition>PS</Transition><Cmd>2</Cmd><Adp>0</Adp><Ado>#x130</Ado>"
        f"<DataLength>{length}</DataLength></InitCmd></InitCmds></Slave></Config>"
        "</EtherCATConfig>"
    )
    with pytest.raises(EniError, match="DataLength"):
        parse_eni(doc, "x.xml")
    f = tmp_path / "len.xml"
    f.write_text(doc)
    code, _out, err = cli("eni", "inspect", f)
    assert code == 3
    assert "DataLength" in _one_line(err)


# --------------------------------------------------------------------------- bus emulate


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("<BitLen>16</BitLen>", "<BitLen>256</BitLen>"),
        ("<SubIndex>0</SubIndex>", "<SubIndex>-1</SubIndex>"),
        ("<Index>#x6041</Index>", "<Index>#x16041</Index>"),
    ],
)
def test_emulate_eni_numbers_too_wide_for_the_sii_are_exit_3(
    cli, tmp_path: Path, old: str, new: str
) -> None:
    f = tmp_path / "wide.xml"
    f.write_text(_lola_with(old, new), encoding="utf-8")
    code, _out, err = cli("bus", "emulate", "-i", "nosuchif0", "--eni", f, "--duration", "0.1")
    assert code == 3
    line = _one_line(err)  # refused by the parser, before any SII is built: file and line
    assert f"{f}:" in line and f"{new.split('>')[0]}> " in line and "is outside" in line
