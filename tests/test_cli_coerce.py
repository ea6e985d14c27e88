"""lolacli/cli/coerce.py converts parameter values as typer's pydantic adapters do.

Every parameter of every lolacli command is converted both ways — ours, and the
``TypeAdapter`` typer 0.29 builds for it — from the same inputs (good and bad ones), and
the values or the error messages must be the same. A whole process of ``sdo read`` must
not import pydantic.
"""

from __future__ import annotations

import math
import subprocess
import sys
from enum import Enum
from pathlib import Path
from typing import Any, get_args, get_origin

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytest.importorskip("pydantic")
from typer._click import Context  # noqa: E402
from typer._click.exceptions import BadParameter  # noqa: E402
from typer._coercion import build_runtime_param  # noqa: E402
from typer._param_types import coerce_cli_choice, coerce_cli_path  # noqa: E402
from typer.main import get_command  # noqa: E402

from lolacli.cli.coerce import _converter, install  # noqa: E402
from lolacli.cli.main import app  # noqa: E402

NUMBERS = ["5", " 5 ", "5.0", "5.5", "1e3", "0x10", "1_000", "+5", "-0", "inf", "nan", "", "0.0005"]
WORDS = ["abc", " a b ", "", "0x10", "ünï", "--x"]
TRUTH = ["true", "False", "1", "0", "yes", "NO", "on", "off", "t", "maybe", "", " y "]


def _params():
    root = get_command(app)
    todo = [(root, root.name or "lolacli")]
    while todo:
        cmd, path = todo.pop()
        for sub_name, sub in getattr(cmd, "commands", {}).items():
            todo.append((sub, f"{path} {sub_name}"))
        for p in cmd.params:
            if hasattr(p, "type_descriptor"):
                yield cmd, path, p


def _inputs(annotation: Any, tmp: Path) -> list[Any]:
    if get_origin(annotation) is list:
        (item,) = get_args(annotation)
        return [[v] for v in _inputs(item, tmp)[:4]] + [_inputs(item, tmp)[:2]]
    if annotation is str:
        return WORDS
    if annotation in (int, float):
        return NUMBERS
    if annotation is bool:
        return TRUTH
    if isinstance(annotation, type) and issubclass(annotation, Enum):
        return [e.value for e in annotation] + [str(e.value).upper() for e in annotation] + ["?"]
    if isinstance(annotation, type) and issubclass(annotation, Path):
        (tmp / "file.txt").write_text("x")
        return [str(tmp / "file.txt"), str(tmp), str(tmp / "nosuch" / "x"), "-", ""]
    return []


def _outcome(fn, value, param, ctx):
    try:
        got = fn(value, param, ctx)
    except BadParameter as exc:
        return ("error", exc.message)
    if isinstance(got, float) and math.isnan(got):
        return ("nan",)
    return ("value", got)


def test_every_parameter_converts_as_typer_does(tmp_path) -> None:
    helpers = (coerce_cli_choice, coerce_cli_path)
    checked = 0
    for cmd, path, param in _params():
        descriptor = param.type_descriptor
        ours = _converter(descriptor, helpers)
        if ours is None:
            continue
        theirs = build_runtime_param(descriptor)
        ctx = Context(cmd)
        for value in _inputs(descriptor.annotation, tmp_path):
            mine = _outcome(ours, value, param, ctx)
            typer_s = _outcome(theirs._coerce_value, value, param, ctx)
            assert mine == typer_s, (path, param.name, value)
            checked += 1
    assert checked > 300


def test_parameters_left_to_typer_are_the_unusual_ones() -> None:
    helpers = (coerce_cli_choice, coerce_cli_path)
    left = [
        (path, p.name, p.type_descriptor.annotation)
        for _cmd, path, p in _params()
        if _converter(p.type_descriptor, helpers) is None
    ]
    assert left == [], left


def test_install_is_idempotent() -> None:
    assert install() and install()


def test_a_short_command_does_not_import_pydantic() -> None:
    code = (
        "import sys; sys.argv = ['lolacli', 'sdo', 'read', '5', '0x1000', '--timeout', '2']\n"
        "import lolacli.cli.main as m\n"
        "try:\n    m.main()\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
        "assert 'pydantic' not in sys.modules, 'pydantic imported'\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "5 0x1000:00  Device type  UNSIGNED32 = 131474 (0x00020192)\n"
