"""Issue 37 (3): one place for up-front estimates. Every stage's job implements core.estimate's
``Planned`` protocol and goes through its one gate, ``plan``; no module outside core/estimate.py
refuses or announces an estimate by hand; and the gate refuses, with the caller's error class and
naming the key, a job larger than the machine's memory."""

from __future__ import annotations

import ast
import os
from dataclasses import dataclass
from pathlib import Path

import pytest

from xrayraster.core.errors import ConfigError, RenderError
from xrayraster.core.estimate import Estimate, Part, Planned, plan
from xrayraster.io.scan_file import load_scan_file
from xrayraster.io.scene_file import load_scene_file
from xrayraster.physics.spectrum import SpectrumJob
from xrayraster.pipeline.plan import FrameJob, ScanJob
from xrayraster.simulate.estimate import RenderJob
from xrayraster.weave.size import BendSearch, Size, WeaveJob

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "xrayraster"
GATE = PACKAGE / "core" / "estimate.py"


def _modules():
    """(path, dotted module name, parsed source) of every module of the package."""
    for path in sorted(PACKAGE.rglob("*.py")):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        yield path, name, ast.parse(path.read_text(encoding="utf-8"), str(path))


def _job_classes() -> set[str]:
    """Every class of the package that defines ``estimate`` (the protocol itself left out)."""
    return {f"{name}.{node.name}" for path, name, tree in _modules() if path != GATE for node in tree.body
            if isinstance(node, ast.ClassDef)
            and any(isinstance(f, ast.FunctionDef) and f.name == "estimate" for f in node.body)}


def _jobs() -> dict[str, object]:
    """One small instance of every job class, by its dotted name."""
    scan = load_scan_file(ROOT / "examples" / "scan_small.toml")
    size = Size.planned({}, {})
    jobs = [RenderJob(10, (8, 8), 100), ScanJob(scan, 32), FrameJob(scan),
            FrameJob(load_scene_file(ROOT / "examples" / "bracket_ct.toml")), WeaveJob(size), BendSearch(size),
            SpectrumJob(40.0, 0.5)]
    return {f"{type(job).__module__}.{type(job).__qualname__}": job for job in jobs}


def test_every_job_class_of_the_package_is_planned():
    """Each class with an ``estimate`` is a ``Planned`` whose estimate is an Estimate of positive
    time and memory; a new job class without an instance here fails, so it is checked too."""
    jobs = _jobs()
    assert set(jobs) == _job_classes()
    for name, job in jobs.items():
        assert isinstance(job, Planned), name
        estimate = job.estimate()
        assert isinstance(estimate, Estimate) and estimate.seconds > 0 and estimate.bytes > 0, name
        assert all(isinstance(part, Part) for part in estimate.parts), name


def _hand_made(tree: ast.AST) -> list[int]:
    """Lines of ``tree`` that refuse or announce an estimate by hand: any ``.announce(...)``, and a
    ``.check(...)`` on an estimate (an expression naming one, ``x.estimate()``, ``Estimate(...)``,
    ``render_estimate(...)``, or a name bound to such an expression)."""
    estimates = {target.id for node in ast.walk(tree) if isinstance(node, (ast.Assign, ast.AnnAssign))
                 and node.value is not None and "estimate" in ast.unparse(node.value).lower()
                 for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
                 if isinstance(target, ast.Name)}
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            receiver = node.func.value
            on_estimate = "estimate" in ast.unparse(receiver).lower() or (
                isinstance(receiver, ast.Name) and receiver.id in estimates)
            if node.func.attr == "announce" or (node.func.attr == "check" and on_estimate):
                lines.append(node.lineno)
    return lines


@pytest.mark.parametrize("source, found", [
    ("render_estimate(1, (1, 1), 1).check(RenderError)", True),
    ("Estimate('job', 1.0, ()).check(ConfigError, where)", True),
    ("RenderJob(1, (1, 1), 1).estimate().check(RenderError)", True),
    ("e = job.estimate()\ne.check(ConfigError)", True),
    ("estimate = plan(job, ConfigError)\nestimate.announce()", True),
    ("plan(job, ConfigError, where, announce=True)", False),
    ("self.distortion.check(self.cell)\nsection.check('name')", False),
])
def test_the_search_for_hand_made_calls_finds_them(source, found):
    assert bool(_hand_made(ast.parse(source))) is found


def test_no_module_refuses_or_announces_an_estimate_by_hand():
    """Outside core/estimate.py every stage goes through the gate, ``plan``."""
    found = [f"{path.relative_to(ROOT)}:{line}" for path, _, tree in _modules() if path != GATE
             for line in _hand_made(tree)]
    assert not found, "estimates checked or announced by hand, not through core.estimate.plan:\n" + "\n".join(found)


@dataclass(frozen=True)
class _Buffer:
    """A job of one part of ``nbytes`` bytes taking ``seconds``."""

    nbytes: int
    seconds: float = 1.0

    def estimate(self) -> Estimate:
        return Estimate("test job", self.seconds, (Part("buffer", self.nbytes, "[t] size = 1", "use a smaller size"),))


def test_the_gate_refuses_more_than_the_machine_has_naming_the_key():
    """2⁶² bytes (4 EiB) is more than this machine's physical memory, so the gate refuses it, with
    the caller's error class and where, naming the key and its fix; a byte passes."""
    huge = 1 << 62
    assert huge > os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    for error in (ConfigError, RenderError):
        with pytest.raises(error, match=r"^f\.toml \[t\] size = 1: the test job \(buffer\) needs 4294967296\.00 GiB, "
                                        r"more than half the .* available; use a smaller size$"):
            plan(_Buffer(huge), error, "f.toml ")
    assert plan(_Buffer(1), ConfigError, "f.toml ") == _Buffer(1).estimate()


def test_the_gate_prints_a_long_job_only_when_asked(capsys):
    plan(_Buffer(1, seconds=7300.0), ConfigError)
    assert capsys.readouterr().err == ""
    plan(_Buffer(1, seconds=7300.0), ConfigError, announce=True)
    assert capsys.readouterr().err.startswith("estimate: test job: about 2 h and 0.0 MiB of memory (buffer)")
    plan(_Buffer(1, seconds=10.0), ConfigError, announce=True)  # short: nothing to say
    assert capsys.readouterr().err == ""
