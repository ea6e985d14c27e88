"""Parsed ENIs kept between runs (lolacli/eni_cache.py): the same model as a parse, never
an old one for changed bytes, nothing read that someone else could have written."""

from __future__ import annotations

import pickle
import shutil

import pytest

import lolacli.eni.parser
from lolacli.eni_cache import cache_key, load_eni_cached
from lolacli.errors import EniError
from lolacli.files import load_eni, read_eni_bytes
from tests.live import EXAMPLES, LOLA

SINGLE = EXAMPLES / "single_drive.xml"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("LOLACLI_CACHE_DIR", str(folder))
    return folder


@pytest.fixture
def parses(monkeypatch):
    """How often the parser runs."""
    calls = []
    real = lolacli.eni.parser.parse_eni

    def counting(data, source="<string>"):
        calls.append(source)
        return real(data, source=source)

    monkeypatch.setattr(lolacli.eni.parser, "parse_eni", counting)
    return calls


def test_the_cached_model_is_the_parsed_one(cache, parses) -> None:
    first = load_eni_cached(LOLA)
    second = load_eni_cached(LOLA)
    assert parses == [str(LOLA)]
    assert first == second == load_eni(LOLA)
    entries = list(cache.glob("*.eni.pickle"))
    assert len(entries) == 1 and entries[0].name.startswith(cache_key(read_eni_bytes(LOLA)))
    assert oct(cache.stat().st_mode & 0o777) == "0o700"


def test_changed_bytes_are_parsed_again(cache, parses, tmp_path) -> None:
    path = tmp_path / "chain.xml"
    shutil.copy(SINGLE, path)
    a = load_eni_cached(path)
    text = path.read_text(encoding="utf-8").replace("<Name>", "<Name>X", 1)
    path.write_text(text, encoding="utf-8")
    b = load_eni_cached(path)
    assert len(parses) == 2 and a != b
    assert b == load_eni(path)


def test_another_path_with_the_same_bytes_keeps_its_own_name(cache, parses, tmp_path) -> None:
    copy = tmp_path / "copy.xml"
    shutil.copy(SINGLE, copy)
    assert load_eni_cached(SINGLE).source == str(SINGLE)
    assert load_eni_cached(copy).source == str(copy)
    assert len(parses) == 1


def test_a_damaged_entry_is_parsed_over(cache, parses) -> None:
    reference = load_eni(SINGLE)
    parses.clear()
    load_eni_cached(SINGLE)
    (entry,) = cache.glob("*.eni.pickle")
    entry.write_bytes(b"not a pickle")
    assert load_eni_cached(SINGLE) == reference
    assert len(parses) == 2
    assert load_eni_cached(SINGLE) == reference and len(parses) == 2  # rewritten


def test_an_entry_others_could_write_is_not_read(cache, parses) -> None:
    """A pickle runs code when read: an entry anyone may write to is ignored (and so is
    one in a folder anyone may write to)."""
    real = load_eni_cached(SINGLE)
    (entry,) = cache.glob("*.eni.pickle")
    planted = type(real)(real.master, (), (), real.process_image, source="planted")
    entry.write_bytes(pickle.dumps(planted))
    entry.chmod(0o666)
    assert load_eni_cached(SINGLE).slaves == real.slaves
    entry.chmod(0o600)
    cache.chmod(0o777)
    entry.write_bytes(pickle.dumps(planted))
    assert load_eni_cached(SINGLE).slaves == real.slaves
    cache.chmod(0o700)
    assert load_eni_cached(SINGLE).slaves == ()  # ours again: it is read (proof it was there)


def test_turned_off_and_unwritable(tmp_path, monkeypatch, parses) -> None:
    reference = load_eni(SINGLE)
    parses.clear()
    monkeypatch.setenv("LOLACLI_CACHE_DIR", "")
    assert load_eni_cached(SINGLE) == reference
    monkeypatch.setenv("LOLACLI_CACHE_DIR", str(tmp_path / "file"))
    (tmp_path / "file").write_text("a file where the folder should be")
    assert load_eni_cached(SINGLE) == reference
    assert load_eni_cached(SINGLE) == reference
    assert len(parses) == 3


def test_bad_files_are_the_loaders_errors(cache, tmp_path) -> None:
    with pytest.raises(EniError, match="no such file"):
        load_eni_cached(tmp_path / "nosuch.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text("<EtherCATConfig><Config>")
    with pytest.raises(EniError, match="bad.xml"):
        load_eni_cached(bad)
    assert not list(cache.glob("*.eni.pickle"))


def test_a_cached_model_cannot_bypass_the_parsers_limits(cache, parses, tmp_path) -> None:
    """An entry under the right key whose model holds a number the parser refuses (written
    by other code, or by a parser before the limits) is not served: the file is parsed, and
    its error is the parser's, with the line."""
    from dataclasses import replace

    path = tmp_path / "bad.xml"
    text = SINGLE.read_text(encoding="utf-8")
    path.write_text(text.replace("<DataLength>2</DataLength>", "<DataLength>-56</DataLength>"))
    with pytest.raises(EniError, match=r"bad\.xml:\d+: <DataLength> -56 is outside"):
        load_eni(path)
    good = load_eni(SINGLE)
    frame = good.cyclic[0].frames[0]
    bad_cmd = replace(frame.commands[1], data_length_bytes=-56)
    frames = (replace(frame, commands=(frame.commands[0], bad_cmd)),)
    planted = replace(good, cyclic=(replace(good.cyclic[0], frames=frames),))
    cache.mkdir(mode=0o700)
    entry = cache / (cache_key(read_eni_bytes(path)) + ".eni.pickle")
    entry.write_bytes(pickle.dumps(planted))
    entry.chmod(0o600)
    parses.clear()
    with pytest.raises(EniError, match=r"bad\.xml:\d+: <DataLength> -56 is outside"):
        load_eni_cached(path)
    assert parses == [str(path)]


def test_the_key_follows_the_parsers_limits_and_codecs() -> None:
    """The key covers the modules the parser is made of: the limits it enforces and the
    wire codecs it decodes with, not only the reader (each by name, size and mtime)."""
    from lolacli.eni_cache import _package_fingerprint

    parts = _package_fingerprint().decode().split("|")
    names = {p.rsplit(":", 2)[0] for p in parts[1:]}
    assert {"eni/parser.py", "eni/limits.py", "eni/model.py", "wire/frame.py"} <= names
    assert {"wire/registers.py", "wire/commands.py"} <= names
