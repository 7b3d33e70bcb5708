"""One yarn of a sample (its path, outline and section variation) and the families' labels and priorities."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from ..core.errors import WeaveError
from .section import Section
from .sweep import ellipse, lenticular, power_ellipse, rounded_rectangle, yarn_mesh

__all__ = ["LABELS", "PRIORITIES", "Yarn", "section_outline"]

#: Label volume values and scene priorities: warp over weft over matrix where they share space. A
#: binder is a warp; labelled as a class of its own (``binder_label``), it keeps the warp's priority.
#: A matrix void (:mod:`~xrayraster.weave.voids`) takes the matrix's space and never a yarn's.
LABELS = {"matrix": 1, "weft": 2, "warp": 3, "binder": 4, "void": 5}
PRIORITIES = {"matrix": 0, "weft": 1, "warp": 2, "binder": 2, "void": 0.5}


def section_outline(section: Section, width: float, height: float, k: int) -> np.ndarray:
    """The ``(k, 2)`` outline (mm) of ``section`` for a yarn ``width`` × ``height``."""
    if section.shape == "ellipse":
        return ellipse(width, height, k)
    if section.shape == "lenticular":
        return lenticular(width, height, k)
    if section.shape == "power_ellipse":
        return power_ellipse(width, height, section.exponent, k)
    if section.shape == "rounded_rectangle":
        return rounded_rectangle(width, height, section.corner, k)
    raise WeaveError(f"unknown section shape {section.shape!r}")  # pragma: no cover (Section checks)


@dataclass(frozen=True)
class Yarn:
    """One yarn of a sample: its family (``weft`` or ``warp``), kind, centre-line nodes (mm) and outline."""

    name: str
    family: str
    kind: str  # "weft", "binder" or "stuffer"
    nodes: np.ndarray
    outline: np.ndarray
    end_tangents: tuple | None = None  # clamped unit end tangents of the path, or None (natural)
    section_scale: np.ndarray | None = None  # (m, 2) width/height factors per node, or None (constant)
    section_rotation_deg: np.ndarray | None = None  # (m,) section rotation per node, or None

    def mesh(self, samples_per_mm: float, within=None, sagitta_mm=None) -> trimesh.Trimesh:
        """The closed, unclipped tube of this yarn (:func:`~xrayraster.weave.sweep.yarn_mesh`, ``within`` a box,
        ``sagitta_mm`` the largest chord error of adaptive path samples)."""
        return yarn_mesh(self.nodes, self.outline, samples_per_mm, end_tangents=self.end_tangents,
                         section_scale=self.section_scale, section_rotation_deg=self.section_rotation_deg,
                         within=within, sagitta_mm=sagitta_mm)


