"""What ``xr.ml`` loads: training data reads finished builds through the dataset layouts alone, so
``xr.ml.PatchDataset`` loads neither the renderer nor the build (the import contract "Training data
reads builds without the renderer" in pyproject.toml says which modules; this checks what a fresh
interpreter actually holds, which the contract cannot see: lazy names, eager package imports)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("moderngl", "pyopencl", "trimesh", "manifold3d")  # OpenGL, OpenCL and meshing: the renderer's
# Before the dataset layer, `xr.ml.PatchDataset` loaded ~94 of the package's modules (the whole
# renderer); reading builds needs 32 (core, io, the layouts: a module each and their shared parts,
# ml). Well below the first, a little above the second, so a new eager import of a stage fails here.
MAX_MODULES = 34


def test_patch_dataset_loads_no_renderer():
    code = ("import sys, json, xrayraster; xrayraster.ml.PatchDataset; "
            "print(json.dumps(sorted(m for m in sys.modules if m == 'xrayraster' or m.startswith('xrayraster.') "
            f"or m.split('.')[0] in {HEAVY!r})))")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    loaded = json.loads(run.stdout)
    ours = [m for m in loaded if m.split(".")[0] == "xrayraster"]
    assert [m for m in loaded if m.split(".")[0] in HEAVY] == []
    assert len(ours) < MAX_MODULES, ours
    assert not [m for m in ours if m.split(".")[1:2] in (["pipeline"], ["gl"], ["recon"], ["simulate"])], ours
