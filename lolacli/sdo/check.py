"""``sdo check FILE``: writes to make, then reads with expected values (docs/sdo.md).

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
first problem in one line (file, line, item, key): an :class:`InputError`, exit 3. A
value or expected value that does not fit the item's ``type:`` is such a problem too.

:func:`run_check` types each item as ``sdo read``/``write`` do (the target's
:class:`~lolacli.od.lookup.TypeLookup`), and adds each result to the report as
it is made, so that a stop (Ctrl-C) leaves the results so far.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from lolacli.errors import InputError, SdoAbortError, UsageError
from lolacli.od.lookup import EntryType, format_value
from lolacli.sdo.address import ObjectAddress, parse_object
from lolacli.sdo.client import decode, encode_text, json_value
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
    name: str = ""
    type_source: str = ""
    type_code: int | None = None
    note: str = ""  # for stderr: a guessed type, a --type override

    @property
    def text(self) -> str:
        """The value as every ``sdo`` command prints it."""
        return format_value(self.value, self.type_code)

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
            "name": self.name or None,
            "data_type": self.data_type or None,
            "type_source": self.type_source or None,
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
    items: int = 0  # in the file
    results: list[CheckResult] = field(default_factory=list)
    stopped_by: str | None = None  # "SIGINT"/"SIGTERM" when stopped before the end

    @property
    def failed(self) -> int:
        return sum(1 for r in self.results if not r.ok)

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": "lolacli.sdo-check/1",
            "file": self.path,
            "items": self.items,
            "checks": len(self.results),
            "passed": len(self.results) - self.failed,
            "failed": self.failed,
            "stopped_by": self.stopped_by,
            "results": [r.to_dict() for r in self.results],
        }


# --- parsing -----------------------------------------------------------------------------------


def parse_check(text: str, path: str) -> CheckFile:
    """Validate a check file's text; InputError naming file, line, item and key."""
    import yaml

    text = _json_as_yaml(text, path)
    try:
        loader = yaml.SafeLoader(text)
        try:
            node = loader.get_single_node()
            data = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        problem = exc.problem or exc.context or "not valid"
        raise InputError(f"not YAML/JSON: {problem}", path=path, line=line) from None
    except yaml.YAMLError as exc:
        raise InputError(f"not YAML/JSON: {exc}", path=path) from None
    return _Validator(path, node).check_file(data)


def _json_as_yaml(text: str, path: str) -> str:
    """JSON is YAML, except that YAML refuses the tabs JSON may be indented with. Valid
    JSON has tabs only between tokens (a tab in a string is written ``\\t``): as spaces,
    the same document on the same lines. Text that looks like JSON and is not gets
    JSON's own message and line."""
    stripped = text.lstrip()
    if not (path.lower().endswith(".json") or stripped.startswith(("{", "["))):
        return text
    try:
        json.loads(text)
    except json.JSONDecodeError as exc:
        if path.lower().endswith(".json") or "\t" in text:
            raise InputError(f"not JSON: {exc.msg}", path=path, line=exc.lineno) from None
        return text  # YAML flow style that is not JSON: YAML says what it thinks
    return text.replace("\t", " ")


class _Validator:
    def __init__(self, path: str, root: Any) -> None:
        self.path = path
        self.lines = _key_lines(root)

    def fail(self, message: str, line: int | None = None) -> InputError:
        return InputError(message, path=self.path, line=line)

    def check_file(self, data: Any) -> CheckFile:
        if not isinstance(data, dict):
            kind = "empty" if data is None else f"a {type(data).__name__}"
            raise self.fail(f"a check file is a mapping with writes/reads lists, not {kind}", 1)
        unknown = [k for k in data if k not in TOP_KEYS]
        if unknown:
            raise self.fail(
                f"unknown key {unknown[0]!r} (allowed: {', '.join(TOP_KEYS)})",
                self.lines.get(("", str(unknown[0]))),
            )
        default = data.get("slave")
        if default is not None and not isinstance(default, int | str):
            raise self.fail(
                f"slave: {default!r} is not a position, @address, name or node ID",
                self.lines.get(("", "slave")),
            )
        items: list[CheckItem] = []
        for key in ("writes", "reads"):
            entries = data.get(key) or []
            if not isinstance(entries, list):
                raise self.fail(
                    f"{key}: a list of items, not {type(entries).__name__}",
                    self.lines.get(("", key)),
                )
            for n, entry in enumerate(entries):
                items.append(self.item(key, n, entry, default))
        if not items:
            raise self.fail("no checks: give writes and/or reads")
        return CheckFile(self.path, tuple(items))

    def item(self, key: str, n: int, entry: Any, default: Any) -> CheckItem:
        where = f"{key}[{n}]"
        item_line = self.lines.get((where, ""))

        def at(name: str) -> int | None:
            return self.lines.get((where, name), item_line)

        if not isinstance(entry, dict):
            raise self.fail(f"{where}: an item is a mapping (object: …), not {entry!r}", item_line)
        allowed = ITEM_KEYS[key]
        unknown = [k for k in entry if k not in allowed]
        if unknown:
            raise self.fail(
                f"{where}: unknown key {unknown[0]!r} (allowed: {', '.join(allowed)})",
                at(str(unknown[0])),
            )
        if "object" not in entry:
            raise self.fail(f'{where}: no object (like object: "0x1018:01")', item_line)
        try:
            address = parse_object(_object_text(entry["object"]))
        except UsageError as exc:
            raise self.fail(f"{where}: object: {exc}", at("object")) from None
        slave = entry.get("slave", default)
        if slave is None:
            raise self.fail(f"{where}: no slave (give slave: at the top or in the item)", item_line)
        if not isinstance(slave, int | str) or isinstance(slave, bool):
            raise self.fail(
                f"{where}: slave: {slave!r} is not a position, name or node ID", at("slave")
            )
        data_type = None
        if "type" in entry:
            data_type = data_type_from_name(str(entry["type"]))
            if data_type is None:
                raise self.fail(f"{where}: type: unknown data type {entry['type']!r}", at("type"))
        abort = None
        if "expect_abort" in entry:
            abort = self.abort_code(entry["expect_abort"], where, at("expect_abort"))
        value_key = "value" if key == "writes" else "expect"
        if value_key not in entry and (key == "writes" or abort is None):
            raise self.fail(f"{where}: no {value_key}", item_line)
        value = entry.get(value_key)
        if value_key in entry and value is None:
            raise self.fail(
                f"{where}: {value_key}: empty (null): give a number or a string", at(value_key)
            )
        if value is not None and not isinstance(value, bool | int | float | str):
            raise self.fail(
                f"{where}: {value_key}: {value!r} is not a number or a string", at(value_key)
            )
        if value is not None and data_type is not None:
            try:
                encode_text(data_type, value)
            except UsageError as exc:
                raise self.fail(f"{where}: {value_key}: {exc}", at(value_key)) from None
        tolerance = entry.get("tolerance")
        if tolerance is not None and (
            isinstance(tolerance, bool)
            or not isinstance(tolerance, int | float)
            or not math.isfinite(tolerance)  # NaN fails every comparison, inf passes them all
            or tolerance < 0
        ):
            raise self.fail(
                f"{where}: tolerance: {tolerance!r} is not a finite number >= 0", at("tolerance")
            )
        return CheckItem(
            key[:-1],
            n,
            item_line,
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


def _key_lines(root: Any) -> dict[tuple[str, str], int]:
    """1-based lines from the YAML node tree: ``("", key)`` of a top-level key's value,
    ``("reads[0]", "")`` of an item, ``("reads[0]", key)`` of an item's key's value."""
    import yaml

    lines: dict[tuple[str, str], int] = {}
    if not isinstance(root, yaml.MappingNode):
        return lines
    for key_node, value_node in root.value:
        top = str(key_node.value)
        lines[("", top)] = key_node.start_mark.line + 1
        if not (isinstance(value_node, yaml.SequenceNode) and top in ITEM_KEYS):
            continue
        for n, item in enumerate(value_node.value):
            where = f"{top}[{n}]"
            lines[(where, "")] = item.start_mark.line + 1
            if isinstance(item, yaml.MappingNode):
                for k, v in item.value:
                    lines[(where, str(k.value))] = v.start_mark.line + 1
    return lines


# --- running -----------------------------------------------------------------------------------


def run_check(
    check: CheckFile,
    session: Session,
    report: CheckReport | None = None,
    on_result: Callable[[CheckResult], None] | None = None,
) -> CheckReport:
    """Every write, then every read, in file order, each result added to ``report`` (and
    given to ``on_result``) as soon as it is made. Aborts and differences are results; a
    bus that does not answer raises TransportError (exit 4)."""
    report = report if report is not None else CheckReport(check.path)
    report.items = len(check.items)
    targets: dict[str, Target] = {}
    for item in check.items:
        target = targets.get(item.slave)
        if target is None:
            target = targets[item.slave] = session.target(item.slave)
        result = _run_item(item, target)
        report.results.append(result)
        if on_result is not None:
            on_result(result)
    return report


def _run_item(item: CheckItem, target: Target) -> CheckResult:
    index, subindex = item.address.index, item.address.subindex
    lookup = target.lookup
    try:
        if item.kind == "write":
            typed = lookup.entry_type(index, subindex, explicit=item.data_type)
            return _write(item, target, typed)
        raw = target.client.upload(index, subindex)
    except SdoAbortError as exc:
        return _aborted(item, exc.code, lookup.entry_type(index, subindex, explicit=item.data_type))
    except UsageError as exc:  # a value that does not fit its type
        typed = lookup.entry_type(index, subindex, explicit=item.data_type)
        return _typed(item, False, typed, message=f"{item.where}: {exc}")
    typed = lookup.entry_type(index, subindex, explicit=item.data_type, raw=raw)
    value, code, note = decode(raw, typed)
    label = type_name(code) if code is not None else ""
    base = CheckResult(
        item, False, label, value, raw, None, "", typed.name, typed.source, code, note
    )
    if item.expect_abort is not None:
        base.message = f"expected abort 0x{item.expect_abort:08X}, read a value"
        return base
    base.ok, base.message = _compare(item, code, value)
    return base


def _typed(item: CheckItem, ok: bool, typed: EntryType, **fields: Any) -> CheckResult:
    fields.setdefault("note", typed.note)
    return CheckResult(
        item,
        ok,
        typed.type_label,
        name=typed.name,
        type_source=typed.source,
        type_code=typed.data_type,
        **fields,
    )


def _write(item: CheckItem, target: Target, typed: EntryType) -> CheckResult:
    if typed.data_type is None:
        raise UsageError(
            f"{item.where}: the data type of {item.address} is not known: give type: "
            "in the item (or --eds/--esi)"
        )
    raw = encode_text(typed.data_type, item.value)
    target.client.download(item.address.index, item.address.subindex, raw)
    if item.expect_abort is not None:
        return _typed(
            item,
            False,
            typed,
            value=item.value,
            raw=raw,
            message=f"expected abort 0x{item.expect_abort:08X}, the write was taken",
        )
    return _typed(item, True, typed, value=decode_value(typed.data_type, raw), raw=raw)


def _aborted(item: CheckItem, code: int, typed: EntryType) -> CheckResult:
    text = abort_text(code)
    if item.expect_abort == code:
        return _typed(item, True, typed, abort_code=code, message=text, note="")
    if item.expect_abort is not None:
        message = f"expected abort 0x{item.expect_abort:08X}, got 0x{code:08X} {text}"
    else:
        message = f"abort 0x{code:08X}: {text}"
    return _typed(item, False, typed, abort_code=code, message=message, note="")


def _compare(item: CheckItem, data_type: int | None, value: Value) -> tuple[bool, str]:
    """Expected against read. The expected value goes through the type's encoding first,
    so that ``0.1`` matches a REAL32 that holds 0.1 and ``0x20192`` an UNSIGNED32."""
    expected: Any = item.value
    kind = data_type if data_type is not None else _type_of(value)
    try:
        expected = decode_value(kind, encode_text(kind, expected))
    except Exception as exc:  # UsageError/WireError: the expected value cannot be this type
        return False, f"expected {format_value(item.value, None)} is not a {type_name(kind)}: {exc}"
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
    return False, f"expected {format_value(expected, kind)}, read {format_value(value, kind)}"


def _type_of(value: Value) -> int:
    if isinstance(value, bytes):
        return DataType.OCTET_STRING
    if isinstance(value, str):
        return DataType.VISIBLE_STRING
    if isinstance(value, float):
        return DataType.REAL64
    return DataType.UNSIGNED64


__all__ = ["CheckFile", "CheckItem", "CheckReport", "CheckResult", "parse_check", "run_check"]
