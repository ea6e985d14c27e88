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
