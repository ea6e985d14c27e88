"""Parameter values without pydantic.

typer 0.29 turns each command-line value into its annotated type through a pydantic
``TypeAdapter`` built on first use. Importing pydantic (which brings asyncio and ssl) and
building an adapter per parameter is about a third of the instructions of a short command:
``lolacli sdo read 5 0x1000`` on the emulated chain runs ~1,600 M instructions, ~500 M of
them in that (callgrind, benchmarks/sdo_read.py). The annotations lolacli's commands use —
``str``, ``bool``, ``int``/``float`` with ``min``/``max``/``clamp``, ``Path`` (typer's own existence
and access checks, :func:`typer._param_types.coerce_cli_path`), ``Enum`` choices
(:func:`typer._param_types.coerce_cli_choice`), and lists of these — are converted here
by typer's rules, with pydantic's wording in the messages; anything else (``parser=``,
``click_type``, ``datetime``, tuples, files) is left to typer.

:func:`install` hooks into typer's private parameter class; when a typer release no longer
has the parts it hooks into, it does nothing and typer works as it would without it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, get_args, get_origin

Convert = Callable[[Any, Any, Any], Any]  # (value, param, ctx) -> value
#: the words pydantic reads as booleans (besides bool values)
_TRUE = frozenset({"1", "on", "t", "true", "y", "yes"})
_FALSE = frozenset({"0", "off", "f", "false", "n", "no"})


def install() -> bool:
    """Let lolacli's commands convert their simple parameters without pydantic; False
    when this typer does not have what the hook needs (nothing is changed then)."""
    try:
        from typer import core
        from typer._coercion import RuntimeParam
        from typer._param_types import coerce_cli_choice, coerce_cli_path
    except ImportError:
        return False
    cls = getattr(core, "_TyperParameter", None)
    original = getattr(cls, "get_runtime_param", None)
    if cls is None or original is None or not hasattr(RuntimeParam, "_coerce_value"):
        return False
    if getattr(original, "_lolacli", False):
        return True
    light = _light_param_class(RuntimeParam)
    helpers = (coerce_cli_choice, coerce_cli_path)

    def get_runtime_param(self: Any) -> Any:
        if getattr(self, "_runtime_param", None) is None:
            descriptor: Any = getattr(self, "type_descriptor", None)
            convert = _converter(descriptor, helpers) if descriptor is not None else None
            if convert is not None:
                self._runtime_param = light(
                    parameter_info=descriptor.parameter_info,
                    annotation=descriptor.annotation,
                    convert=convert,
                )
        return original(self)

    get_runtime_param._lolacli = True  # type: ignore[attr-defined]
    cls.get_runtime_param = get_runtime_param
    return True


def _light_param_class(base: type) -> type:
    @dataclass(frozen=True)
    class LightRuntimeParam(base):  # type: ignore[misc]
        convert: Convert

        def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
            return self.convert(value, param, ctx)

    return LightRuntimeParam


def _converter(descriptor: Any, helpers: tuple[Any, Any]) -> Convert | None:
    """The conversion of a parameter, or None to leave it to typer."""
    if getattr(descriptor, "file_annotation", None) is not None:
        return None
    info = descriptor.parameter_info
    if getattr(info, "parser", None) is not None or getattr(info, "click_type", None) is not None:
        return None
    annotation = descriptor.annotation
    if get_origin(annotation) is list:
        (item,) = get_args(annotation) or (None,)
        leaf = _leaf(item, info, helpers)
        if leaf is None:
            return None
        one = leaf

        def each(value: Any, param: Any, ctx: Any) -> list[Any]:
            values = value if isinstance(value, list | tuple) else [value]
            return [one(v, param, ctx) for v in values]

        return each
    return _leaf(annotation, info, helpers)


def _leaf(annotation: Any, info: Any, helpers: tuple[Any, Any]) -> Convert | None:
    from typer._click.exceptions import BadParameter

    choice, path = helpers
    if annotation is str:
        return _text
    if annotation is int or annotation is float:
        return _number(annotation, info, BadParameter)
    if annotation is bool:

        def truth(value: Any, param: Any, ctx: Any) -> bool:
            if isinstance(value, bool):
                return value
            word = _text(value).strip().lower()
            if word in _TRUE or word in _FALSE:
                return word in _TRUE
            if word == "":  # typer reads an empty value as false
                return False
            raise BadParameter(
                "Input should be a valid boolean, unable to interpret input", ctx=ctx, param=param
            )

        return truth
    if isinstance(annotation, type) and issubclass(annotation, Enum):
        choices = list(annotation)
        case_sensitive = getattr(info, "case_sensitive", True)

        def pick(value: Any, param: Any, ctx: Any) -> Any:
            try:
                return choice(value, choices=choices, case_sensitive=case_sensitive, ctx=ctx)
            except ValueError as exc:
                raise BadParameter(f"Value error, {exc}", ctx=ctx, param=param) from None

        return pick
    if isinstance(annotation, type) and issubclass(annotation, Path):
        path_type = getattr(info, "path_type", None) or annotation
        if not (isinstance(path_type, type) and issubclass(path_type, Path)):
            return None

        def to_path(value: Any, param: Any, ctx: Any) -> Any:
            if isinstance(value, bytes):
                value = _text(value, param, ctx)
            if not isinstance(value, path_type):
                value = path_type(value)
            return path(value, info, path_type=path_type, param=param, ctx=ctx)

        return to_path
    return None


def _text(value: Any, _param: Any = None, _ctx: Any = None) -> str:
    if isinstance(value, bytes):
        import sys

        return value.decode(sys.getfilesystemencoding(), "replace")
    return str(value)


def _number(kind: type, info: Any, bad: Any) -> Convert:
    low, high = getattr(info, "min", None), getattr(info, "max", None)
    clamp = bool(getattr(info, "clamp", False))
    noun = ("integer", "an integer") if kind is int else ("number", "a number")

    def convert(value: Any, param: Any, ctx: Any) -> Any:
        try:
            number = _parse(kind, value.strip() if isinstance(value, str) else value)
        except (TypeError, ValueError, OverflowError):
            raise bad(
                f"Input should be a valid {noun[0]}, unable to parse string as {noun[1]}",
                ctx=ctx,
                param=param,
            ) from None
        if number != number and not clamp:  # NaN meets no bound; pydantic checks le first
            if high is not None:
                raise bad(
                    f"Input should be less than or equal to {_bound(high)}", ctx=ctx, param=param
                )
            if low is not None:
                raise bad(
                    f"Input should be greater than or equal to {_bound(low)}", ctx=ctx, param=param
                )
        if low is not None and number < low:
            if not clamp:
                raise bad(
                    f"Input should be greater than or equal to {_bound(low)}", ctx=ctx, param=param
                )
            number = kind(low)
        if high is not None and number > high:
            if not clamp:
                raise bad(
                    f"Input should be less than or equal to {_bound(high)}", ctx=ctx, param=param
                )
            number = kind(high)
        return number

    return convert


def _bound(limit: float) -> str:
    """A bound as pydantic-core writes it (Rust's Display): ``0`` for 0.0, no exponent."""
    if isinstance(limit, float):
        if limit.is_integer():
            return str(int(limit))
        text = repr(limit)
        if "e" in text or "E" in text:
            from decimal import Decimal

            text = format(Decimal(text), "f")
        return text
    return str(limit)


def _parse(kind: type, value: Any) -> Any:
    """int or float of a value as pydantic reads it: ASCII digits only, ``"5.00"`` is the
    integer 5, ``"1e3"`` is not an integer."""
    if isinstance(value, str):
        if not value.isascii():
            raise ValueError(value)
        if kind is int:
            import re

            match = re.fullmatch(r"([+-]?[0-9]+(?:_[0-9]+)*)(?:\.0+)?", value)
            if match is None:
                raise ValueError(value)
            return int(match.group(1))
    return kind(value)


__all__ = ["install"]
