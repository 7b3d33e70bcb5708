"""pyproject.toml ships what the package needs at run time (a wheel that lacks a shader fails only
on a user's machine, never in a source checkout)."""

from __future__ import annotations

import tomllib
from fnmatch import fnmatch
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_every_shader_file_is_package_data():
    setuptools = PYPROJECT["tool"]["setuptools"]
    assert setuptools["package-dir"]["xrayraster.shaders"] == "shaders"
    patterns = setuptools["package-data"]["xrayraster.shaders"]
    shaders = [p for p in (ROOT / "shaders").iterdir() if p.is_file() and p.suffix not in (".py", ".pyc")]
    assert shaders
    missed = [p.name for p in shaders if not any(fnmatch(p.name, pattern) for pattern in patterns)]
    assert not missed, f"shaders/ files that the wheel would not ship: {missed}; add their pattern to package-data"


def test_console_script_and_readme():
    assert PYPROJECT["project"]["scripts"]["xrayraster"] == "xrayraster.cli:run"
    assert (ROOT / PYPROJECT["project"]["readme"]).is_file()


def test_every_subpackage_is_shipped():
    """A stage subpackage missing from the list installs a package that fails on import."""
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "xrayraster").rglob("__init__.py")}
    assert found <= listed, f"subpackages the wheel would lack: {sorted(found - listed)}; add them to packages"
    assert "xrayraster.shaders" in listed
