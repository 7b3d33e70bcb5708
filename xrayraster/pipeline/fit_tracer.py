"""Tracer yarns found in a real reconstruction: a step of :func:`~xrayraster.pipeline.fit.fit` for a
woven sample whose scan file names no tracer (docs/fit.md, "The weave and its tracers").

Real samples carry a few tracer yarns, typically of glass fibre, several times as bright as carbon.
Voxels of the real volume (smoothed as for the classes, :mod:`~xrayraster.pipeline.fit_weave`) above
the yarns' peak by :data:`CONTRAST` times the step from the matrix's peak to the yarns', in bodies of
:data:`MIN_VOXELS` or more, are a tracer's. A yarn of the fitted cell with :data:`MIN_SHARE` of its
voxels among them is a tracer: it is given e-glass fibres in the matrix (:data:`FIBRE`; a scan shows
only the attenuation, and any material of that μ at this spectrum looks alike), and its fibre fraction
is then fitted with the densities, to the median μ of the bright voxels a voxel or more inside their
body (its ``peak``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..core.volume import VolumeGeometry
from ..gl.voxelize import voxelize
from ..io.scan_file import ScanFile
from ..scene.scene import Scene
from ..weave.materials import FibreBundle, Tracer
from .fit_figures import core
from .fit_weave import MATRIX, YARN

#: How far above the yarns' peak a tracer's voxels lie, in steps from the matrix's peak to the yarns'.
CONTRAST = 2.0
#: Voxels a bright body needs to be a tracer's (smaller ones: streaks, noise, a speck).
MIN_VOXELS = 100
#: The share of a yarn's voxels that must be bright for it to be a tracer.
MIN_SHARE = 0.25
#: A found tracer's fibre: its fraction is fitted, starting at :data:`START_FRACTION`.
FIBRE, START_FRACTION = "e_glass", 0.6


@dataclass(frozen=True)
class FoundTracer:
    """A tracer yarn: its ``yarn`` name, the ``share`` of its voxels the real volume shows bright, and
    the voxels its peak is taken over in the ``real`` volume and in a ``simulated`` one (bool, z, y, x)."""

    yarn: str
    share: float
    real: np.ndarray = dataclasses.field(repr=False)
    simulated: np.ndarray = dataclasses.field(repr=False)


def find_tracers(smoothed: np.ndarray, means: dict[int, float], use: np.ndarray, sample: Scene,
                 volume: VolumeGeometry, gl) -> list[FoundTracer]:
    """The tracer yarns of a woven ``sample`` (a scan's sample scene, on the grid ``volume``) in the
    real volume ``smoothed`` (cm⁻¹, smoothed) whose classes' peaks are ``means`` (class → μ), over
    the voxels of ``use`` (module docstring)."""
    step = means[YARN] - means[MATRIX]
    if step <= 0:
        return []
    bright = (smoothed > means[YARN] + CONTRAST * step) & use
    bodies, count = ndimage.label(bright)
    if not count:
        return []
    sizes = np.bincount(bodies.ravel())
    bright = (sizes >= MIN_VOXELS)[bodies] & bright
    if not bright.any():
        return []
    objects = sample.objects
    yarns = Scene()  # each object its own label: which yarn a voxel is in
    for i, o in enumerate(objects):
        yarns.add(o.mesh, o.material, label=i + 1, priority=o.priority, name=o.name)
    owner = voxelize(yarns, volume, context=gl).data
    total = np.bincount(owner.ravel(), minlength=len(objects) + 1)
    hits = np.bincount(owner[bright], minlength=len(objects) + 1)
    found = []
    for i, o in enumerate(objects):
        share = hits[i + 1] / max(total[i + 1], 1)
        if o.name != "matrix" and not o.name.startswith("void") and share >= MIN_SHARE:
            touched = np.isin(bodies, np.unique(bodies[bright & (owner == i + 1)])) & bright  # its bodies whole
            found.append(FoundTracer(o.name, float(share), core(touched), core((owner == i + 1) & use)))
    return found


def with_tracers(scan: ScanFile, found: list[FoundTracer]) -> ScanFile:
    """``scan`` with each ``found`` tracer given :data:`FIBRE` at :data:`START_FRACTION`."""
    materials = dataclasses.replace(scan.weave.materials, tracers=tuple(
        Tracer(t.yarn, FibreBundle(FIBRE, START_FRACTION)) for t in found))
    return dataclasses.replace(scan, weave=dataclasses.replace(scan.weave, materials=materials))


def tracer_entry(yarn: str, fraction: float) -> dict:
    """A ``[weave.materials] tracers`` entry of a scan file for ``yarn`` at fibre ``fraction``."""
    return {"yarn": yarn, "material": {"fibre": FIBRE, "fibre_fraction": round(float(fraction), 4)}}

