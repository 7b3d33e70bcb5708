"""``xr.weave``: a weave file → a woven sample, its report, its scene and a voxel grid over it.

The command line's ``xrayraster weave`` is this function and :meth:`WeaveResult.save`: one code
path. The output directory is built under a temporary name and moved into place whole
(:func:`output_directory`, the one place that decides how an earlier export is replaced).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..core.files import atomic_directory
from ..core.geometry import ConeBeamGeometry
from ..core.transform import Transform
from ..core.volume import VolumeGeometry
from ..io.grid_file import write_grid_file
from ..io.weave_file import WeaveFile, framing_geometry, load_weave_file, sample_grid, write_scene_file
from ..scene.scene import Scene
from ..weave.export import GENERATOR, REPORT_NAME, MeshPart, write_parts, write_report
from ..weave.sample import Sample

__all__ = ["GRID_NAME", "SCENE_NAME", "WeaveResult", "output_directory", "weave"]

# An export before the grid file was named wrote its grid as scan.json: its report.json lists it,
# so a new export over it removes it (core/files.atomic_directory).
SCENE_NAME, GRID_NAME = "scene.toml", "grid.json"


@dataclass(frozen=True)
class WeaveResult:
    """A generated sample: ``parts`` (one mesh file each), the ``report`` that ``report.json``
    stores, the scan ``geometry`` of its scene file (a full circle that frames the sample) and the
    voxel ``grid`` of its ``grid.json`` (the sample's box at the scan's magnified pixel pitch)."""

    sample: Sample
    parts: list[MeshPart]
    report: dict
    geometry: ConeBeamGeometry
    grid: VolumeGeometry

    @cached_property
    def scene(self) -> Scene:
        """The scene that ``scene.toml`` describes, without its tube: the parts with their materials,
        labels and priorities, the box centred on the rotation axis. Made on first use."""
        centre = Transform.translation(-np.mean(self.report["box_mm"], axis=0))
        scene = Scene()
        for part in self.parts:
            scene.add(part.mesh, part.material, label=part.label, priority=part.priority, name=part.name,
                      transform=centre)
        return scene

    def save(self, directory, *, overwrite: bool = False) -> Path:
        """Write what ``xrayraster weave`` writes into ``directory``, atomically (:func:`output_directory`;
        ``overwrite``: as ``--force``)."""
        with output_directory(directory, overwrite=overwrite) as tmp:
            self.write(tmp)
        return Path(directory)

    def write(self, directory) -> None:
        """The mesh files, ``report.json``, ``scene.toml`` and ``grid.json``, each written atomically,
        into an existing ``directory``."""
        directory = Path(directory)
        write_parts(self.parts, directory, self.report["format"])
        write_report(self.report, directory)
        write_scene_file(directory / SCENE_NAME, self.report, self.geometry)
        write_grid_file(directory / GRID_NAME, self.grid)


@contextmanager
def output_directory(path, *, overwrite: bool = False):
    """A temporary directory to write an export into, moved to ``path`` when the block ends
    (:func:`~xrayraster.core.files.atomic_directory`, recorded in ``report.json``): an existing
    ``path`` is replaced only if it holds nothing but an earlier export, checked on entry, so the
    command line refuses before any work; ``overwrite`` replaces the earlier export's files and
    keeps every other entry."""
    with atomic_directory(path, marker=REPORT_NAME, generator=GENERATOR, overwrite=overwrite,
                          names=(REPORT_NAME, SCENE_NAME, GRID_NAME)) as tmp:
        yield tmp


def weave(source, *, per: str = "family", fmt: str = "stl", resolve: str = "priority",
          progress: bool = False) -> WeaveResult:
    """Generate the sample of a weave file (a path, its parsed table as a dict, or a loaded
    :class:`~xrayraster.io.weave_file.WeaveFile`; docs/weave.md). ``per``: one mesh per yarn
    ``family`` or per ``yarn``; ``fmt``: "stl" or "ply"; ``resolve``: "priority" (overlaps left to the
    scene's priorities, as the renderer settles them) or "boolean" (disjoint meshes, for
    finite-element tools); ``progress``: progress bars and stage lines on stderr."""
    loaded = source if isinstance(source, WeaveFile) else load_weave_file(source)
    parts, report = loaded.sample.exported(loaded.materials, per=per, fmt=fmt, resolve=resolve, progress=progress)
    geometry = framing_geometry(report["box_mm"])
    return WeaveResult(loaded.sample, parts, report, geometry, sample_grid(report["box_mm"], geometry))
