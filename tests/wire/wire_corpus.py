"""Test helpers for the wire codec: raw packets from corpus captures, and tshark as oracle.

The packet reader is deliberately minimal (pcapng EPB/SPB/OPB and classic pcap records)
and independent of lolacli.capture, so the codec is checked against tshark without
depending on another package's reader.
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
from pathlib import Path
from typing import Any

import pytest

# Same rule as tests/conftest.py (not imported by name: "conftest" is not a unique module).
ROOT = Path(__file__).resolve().parents[2]
CORPUS = Path(os.environ.get("LOLACLI_CORPUS", ROOT.parent / "shared" / "corpus"))
PCAPS = sorted((CORPUS / "pcap").glob("*")) if (CORPUS / "pcap").is_dir() else []
PCAP_IDS = [p.name for p in PCAPS]
TSHARK = shutil.which("tshark")

_PCAPNG_SHB = 0x0A0D0D0A
_CLASSIC = {
    b"\xd4\xc3\xb2\xa1": "<",
    b"\x4d\x3c\xb2\xa1": "<",
    b"\xa1\xb2\xc3\xd4": ">",
    b"\xa1\xb2\x3c\x4d": ">",
}


def need_corpus_and_tshark() -> None:
    if not PCAPS:
        pytest.skip(f"no captures under {CORPUS / 'pcap'}")
    if TSHARK is None:
        pytest.skip("tshark not installed")


def read_packets(path: Path) -> list[bytes]:
    """Captured bytes of every packet, in file order (tshark's frame.number - 1)."""
    data = path.read_bytes()
    if data[:4] in _CLASSIC:
        return _classic(data, _CLASSIC[data[:4]])
    return _pcapng(data)


def _classic(data: bytes, endian: str) -> list[bytes]:
    rec = struct.Struct(endian + "IIII")
    out: list[bytes] = []
    pos = 24
    while pos + rec.size <= len(data):
        _, _, caplen, _ = rec.unpack_from(data, pos)
        pos += rec.size
        out.append(data[pos : pos + caplen])
        pos += caplen
    return out


def _pcapng(data: bytes) -> list[bytes]:
    out: list[bytes] = []
    pos = 0
    endian = "<"
    while pos + 12 <= len(data):
        (btype,) = struct.unpack_from(endian + "I", data, pos)
        if btype == _PCAPNG_SHB:
            endian = "<" if data[pos + 8 : pos + 12] == b"\x4d\x3c\x2b\x1a" else ">"
        (blen,) = struct.unpack_from(endian + "I", data, pos + 4)
        body = pos + 8
        if btype == 6:  # enhanced packet block
            (caplen,) = struct.unpack_from(endian + "I", data, body + 12)
            out.append(data[body + 20 : body + 20 + caplen])
        elif btype == 3:  # simple packet block
            (origlen,) = struct.unpack_from(endian + "I", data, body)
            out.append(data[body + 4 : body + 4 + min(origlen, blen - 16)])
        elif btype == 2:  # obsolete packet block
            (caplen,) = struct.unpack_from(endian + "I", data, body + 12)
            out.append(data[body + 20 : body + 20 + caplen])
        pos += blen
    return out


DATAGRAM_FIELDS = (
    "frame.number",
    "ecatf.length",
    "ecatf.type",
    "ecat.cmd",
    "ecat.idx",
    "ecat.adp",
    "ecat.ado",
    "ecat.lad",
    "ecat.subframe.length",
    "ecat.subframe.circulating",
    "ecat.subframe.more",
    "ecat.int",
    "ecat.cnt",
)


def tshark_datagrams(path: Path) -> dict[int, dict[str, list[str]]]:
    """Per EtherCAT frame number: each datagram field as the list tshark gives."""
    args = [str(TSHARK), "-r", str(path), "-T", "fields", "-E", "occurrence=a"]
    args += ["-E", "aggregator=|", "-E", "separator=\t", "-Y", "ecat"]
    for name in DATAGRAM_FIELDS:
        args += ["-e", name]
    text = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    out: dict[int, dict[str, list[str]]] = {}
    for line in text.splitlines():
        cells = line.split("\t")
        row = {k: (v.split("|") if v else []) for k, v in zip(DATAGRAM_FIELDS, cells, strict=True)}
        out[int(cells[0])] = row
    return out


def tshark_malformed(path: Path) -> set[int]:
    """Frame numbers tshark marks as malformed."""
    args = [str(TSHARK), "-r", str(path), "-T", "fields", "-e", "frame.number"]
    args += ["-Y", "_ws.malformed"]
    text = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    return {int(x) for x in text.split()}


def tshark_mailboxes(path: Path) -> dict[int, list[tuple[dict[str, str], dict[str, Any]]]]:
    """Per frame number: ``(datagram header fields, flattened mailbox fields)`` for every
    datagram tshark decoded as a mailbox."""
    args = [str(TSHARK), "-r", str(path), "-T", "json", "--no-duplicate-keys"]
    args += ["-Y", "ecat_mailbox"]
    text = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    out: dict[int, list[tuple[dict[str, str], dict[str, Any]]]] = {}
    for packet in json.loads(text or "[]"):
        layers = packet["_source"]["layers"]
        number = int(_first(layers["frame"]["frame.number"]))
        for entry in _datagram_entries(layers.get("ecat", {})):
            if "ecat_mailbox" not in entry:
                continue
            head: dict[str, Any] = {}
            _flatten(entry.get("Header", {}), head)
            for mailbox in _as_list(entry["ecat_mailbox"]):
                fields: dict[str, Any] = {}
                _flatten(mailbox, fields)
                out.setdefault(number, []).append((head, fields))
    return out


def _as_list(value: Any) -> list[Any]:
    return value if isinstance(value, list) else [value]


def _first(value: Any) -> str:
    return str(value[0] if isinstance(value, list) else value)


def _datagram_entries(ecat: dict[str, Any]) -> list[dict[str, Any]]:
    entries: list[dict[str, Any]] = []
    for key, value in ecat.items():
        if key.startswith("EtherCAT datagram"):
            entries.extend(v for v in _as_list(value) if isinstance(v, dict))
    return entries


def _flatten(tree: Any, out: dict[str, Any]) -> None:
    """Collect ``name: value`` leaves of a tshark JSON subtree; repeats become lists."""
    if isinstance(tree, list):
        for item in tree:
            _flatten(item, out)
        return
    if not isinstance(tree, dict):
        return
    for key, value in tree.items():
        if isinstance(value, (dict, list)) and not (
            isinstance(value, list) and all(isinstance(v, str) for v in value)
        ):
            _flatten(value, out)
        elif "." in key and " " not in key:
            values = value if isinstance(value, list) else [value]
            for v in values:
                if key in out:
                    prev = out[key]
                    out[key] = (prev if isinstance(prev, list) else [prev]) + [v]
                else:
                    out[key] = v
