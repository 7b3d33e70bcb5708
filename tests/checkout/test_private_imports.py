"""No module of the package imports a private name (a leading underscore) from another.

A name with a leading underscore is its module's own business: when a second module
needs it, it is shared, and gets a public name (and a docstring) in its home module.
Dunder names such as ``__version__`` are public by convention and allowed.
"""

from __future__ import annotations

import ast
from pathlib import Path

import xrayraster

PACKAGE_DIR = Path(xrayraster.__file__).resolve().parent
PACKAGE = PACKAGE_DIR.name


def _module_name(path: Path) -> tuple[str, bool]:
    """The dotted name of the module at `path`, and whether it is a package's ``__init__``."""
    parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts)
    is_package = parts[-1] == "__init__"
    if is_package:
        parts = parts[:-1]
    return ".".join(parts), is_package


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute module that `node` imports from, as written in `module`."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]  # a plain module's relative imports start from its package
    if node.level > 1:
        base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _offenders() -> list[str]:
    found = []
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        module, is_package = _module_name(path)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = _resolve(module, is_package, node)
                if source != PACKAGE and not source.startswith(PACKAGE + "."):
                    continue
                if source == module:
                    continue
                for alias in node.names:
                    if _is_private(alias.name):
                        found.append(f"{module} imports {alias.name} from {source}")
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    name = alias.name
                    if (name == PACKAGE or name.startswith(PACKAGE + ".")) and any(
                        _is_private(part) for part in name.split(".")
                    ):
                        found.append(f"{module} imports private module {name}")
    return found


def test_resolves_relative_imports():
    def resolve(module, is_package, source):
        return _resolve(module, is_package, ast.parse(source).body[0])

    assert resolve("xrayraster.dataset.dataset_file", False, "from ..io.scene_file import x") == "xrayraster.io.scene_file"
    assert resolve("xrayraster.ml.predict", False, "from .patches import x") == "xrayraster.ml.patches"
    assert resolve("xrayraster.ml", True, "from .patches import x") == "xrayraster.ml.patches"
    assert resolve("xrayraster.ml", True, "from . import patches") == "xrayraster.ml"
    assert resolve("xrayraster.ml.predict", False, "from xrayraster.io import x") == "xrayraster.io"


def test_no_private_name_imported_across_modules():
    offenders = _offenders()
    assert not offenders, "private names imported across modules:\n" + "\n".join(offenders)
