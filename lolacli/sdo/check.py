"""``sdo check FILE``: writes to make, then reads with expected values (docs/sdo-check.md).

The file is YAML or JSON (JSON is YAML here)::

    slave: 1                      # default SLAVE of every item (optional)
    writes:                       # done first, in order (optional)
      - {object: "0x607F", value: 250000, type: UNSIGNED32}
    reads:                        # then these, in order
      - {object: "0x1000", expect: 0x00020192}
      - {object: "0x1008", expect: "LOLA drive"}
      - {object: "0x6010:01", expect: 0.0, tolerance: 0.5}
      - {object: "0x2345", expect_abort: 0x06020000}

:func:`parse_check` validates the whole file before any bus is opened and names the
first problem in one line (file, line, item, key): an :class:`InputError`, exit 3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from lolacli.errors import InputError, SdoAbortError, UsageError
from lolacli.sdo.address import ObjectAddress, parse_object
from lolacli.sdo.client import (
    choose_type,
    decode,
    encode_text,
    json_value,
)
from lolacli.sdo.session import Session, Target
from lolacli.wire.datatypes import (
    DataType,
    Value,
    data_type_from_name,
    decode_value,
    parse_int,
    type_name,
)
from lolacli.wire.sdo import abort_text

TOP_KEYS = ("slave", "writes", "reads")
ITEM_KEYS = {
    "writes": ("object", "value", "type", "slave", "expect_abort"),
    "reads": ("object", "expect", "type", "slave", "tolerance", "expect_abort"),
}


@dataclass(frozen=True, slots=True)
class CheckItem:
    kind: str  # "write" or "read"
    number: int  # position in its list, 0-based
    line: int | None
    slave: str
    address: ObjectAddress
    data_type: int | None = None
    value: Any = None  # the value to write, or the expected value
    tolerance: float | None = None
    expect_abort: int | None = None

    @property
    def where(self) -> str:
        return f"{self.kind}s[{self.number}]"


@dataclass(frozen=True, slots=True)
class CheckFile:
    path: str
    items: tuple[CheckItem, ...]


@dataclass(slots=True)
class CheckResult:
    item: CheckItem
    ok: bool
    data_type: str = ""
    value: Any = None
    raw: bytes | None = None
    abort_code: int | None = None
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        item = self.item
        return {
            "kind": item.kind,
            "item": item.where,
            "line": item.line,
            "slave": item.slave,
            "index": item.address.index,
            "subindex": item.address.subindex,
            "object": str(item.address),
            "data_type": self.data_type or None,
            "expected": json_value(item.value) if item.kind == "read" else None,
            "written": json_value(item.value) if item.kind == "write" else None,
            "expect_abort": None if item.expect_abort is None else f"0x{item.expect_abort:08X}",
            "value": json_value(self.value),
            "raw_hex": None if self.raw is None else self.raw.hex(),
            "abort_code": None if self.abort_code is None else f"0x{self.abort_code:08X}",
            "ok": self.ok,
            "message": self.message,
        }


@dataclass(slots=True)
class CheckReport:
    path: str
    results: list[CheckResult] = field(default_factory=list)

    @property
    def failed(self) -> int:
        return sum(1 for r in self.results if not r.ok)

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": "lolacli.sdo-check/1",
            "file": self.path,
            "checks": len(self.results),
            "passed": len(self.results) - self.failed,
            "failed": self.failed,
            "results": [r.to_dict() for r in self.results],
        }


# --- parsing -----------------------------------------------------------------------------------


def parse_check(text: str, path: str) -> CheckFile:
    """Validate a check file's text; InputError naming file, line, item and key."""
    import yaml

    try:
        loader = yaml.SafeLoader(text)
        try:
            node = loader.get_single_node()
            data = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        line = exc.problem_mark.line + 1 if exc.problem_mark is not None else None
        raise InputError(f"not YAML/JSON: {exc.problem}", path=path, line=line) from None
    except yaml.YAMLError as exc:
        raise InputError(f"not YAML/JSON: {exc}", path=path) from None
    return _Validator(path, node).check_file(data)


class _Validator:
    def __init__(self, path: str, root: Any) -> None:
        self.path = path
        self.lines = _item_lines(root)

    def fail(self, message: str, line: int | None = None) -> InputError:
        return InputError(message, path=self.path, line=line)

    def check_file(self, data: Any) -> CheckFile:
        if not isinstance(data, dict):
            kind = "empty" if data is None else f"a {type(data).__name__}"
            raise self.fail(f"a check file is a mapping with writes/reads lists, not {kind}", 1)
        unknown = [k for k in data if k not in TOP_KEYS]
        if unknown:
            raise self.fail(f"unknown key {unknown[0]!r} (allowed: {', '.join(TOP_KEYS)})")
        default = data.get("slave")
        if default is not None and not isinstance(default, int | str):
            raise self.fail(f"slave: {default!r} is not a position, @address, name or node ID")
        items: list[CheckItem] = []
        for key in ("writes", "reads"):
            entries = data.get(key) or []
            if not isinstance(entries, list):
                raise self.fail(f"{key}: a list of items, not {type(entries).__name__}")
            for n, entry in enumerate(entries):
                items.append(self.item(key, n, entry, default))
        if not items:
            raise self.fail("no checks: give writes and/or reads")
        return CheckFile(self.path, tuple(items))

    def item(self, key: str, n: int, entry: Any, default: Any) -> CheckItem:
        line = self.lines.get((key, n))
        where = f"{key}[{n}]"
        if not isinstance(entry, dict):
            raise self.fail(f"{where}: an item is a mapping (object: …), not {entry!r}", line)
        allowed = ITEM_KEYS[key]
        unknown = [k for k in entry if k not in allowed]
        if unknown:
            raise self.fail(
                f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(allowed)})", line
            )
        if "object" not in entry:
            raise self.fail(f'{where}: no object (like object: "0x1018:01")', line)
        try:
            address = parse_object(_object_text(entry["object"]))
        except UsageError as exc:
            raise self.fail(f"{where}: object: {exc}", line) from None
        slave = entry.get("slave", default)
        if slave is None:
            raise self.fail(f"{where}: no slave (give slave: at the top or in the item)", line)
        data_type = None
        if "type" in entry:
            data_type = data_type_from_name(str(entry["type"]))
            if data_type is None:
                raise self.fail(f"{where}: type: unknown data type {entry['type']!r}", line)
        abort = None
        if "expect_abort" in entry:
            abort = self.abort_code(entry["expect_abort"], where, line)
        value_key = "value" if key == "writes" else "expect"
        if value_key not in entry and (key == "writes" or abort is None):
            raise self.fail(f"{where}: no {value_key}", line)
        value = entry.get(value_key)
        if value is not None and not isinstance(value, bool | int | float | str):
            raise self.fail(f"{where}: {value_key}: {value!r} is not a number or a string", line)
        tolerance = entry.get("tolerance")
        if tolerance is not None and (
            isinstance(tolerance, bool) or not isinstance(tolerance, int | float) or tolerance < 0
        ):
            raise self.fail(f"{where}: tolerance: {tolerance!r} is not a number >= 0", line)
        return CheckItem(
            key[:-1],
            n,
            line,
            str(slave),
            address,
            data_type,
            value,
            None if tolerance is None else float(tolerance),
            abort,
        )

    def abort_code(self, raw: Any, where: str, line: int | None) -> int:
        try:
            code = (
                raw if isinstance(raw, int) and not isinstance(raw, bool) else parse_int(str(raw))
            )
        except ValueError:
            code = -1
        if not 0 < code <= 0xFFFFFFFF:
            raise self.fail(
                f"{where}: expect_abort: {raw!r} is not an abort code like 0x06020000", line
            )
        return code


def _object_text(raw: Any) -> str:
    # YAML reads an unquoted 0x1018 as the integer 4120: that is the index
    return f"0x{raw:X}" if isinstance(raw, int) and not isinstance(raw, bool) else str(raw)


def _item_lines(root: Any) -> dict[tuple[str, int], int]:
    """(list key, position) -> 1-based line of each item, from the YAML node tree."""
    import yaml

    lines: dict[tuple[str, int], int] = {}
    if not isinstance(root, yaml.MappingNode):
        return lines
    for key_node, value_node in root.value:
        if isinstance(value_node, yaml.SequenceNode) and key_node.value in ITEM_KEYS:
            for n, item in enumerate(value_node.value):
                lines[(key_node.value, n)] = item.start_mark.line + 1
    return lines


# --- running -----------------------------------------------------------------------------------


def run_check(check: CheckFile, session: Session) -> CheckReport:
    """Every write, then every read, in file order. Aborts and differences are results;
    a bus that does not answer raises TransportError (exit 4)."""
    report = CheckReport(check.path)
    targets: dict[str, Target] = {}
    for item in check.items:
        target = targets.get(item.slave)
        if target is None:
            target = targets[item.slave] = session.target(item.slave)
        report.results.append(_run_item(item, target))
    return report


def _run_item(item: CheckItem, target: Target) -> CheckResult:
    index, subindex = item.address.index, item.address.subindex
    choice = choose_type(index, subindex, item.data_type, target.dictionary)
    label = "" if choice.data_type is None else type_name(choice.data_type)
    try:
        if item.kind == "write":
            return _write(item, target, choice.data_type, label)
        raw = target.client.upload(index, subindex)
    except SdoAbortError as exc:
        return _aborted(item, exc.code, label)
    except UsageError as exc:  # a value that does not fit its type
        return CheckResult(item, False, label, message=f"{item.where}: {exc}")
    if item.expect_abort is not None:
        value, label, _, _ = decode(raw, choice)
        expected = f"abort 0x{item.expect_abort:08X}"
        return CheckResult(
            item, False, label, value, raw, message=f"expected {expected}, read a value"
        )
    value, label, _, note = decode(raw, choice)
    ok, message = _compare(item, choice.data_type, value)
    return CheckResult(item, ok, label, value, raw, message=message or note)


def _write(item: CheckItem, target: Target, data_type: int | None, label: str) -> CheckResult:
    if data_type is None:
        raise UsageError(
            f"{item.where}: the data type of {item.address} is not known: give type: "
            "in the item (or --eds/--esi)"
        )
    raw = encode_text(data_type, item.value)
    target.client.download(item.address.index, item.address.subindex, raw)
    if item.expect_abort is not None:
        return CheckResult(
            item,
            False,
            label,
            item.value,
            raw,
            message=f"expected abort 0x{item.expect_abort:08X}, the write was taken",
        )
    return CheckResult(item, True, label, decode_value(data_type, raw), raw)


def _aborted(item: CheckItem, code: int, label: str) -> CheckResult:
    text = abort_text(code)
    if item.expect_abort == code:
        return CheckResult(item, True, label, abort_code=code, message=text)
    if item.expect_abort is not None:
        message = f"expected abort 0x{item.expect_abort:08X}, got 0x{code:08X} {text}"
    else:
        message = f"abort 0x{code:08X}: {text}"
    return CheckResult(item, False, label, abort_code=code, message=message)


def _compare(item: CheckItem, data_type: int | None, value: Value) -> tuple[bool, str]:
    """Expected against read. The expected value goes through the type's encoding first,
    so that ``0.1`` matches a REAL32 that holds 0.1 and ``0x20192`` an UNSIGNED32."""
    expected: Any = item.value
    kind = data_type if data_type is not None else _type_of(value)
    try:
        expected = decode_value(kind, encode_text(kind, expected))
    except Exception as exc:  # UsageError/WireError: the expected value cannot be this type
        return False, f"expected {item.value!r} is not a {type_name(kind)}: {exc}"
    if (
        item.tolerance is not None
        and isinstance(value, int | float)
        and not isinstance(value, bool)
    ):
        ok = (
            isinstance(expected, int | float)
            and abs(float(value) - float(expected)) <= item.tolerance
        )
    elif isinstance(value, float) and isinstance(expected, float):
        ok = value == expected or (math.isnan(value) and math.isnan(expected))
    else:
        ok = value == expected
    if ok:
        return True, ""
    return False, f"expected {_show(expected)}, read {_show(value)}"


def _type_of(value: Value) -> int:
    if isinstance(value, bytes):
        return DataType.OCTET_STRING
    if isinstance(value, str):
        return DataType.VISIBLE_STRING
    if isinstance(value, float):
        return DataType.REAL64
    return DataType.UNSIGNED64


def _show(value: Any) -> str:
    if isinstance(value, bytes):
        return value.hex(" ") or "(empty)"
    return repr(value)


__all__ = ["CheckFile", "CheckItem", "CheckReport", "CheckResult", "parse_check", "run_check"]
