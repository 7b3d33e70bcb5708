"""README.md's CT chain, run as written: render → reconstruct → voxelize from the shipped files.

The commands are taken from the README block marked ``<!-- run: chain -->`` and run by the
shell in a temporary folder where ``examples/`` is the repository's. The reconstruction is then
checked against the materials' attenuation at the source's 60 keV, from xraylib directly
(μ/ρ × ρ), inside each object (two voxels in from its surface, by the label volume).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile
import xraylib

ROOT = Path(__file__).resolve().parents[2]
BLOCK = re.compile(r"<!-- run: chain -->\s*```bash\n(.*?)```", re.DOTALL)
MU_PER_CM = {  # 60 keV: CS_Total (cm²/g) × density (g/cm³), the example's materials
    1: xraylib.CS_Total(13, 60.0) * 2.699,  # the bracket: aluminium
    2: (0.98 * xraylib.CS_Total(26, 60.0) + 0.02 * xraylib.CS_Total(6, 60.0)) * 7.85,  # the ball: steel
}


def erode(mask: np.ndarray, steps: int) -> np.ndarray:
    """Voxels whose 6-neighbourhood stays in ``mask`` for ``steps`` steps (grid edges count as out)."""
    for _ in range(steps):
        padded = np.pad(mask, 1)
        inner = padded[1:-1, 1:-1, 1:-1].copy()
        for axis in range(3):
            for shift in (-1, 1):
                inner &= np.roll(padded, shift, axis)[1:-1, 1:-1, 1:-1]
        mask = inner
    return mask


def chain(doc: str) -> list[str]:
    return [line for line in BLOCK.search((ROOT / doc).read_text()).group(1).splitlines() if line.strip()]


def test_the_reconstruction_docs_show_the_same_chain():
    """docs/reconstruction.md's commands are the README's first two, so running these runs those."""
    assert chain("docs/reconstruction.md") == chain("README.md")[:2]


@pytest.mark.slow
def test_readme_chain_runs_as_written_and_recovers_mu(tmp_path, gl, cl):
    commands = chain("README.md")
    assert [c.split()[1] for c in commands] == ["render", "reconstruct", "voxelize"]
    (tmp_path / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    # The environment's xrayraster script first on PATH, importing this checkout.
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}", "PYTHONPATH": str(ROOT)}
    for command in commands:
        run = subprocess.run(command, shell=True, cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env)
        assert run.returncode == 0, f"{command}\n{run.stderr}"
    out = tmp_path / "out" / "ct"
    for name in ("projections", "volume", "labels"):
        assert (out / f"{name}.tif").stat().st_size > 0 and (out / f"{name}.png").stat().st_size > 0
    volume, labels = tifffile.imread(out / "volume.tif"), tifffile.imread(out / "labels.tif")
    assert volume.shape == labels.shape == (120, 136, 136)
    for label, mu in MU_PER_CM.items():
        inside = erode(labels == label, 2)
        assert inside.sum() > 20_000
        mean = float(volume[inside].mean())
        print(f"label {label}: mean {mean:.4f} /cm over {inside.sum()} voxels, xraylib {mu:.4f} /cm")
        assert abs(mean / mu - 1) < 0.05
