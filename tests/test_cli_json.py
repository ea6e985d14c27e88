"""The one JSON writer (lolacli.cli.common.json_text, orjson) against json's own encoder:
the same document on every corpus capture's report, the same text but for the spelling of
float exponents (1e-05 / 0.00001); NaN, wide integers and numpy scalars handled."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from lolacli.capture.analyze import analyze_file
from lolacli.cli.common import json_text

EXPONENT = re.compile(r"\d[eE][-+]?\d")


def _captures(corpus):
    return sorted(p for p in (corpus / "pcap").iterdir() if p.suffix in (".pcap", ".pcapng"))


def test_every_corpus_report_is_the_document_json_writes(corpus):
    files = _captures(corpus)
    assert len(files) >= 10
    same_text = 0
    for path in files:
        doc = analyze_file(path).to_dict()
        ours = json_text(doc)
        theirs = json.dumps(doc, indent=2, ensure_ascii=False)
        assert json.loads(ours) == json.loads(theirs), path.name
        if not EXPONENT.search(theirs):
            assert ours == theirs, path.name
            same_text += 1
    assert same_text >= len(files) // 2


def test_values_json_has_no_simple_form_for():
    doc = {"nan": math.nan, "inf": [-math.inf], 7: "µs", "np": np.float64(0.25),
           "n": np.int64(-3), "flag": True}
    assert json.loads(json_text(doc)) == {"nan": None, "inf": [None], "7": "µs",
                                          "np": 0.25, "n": -3, "flag": True}
    wide = {"v": 2**70, "nan": [math.nan], "np": np.int64(5)}  # json's path
    assert json.loads(json_text(wide)) == {"v": 2**70, "nan": [None], "np": 5}
    with pytest.raises(TypeError):
        json_text({"x": object()})


def test_an_undecodable_file_name_is_written_as_valid_utf8(tmp_path, corpus):
    """A name's bytes that are not UTF-8 (Python holds them as lone surrogates) come out
    as U+FFFD: the document is valid UTF-8 JSON, for the library and the CLI alike."""
    import os
    import subprocess
    import sys

    assert json.loads(json_text({"file": "bad\udcffname"})) == {"file": "bad\ufffdname"}
    name = os.fsdecode(b"bad\xffname.pcapng")
    path = tmp_path / name
    path.write_bytes((corpus / "pcap" / "ethercrab__replay-sdo-error.pcapng").read_bytes())
    out = subprocess.run([sys.executable, "-m", "lolacli", "capture", "analyze", "-f", "json",
                          str(path)], capture_output=True, check=False)
    assert out.returncode in (0, 1), out.stderr
    doc = json.loads(out.stdout.decode("utf-8"))  # strict: fails on a raw 0xFF byte
    assert doc["file"].endswith("bad\ufffdname.pcapng")
