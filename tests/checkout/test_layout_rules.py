"""The checkout's one-way rules that import-linter (which checks the package) does not see: tests
never import the benchmarks (scripts/), and the references (references/), which tests and
benchmarks share, import neither. What a test needs from a benchmark lives in references/ (or in
the package); a test of a benchmark script runs it as a child process (``python -m scripts.X``)."""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def forbidden_imports(folder: Path, top_levels: set[str]) -> list[str]:
    """``path:line: module`` for every import (``import`` or ``from ... import``, at any depth, also
    ``importlib.import_module("...")`` and ``__import__("...")`` with a literal name) in the Python
    files under ``folder`` whose top-level module is one of ``top_levels``."""
    found = []
    for path in sorted(folder.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                modules = [node.module or ""] if node.level == 0 else []
            elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
                  and isinstance(node.args[0].value, str)
                  and ((isinstance(node.func, ast.Attribute) and node.func.attr == "import_module")
                       or (isinstance(node.func, ast.Name) and node.func.id in ("import_module", "__import__")))):
                modules = [node.args[0].value]
            else:
                continue
            found += [f"{path.relative_to(folder.parent)}:{node.lineno}: {m}" for m in modules
                      if m.split(".")[0] in top_levels]
    return found


def test_no_test_imports_a_benchmark_script():
    found = forbidden_imports(ROOT / "tests", {"scripts"})
    assert not found, ("tests import scripts/ (move what they need into references/ or the package, or run the "
                       "script as a child process):\n" + "\n".join(found))


def test_references_import_no_benchmark_or_test():
    found = forbidden_imports(ROOT / "references", {"scripts", "tests"})
    assert not found, "references/ imports scripts/ or tests/:\n" + "\n".join(found)


def test_the_check_sees_every_form_of_import(tmp_path):
    (tmp_path / "a.py").write_text("import scripts\nimport scripts.common as c\nfrom scripts import bench_weave\n"
                                   "def f():\n    from scripts.peers.x import y\n"
                                   "import importlib\nimportlib.import_module('scripts.profile_scan')\n"
                                   "__import__('scripts')\n")
    (tmp_path / "b.py").write_text("import scriptsy\nfrom . import scripts\nfrom references import browser\n"
                                   "import subprocess\nsubprocess.run(['python', '-m', 'scripts.bench_weave'])\n")
    found = forbidden_imports(tmp_path, {"scripts"})
    assert [line.split(": ")[0] for line in found] == [f"{tmp_path.name}/a.py:{n}" for n in (1, 2, 3, 5, 7, 8)]


# Where tests live: a folder each for the package's subpackages, and for the checkout's other parts.
OTHER_FOLDERS = {"checkout", "references", "scripts"}  # the repository's rules; references/; benchmark scripts


def test_tests_mirror_the_package():
    subpackages = {p.parent.name for p in (ROOT / "xrayraster").glob("*/__init__.py")}
    folders = {p.parent.relative_to(ROOT / "tests") for p in (ROOT / "tests").rglob("test_*.py")}
    assert not [p.name for p in (ROOT / "tests").glob("test_*.py")], "a test file directly in tests/: move it"
    assert {str(f) for f in folders} <= subpackages | OTHER_FOLDERS, folders
    assert subpackages <= {str(f) for f in folders}, "a subpackage without a test folder"
    names = [p.name for p in (ROOT / "tests").rglob("test_*.py")]
    assert len(names) == len(set(names)), "two test files of one name (pytest imports them by name)"


def test_no_test_imports_another_test_module():
    found = []
    for path in sorted((ROOT / "tests").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        found += [f"{path.relative_to(ROOT)}:{node.lineno}" for node in ast.walk(tree)
                  if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("test_")]
    assert not found, "a test imports another test module; move what both need into a helper in tests/:\n" + \
        "\n".join(found)


def test_every_checkout_path_that_ci_and_the_docs_name_exists():
    """Paths into tests/, scripts/, examples/, references/ and docs/ named by .ci/run, the README,
    docs/, pyproject.toml and the GPU check (scripts/gpu_check.sh) exist (a glob must match something)."""
    pattern = re.compile(r"(?<![\w/.-])((?:tests|scripts|examples|references|docs)/[\w*./-]*[\w*])")
    sources = [ROOT / ".ci" / "run", ROOT / "README.md", ROOT / "BENCHMARKS.md", ROOT / "pyproject.toml",
               ROOT / "scripts" / "gpu_check.sh",
               *sorted((ROOT / "docs").glob("*.md"))]
    missing, named = [], 0
    for source in sources:
        for n, line in enumerate(source.read_text(encoding="utf-8").splitlines(), 1):
            for path in pattern.findall(line):
                path, named = path.rstrip("."), named + 1
                if not any(ROOT.glob(path)):
                    missing.append(f"{source.relative_to(ROOT)}:{n}: {path}")
    assert named > 100 and not missing, "named paths that do not exist:\n" + "\n".join(missing)


def test_the_layer_table_of_the_docs_is_the_contract():
    """docs/architecture.md's layer table and the layers contract of pyproject.toml name the same
    layers in the same order, so neither is changed without the other."""
    contract = next(c for c in tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
                    if c["type"] == "layers")
    layers = [{name.strip() for name in layer.split("|")} for layer in contract["layers"]]
    rows = re.findall(r"^\| (\d+) \| (.+?) \|", (ROOT / "docs" / "architecture.md").read_text(), re.M)
    table = [set(re.findall(r"`(\w+)`", cell)) for _, cell in sorted(rows, key=lambda r: -int(r[0]))]
    assert table == layers
