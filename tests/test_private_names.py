"""No module of lolacli uses another module's private names.

ruff enforces the attribute side for lolacli/ (SLF001: ``other._name``; PLC2701: a private
name imported from another package). What ruff lets pass is a private name imported from
another module of lolacli itself (``from lolacli.emulator.plan import _Brd``): this test
looks for those.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "lolacli"


def _module_of(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _private(name: str) -> bool:
    return name.startswith("_") and not name.endswith("__")


def _foreign_private_module(source: str, here: str) -> bool:
    """Whether ``source`` passes through a private module (``lolacli.wire._codes``) that
    ``here`` is not in the package of (its siblings may use it)."""
    parts = source.split(".")
    for i, part in enumerate(parts):
        if _private(part) and not here.startswith(".".join(parts[:i]) + "."):
            return True
    return False


def private_imports(source_text: str, here: str, is_package: bool = False) -> list[str]:
    """``module:line name`` for every private name module ``here`` (its text) imports
    from another module of lolacli (absolute or relative; ``import lolacli.x._y`` too)."""
    package = here if is_package else here.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source_text, here)):
        if isinstance(node, ast.ImportFrom):
            source = node.module or ""
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                source = ".".join([*base, *([source] if source else [])])
            if not source.startswith("lolacli"):
                continue
            for alias in node.names:
                if source != here and (
                    _private(alias.name) or _foreign_private_module(source, here)
                ):
                    found.append(f"{here}:{node.lineno} {alias.name} from {source}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("lolacli.") and _foreign_private_module(alias.name, here):
                    found.append(f"{here}:{node.lineno} {alias.name}")
    return found


def test_no_module_imports_another_modules_private_names() -> None:
    found = [
        hit
        for path in sorted(PACKAGE.rglob("*.py"))
        for hit in private_imports(path.read_text(), _module_of(path), path.name == "__init__.py")
    ]
    assert found == []


def test_the_check_sees_a_private_import() -> None:
    """The check is not blind: a private name from another module, absolute or relative,
    and a private module of another package are found; the module's own names, a public
    one under a private alias and a private module of its own package are not."""
    source = (
        "from lolacli.emulator.plan import _Brd\n"
        "from .plan import _Logical\n"
        "from .probe import _mine\n"
        "from lolacli.wire.registers import Register as _R\n"
        "import lolacli.emulator._ccore\n"
        "from lolacli.capture._cscan import scan\n"
    )
    hits = [h.split(" ", 1)[1] for h in private_imports(source, "lolacli.emulator.probe")]
    assert hits == [
        "_Brd from lolacli.emulator.plan",
        "_Logical from lolacli.emulator.plan",
        "scan from lolacli.capture._cscan",
    ]
