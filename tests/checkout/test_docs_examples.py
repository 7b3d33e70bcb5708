"""The documentation's examples work: every ```python block of README.md and docs/*.md runs, every
```toml block loads through the scene loader (a scan file's, one with a table only scan files
have, through the scan-file loader) and renders, every ```json block loads as a grid
file, and the README's commands are the ones CI runs.

Python blocks run one by one in a fresh namespace, with the working directory a temporary folder
in which ``examples/`` points at the repository's examples. A block that uses the renderer needs
OpenGL: it takes the ``gl`` fixture, so it skips with the reason when there is none, unless
XRAYRASTER_REQUIRE_GL=1. A toml block preceded by ``<!-- expect-error: REGEX -->`` must fail to
load with a message matching REGEX; every other toml block must load and render.
"""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
EXPECT_ERROR = re.compile(r"<!--\s*expect-error:\s*(.*?)\s*-->\s*$")
SCANS = r"|\bxr\.(build|scan)\("  # a whole scan: GL for the projections and labels, OpenCL for FDK
NEEDS_GL = re.compile(r"\b(Renderer|GLContext)\b" + SCANS)
NEEDS_CL = re.compile(r"\b(fdk|CLContext)\b" + SCANS)


def _blocks(lang: str) -> list:
    found = []
    for doc in DOCS:
        text = doc.read_text()
        for m in FENCE.finditer(text):
            if m.group(1) != lang:
                continue
            line = text.count("\n", 0, m.start(2)) + 1  # first line of the block's body
            before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1]
            expect = EXPECT_ERROR.search(before)
            found.append((doc, line, m.group(2), expect.group(1) if expect else None))
    return found


def _params(blocks):
    return [pytest.param(*b, id=f"{b[0].relative_to(ROOT)}:{b[1]}") for b in blocks]


PYTHON = _blocks("python")
JSON = _blocks("json")
TOML = _blocks("toml")
SCENES = [b for b in TOML if b[3] is None]


def test_the_docs_have_examples():
    """Guards against a parser or layout change that silently finds nothing to test."""
    assert (ROOT / "README.md").exists() and (ROOT / "docs" / "scene-format.md").exists()
    assert any(doc.name == "README.md" for doc, *_ in PYTHON)
    assert {doc.name for doc, *_ in PYTHON} >= {"README.md", "geometry.md", "scene-format.md", "reconstruction.md"}
    assert JSON
    assert len(SCENES) >= 3 and len(TOML) > len(SCENES)


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    (tmp_path / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize("doc, line, code, expect", _params(PYTHON))
def test_python_block_runs(doc, line, code, expect, workdir, request):
    """Each example runs and checks its own result: a block without an assert shows, not proves."""
    assert re.search(r"^\s*assert ", code, re.MULTILINE), f"{doc.name}:{line}: the example asserts nothing"
    if NEEDS_GL.search(code):
        request.getfixturevalue("gl")  # skip (or fail under XRAYRASTER_REQUIRE_GL=1) without OpenGL
    if NEEDS_CL.search(code):
        request.getfixturevalue("cl")  # likewise without OpenCL (XRAYRASTER_REQUIRE_OPENCL=1)
    # Pad so that a traceback's line numbers are the markdown file's.
    compiled = compile("\n" * (line - 1) + code, str(doc), "exec")
    exec(compiled, {"__name__": "__doc_example__"})


@pytest.mark.parametrize("doc, line, text, expect", _params(JSON))
def test_json_grid_file_loads(doc, line, text, expect, tmp_path):
    from xrayraster.io.grid_file import read_grid_file

    path = tmp_path / "grid.json"
    path.write_text(text)
    geometry, volume = read_grid_file(path)
    assert geometry is not None and geometry.num_views >= 1 and all(n >= 1 for n in volume.shape)


# Tables a scan file has and a scene file has not (docs/scan.md).
SCAN_TABLES = {"weave", "mount", "volume", "scan", "pose"}


def _loader(text: str):
    """The scan-file loader for a block with a scan file's table, else the scene loader."""
    from xrayraster.io.scene_file import load_scene_file
    from xrayraster.pipeline import load_scan_file

    try:
        tables = set(tomllib.loads(text))
    except tomllib.TOMLDecodeError:
        tables = set()  # a block showing a syntax error: the scene loader reports it
    return load_scan_file if tables & SCAN_TABLES else load_scene_file


def _scene(loaded):
    """What a loaded scene or scan file scans."""
    return loaded.with_mount(loaded.sample_scene()) if hasattr(loaded, "sample_scene") else loaded.scene


def _write_scene(tmp_path: Path, text: str) -> Path:
    """The block as a file beside a ``meshes/`` link, so its relative mesh paths resolve as in examples/."""
    (tmp_path / "meshes").symlink_to(ROOT / "examples" / "meshes", target_is_directory=True)
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("doc, line, text, expect", _params(TOML))
def test_toml_block_loads(doc, line, text, expect, tmp_path):
    path = _write_scene(tmp_path, text)
    load = _loader(text)
    if expect is not None:
        with pytest.raises(ValueError, match=expect):
            load(path)
        return
    loaded = load(path)
    assert len(_scene(loaded)) >= 1 and loaded.geometry.num_views >= 1


@pytest.mark.parametrize("doc, line, text, expect", _params(SCENES))
def test_toml_scene_renders_every_material(doc, line, text, expect, tmp_path, gl):
    """A documented scene that loads but shows nothing (object behind the source, off the detector) is broken too."""
    from xrayraster import Renderer

    loaded = _loader(text)(_write_scene(tmp_path, text))
    scene = _scene(loaded)
    with Renderer(loaded.geometry, context=gl) as renderer:
        lengths = renderer.path_lengths(scene, 0)
    assert lengths.shape == (len(scene.materials), *loaded.geometry.detector_shape)
    assert np.all(np.isfinite(lengths))
    visible = lengths.max(axis=(1, 2)) > 0
    assert visible.all(), f"materials not in view 0: {[m for m, v in zip(scene.materials, visible) if not v]}"


def test_bundled_examples_are_quoted_verbatim_in_the_format_reference():
    """Scene files in docs/scene-format.md (loaded there as toml blocks); weave files in docs/weave.md,
    woven scan files (a [weave] and a [source]) in docs/scan.md or, the twin's, docs/twin.md, and
    dataset files (a [dataset]) in docs/dataset.md (the training experiment's, ml_*, in docs/ml.md),
    as text blocks."""
    quoted = {text.strip() for doc, _, text, _ in TOML if doc.name == "scene-format.md"}
    examples = sorted((ROOT / "examples").glob("*.toml"))
    assert examples
    for example in examples:
        text = example.read_text().strip()
        data = tomllib.loads(text)
        if "dataset" in data:  # the training experiment's in docs/ml.md
            doc = "ml.md" if example.name.startswith("ml_") else "dataset.md"
            assert f"```text\n{text}\n```" in (ROOT / "docs" / doc).read_text(), \
                f"{example.name} differs from its copy in docs/{doc}"
        elif "weave" in data:
            docs = ("scan.md", "twin.md") if "source" in data else ("weave.md",)
            assert any(f"```text\n{text}\n```" in (ROOT / "docs" / doc).read_text() for doc in docs), \
                f"{example.name} differs from its copy in docs/{' or docs/'.join(docs)}"
        else:
            assert text in quoted, f"{example.name} differs from its copy in docs/scene-format.md"


def _readme_commands() -> list[str]:
    first = FENCE.search((ROOT / "README.md").read_text())
    return [line for line in first.group(2).splitlines() if line.strip()]


def test_readme_starts_with_the_two_commands():
    text = (ROOT / "README.md").read_text()
    assert text.startswith("```"), "README.md must open with the commands block"
    assert _readme_commands() == [
        'pip install ".[test]" && xrayraster scan examples/twin_small.toml -o out/scan',
        "pytest",
    ]


def test_ci_runs_the_readme_commands_verbatim_first_in_a_fresh_environment():
    """.ci/run makes a virtual environment, runs the README's two lines exactly and before anything
    else is installed (what a new user gets is what passes), with no GL, OpenCL or page test allowed
    to skip; then the ml extra (the CPU build of torch, pinned) and its tests, required."""
    ci = ROOT / ".ci" / "run"
    assert os.access(ci, os.X_OK), ".ci/run must be executable"
    code = [line.strip() for line in ci.read_text().splitlines() if line.strip() and not line.lstrip().startswith("#")]
    install, test = _readme_commands()
    at = {name: next((i for i, line in enumerate(code) if predicate(line)), None) for name, predicate in {
        "venv": lambda line: line.startswith("python -m venv"),
        "activate": lambda line: line.startswith("source") and "/bin/activate" in line,
        "install": lambda line: line.startswith(install),
        "test": lambda line: line == test or line.startswith(f"{test} ||"),
        "require": lambda line: line.startswith("export XRAYRASTER_REQUIRE_GL=1")
        and "XRAYRASTER_REQUIRE_OSMESA=1" in line and "XRAYRASTER_REQUIRE_OPENCL=1" in line,
        "browser": lambda line: line.startswith("export XRAYRASTER_REQUIRE_BROWSER=1"),
        "ml": lambda line: line.startswith('pip install "torch==2.13.0+cpu" ".[ml]"'),
        "torch": lambda line: line.startswith("export XRAYRASTER_REQUIRE_TORCH=1"),
        "ml tests": lambda line: line.startswith("python -m pytest -m needs_torch"),
    }.items()}
    assert None not in at.values(), f".ci/run lacks {[name for name, i in at.items() if i is None]}"
    installs = [i for i, line in enumerate(code) if line.startswith("pip install")]
    assert installs[0] == at["install"], "the README's install line must be .ci/run's first pip install"
    assert at["venv"] < at["activate"] < at["install"] < at["test"] < at["ml"] < at["torch"] < at["ml tests"]
    assert max(at["require"], at["browser"]) < at["test"]


LINK = re.compile(r"\]\(([^)\s]+)\)")


@pytest.mark.parametrize("doc", DOCS, ids=lambda d: str(d.relative_to(ROOT)))
def test_every_local_link_and_picture_exists(doc):
    """Links and pictures to files of the repository point at files that are there (outside code blocks)."""
    text = FENCE.sub("", doc.read_text())
    targets = [t.split("#", 1)[0] for t in LINK.findall(text) if not re.match(r"[a-z]+:|#", t)]
    missing = [t for t in targets if t and not (doc.parent / t).exists()]
    assert not missing, f"{doc.relative_to(ROOT)} links to missing files: {missing}"
