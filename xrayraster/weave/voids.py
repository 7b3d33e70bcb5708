"""Matrix voids: a seeded population of ellipsoidal pores in a woven sample's matrix.

A :class:`Voids` holds the population's law (all 0 by default: no voids); a
:class:`~xrayraster.weave.Sample` draws the voids from its ``seed`` (:func:`draw_voids`). Each void
is an ellipsoid: its equivalent-sphere radius log-normal about ``radius_mm`` (σ of its logarithm
``radius_spread``), its semi-axes in the ratios ``aspect`` (x, y, z before turning; volume kept),
turned uniformly at random. Voids are drawn until their summed volume reaches ``volume_fraction``
of the matrix box (the last one as drawn: the fraction is exceeded by at most one void). A
candidate that overlaps an earlier void is drawn again, and so is one that cuts a yarn unless
``placement = "anywhere"``:

* ``"matrix"`` (default): centred anywhere in the matrix box, wholly inside it, cutting no yarn;
* ``"between_yarns"``: the same, but centred between the top of the lowest layer of cells' bottom
  margin and the bottom of the top one's top margin (the pockets between yarns, not the resin-rich
  faces);
* ``"anywhere"``: centred anywhere in the box; where it cuts a yarn the yarn keeps its space (a
  void ranks between the matrix and the yarns, :data:`~xrayraster.weave.yarn.PRIORITIES`).

The yarn test is exact on the yarns' meshes, after a quick refusal of candidates near a yarn's
centre line (:class:`_YarnTest`): a candidate whose bounding sphere meets a yarn's bounding box is
intersected with that yarn (manifold3d, float64) and refused when they share any volume. Their material is air; their label ``void``. Each void's mesh is an icosphere of 320
triangles stretched to the ellipsoid and scaled so that its volume is the ellipsoid's.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
import trimesh

from ..core import fields
from ..core.errors import ConfigError, WeaveError
from ..core.validate import show

__all__ = ["MAX_VOIDS", "PLACEMENTS", "Voids", "draw_voids"]

PLACEMENTS = ("matrix", "between_yarns", "anywhere")
#: The most voids a sample may hold (320 triangles each): a larger population is refused, naming the
#: fields that set it, before any is drawn.
MAX_VOIDS = 20000
#: Candidates drawn per void before the population is refused as not fitting.
ATTEMPTS_PER_VOID = 50
#: Icosphere subdivisions of a void's mesh (320 triangles).
SUBDIVISIONS = 2
#: A shared volume (mm³) under this is a touch, not a cut (manifold3d's rounding of a glancing contact).
TOUCH_MM3 = 1e-12


@dataclass(frozen=True)
class Voids:
    """A void population's law (module docstring); mm, and shares of the matrix box's volume."""

    volume_fraction: float = 0.0
    radius_mm: float = 0.1
    radius_spread: float = 0.3
    aspect: tuple[float, float, float] = (1.0, 1.0, 1.0)
    placement: str = "matrix"

    def __post_init__(self):
        for name, hi in (("volume_fraction", 0.3), ("radius_spread", 1.0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 <= value <= hi:
                raise WeaveError(f"voids.{name} must be a number in [0, {hi}], got {show(value)}")
            object.__setattr__(self, name, float(value))
        r = self.radius_mm
        if isinstance(r, bool) or not isinstance(r, numbers.Real) or not 0 < r < float("inf"):
            raise WeaveError(f"voids.radius_mm must be a positive number of mm, got {show(r)}")
        object.__setattr__(self, "radius_mm", float(r))
        aspect = self.aspect
        if (isinstance(aspect, (str, bytes)) or not hasattr(aspect, "__len__") or len(aspect) != 3
                or not all(isinstance(a, numbers.Real) and not isinstance(a, bool) and 0 < a < float("inf")
                           for a in aspect)):
            raise WeaveError(f"voids.aspect must be three positive ratios of the semi-axes (x, y, z), got {show(aspect)}")
        object.__setattr__(self, "aspect", tuple(float(a) for a in aspect))
        if self.placement not in PLACEMENTS:
            raise WeaveError(f"voids.placement must be one of {', '.join(map(repr, PLACEMENTS))}, "
                             f"got {show(self.placement)}")

    @property
    def is_zero(self) -> bool:
        return self.volume_fraction == 0

    def mean_volume_mm3(self) -> float:
        """A void's mean volume: (4/3) π E[r³], r log-normal (E[r³] = radius_mm³ · exp(4.5 σ²))."""
        return 4 / 3 * math.pi * self.radius_mm**3 * math.exp(4.5 * self.radius_spread**2)

    def expected_count(self, box_mm) -> float:
        """About how many voids fill ``volume_fraction`` of the box (``(2, 3)`` corners, mm)."""
        lo, hi = np.asarray(box_mm, dtype=np.float64)
        return self.volume_fraction * float(np.prod(hi - lo)) / self.mean_volume_mm3()

    def to_dict(self) -> dict:
        return {"volume_fraction": self.volume_fraction, "radius_mm": self.radius_mm,
                "radius_spread": self.radius_spread, "aspect": list(self.aspect), "placement": self.placement}

    @classmethod
    def from_dict(cls, d: dict, where: str = "[weave.voids]") -> Voids:
        """Voids from their dict form; errors name ``where`` and the field. Missing keys take defaults."""
        d = fields.mapping(d, where)
        fields.only(d, {"volume_fraction", "radius_mm", "radius_spread", "aspect", "placement"}, where)
        kwargs = {k: fields.number(d[k], k, where) for k in ("volume_fraction", "radius_mm", "radius_spread") if k in d}
        if "aspect" in d:
            kwargs["aspect"] = fields.vector(d["aspect"], "aspect", where, 3, "[x, y, z], three ratios of the semi-axes")
        if "placement" in d:
            kwargs["placement"] = fields.string(d["placement"], "placement", where)
        try:
            return cls(**kwargs)
        except WeaveError as exc:
            raise ConfigError(f"{where}: {exc}") from None


def draw_voids(voids: Voids, box_mm, centre_box_mm, yarns, rng: np.random.Generator) -> list[trimesh.Trimesh]:
    """The voids of one sample (module docstring): closed, outward ellipsoid meshes wholly inside
    ``box_mm`` (``(2, 3)`` corners, mm) with their centres in ``centre_box_mm``, none overlapping
    another and, but for ``placement = "anywhere"``, none cutting ``yarns`` (``(Yarn, mesh)`` pairs,
    :meth:`~xrayraster.weave.Sample.meshes`). ``rng`` draws the candidates in batches of
    :data:`BATCH`, tried in order: the same generator state gives the same voids."""
    if voids.is_zero:
        return []
    lo, hi = np.asarray(box_mm, dtype=np.float64)
    count = voids.expected_count(box_mm)
    if count > MAX_VOIDS:
        raise WeaveError(f"voids: about {count:.0f} voids would fill volume_fraction = {voids.volume_fraction:g} of "
                         f"the box, over {MAX_VOIDS}; raise voids.radius_mm or lower voids.volume_fraction")
    from .manifold_mesh import to_manifold

    avoid = _YarnTest(yarns) if voids.placement != "anywhere" else None
    target = voids.volume_fraction * float(np.prod(hi - lo))
    unit = trimesh.creation.icosphere(subdivisions=SUBDIVISIONS)
    unit.apply_scale((4 / 3 * math.pi / unit.volume) ** (1 / 3))  # the unit ball's volume
    unit_solid = to_manifold(unit, "a void")
    ratios = np.asarray(voids.aspect) / np.prod(voids.aspect) ** (1 / 3)
    first, last = np.asarray(centre_box_mm, dtype=np.float64)
    placed, total, tried = [], 0.0, 0
    others = _Neighbours()
    budget = ATTEMPTS_PER_VOID * max(1, math.ceil(count))
    while total < target and tried < budget:
        radius = voids.radius_mm * np.exp(voids.radius_spread * rng.standard_normal(BATCH))
        turns = np.array([trimesh.transformations.random_rotation_matrix(r)[:3, :3] for r in rng.random((BATCH, 3))])
        along = rng.random((BATCH, 3))
        tried += BATCH
        stretch = turns * (radius[:, None] * ratios)[:, None, :]  # the unit ball's x goes to stretch @ x + centre
        reach = radius * ratios.max()
        low, high = np.maximum(first, lo + reach[:, None]), np.minimum(last, hi - reach[:, None])
        fits = np.all(low <= high, axis=1)  # else too large for the room its centre may take
        centres = low + along * (high - low)
        if avoid is not None:
            fits &= ~avoid.near(centres, reach)
        for k in np.flatnonzero(fits):
            if total >= target:
                break
            if others.overlap(centres[k], reach[k]):
                continue
            if avoid is not None and avoid.cuts(unit_solid.transform(np.column_stack([stretch[k], centres[k]])),
                                                centres[k], reach[k]):
                continue
            placed.append(trimesh.Trimesh(unit.vertices @ stretch[k].T + centres[k], unit.faces, process=False))
            others.add(centres[k], reach[k])
            total += 4 / 3 * math.pi * radius[k] ** 3
    if total >= target:
        return placed
    raise WeaveError(f"voids: {len(placed)} voids placed ({total / np.prod(hi - lo):.3g} of the box) after {tried} "
                     f"candidates, short of volume_fraction = {voids.volume_fraction:g}: the matrix has too little "
                     "room; lower voids.volume_fraction or voids.radius_mm, or use placement = \"anywhere\"")


#: Candidates drawn at once (their quick tests run together).
BATCH = 1024


class _Neighbours:
    """The bounding spheres of the voids placed so far, in cells of a grid for a quick overlap test."""

    def __init__(self):
        self.cell = None
        self.cells: dict[tuple, list[tuple[np.ndarray, float]]] = {}

    def _key(self, centre) -> tuple:
        return tuple(np.floor(centre / self.cell).astype(int))

    def overlap(self, centre: np.ndarray, reach: float) -> bool:
        if self.cell is None:
            return False
        span = int(math.ceil((reach + self.largest) / self.cell))
        x, y, z = self._key(centre)
        return any(np.linalg.norm(c - centre) < r + reach
                   for i in range(x - span, x + span + 1) for j in range(y - span, y + span + 1)
                   for k in range(z - span, z + span + 1) for c, r in self.cells.get((i, j, k), ()))

    def add(self, centre: np.ndarray, reach: float) -> None:
        if self.cell is None:
            self.cell, self.largest = 2 * reach, reach
        self.largest = max(self.largest, reach)
        self.cells.setdefault(self._key(centre), []).append((centre, reach))


class _YarnTest:
    """Whether a void cuts a yarn. First a quick refusal: the void's bounding sphere meets a yarn's
    hull, the ellipse of the section's width and height grown by the sphere's radius, in the path's
    frame at a point of its centre line (:data:`CORE_STEP_MM` apart). It turns away every void that
    comes near a yarn (and some that would have fitted beside a lens's tip or in a distortion's
    hollow: where they go, not how many). Then the exact intersection (manifold3d) with each yarn
    whose box the sphere meets: a void that passes shares no volume with any yarn."""

    def __init__(self, yarns):
        from scipy.spatial import cKDTree

        from .manifold_mesh import to_manifold

        self.meshes = [mesh for _, mesh in yarns]
        self.solids = [None] * len(self.meshes)  # made on first use
        self.to_manifold = to_manifold
        self.bounds = np.array([mesh.bounds for mesh in self.meshes]).reshape(-1, 2, 3)
        self.hull = _hulls([yarn for yarn, _ in yarns])
        self.points = cKDTree(self.hull[0])
        self.widest = float(self.hull[3].max()) if len(self.hull[3]) else 0.0

    def near(self, centres: np.ndarray, reaches: np.ndarray) -> np.ndarray:
        """Per candidate: whether its bounding sphere meets a yarn's hull (the quick refusal)."""
        points, across, up, half = self.hull
        hit = np.zeros(len(centres), bool)
        if not len(points):
            return hit
        _, k = self.points.query(centres, k=NEAREST, distance_upper_bound=self.widest + float(reaches.max()))
        found = k < len(points)
        k = np.where(found, k, 0)
        d = centres[:, None, :] - points[k]
        u = np.einsum("bkj,bkj->bk", d, across[k]) / (half[k, 0] + reaches[:, None])
        v = np.einsum("bkj,bkj->bk", d, up[k]) / (half[k, 1] + reaches[:, None])
        return np.any(found & (u * u + v * v < 1.0), axis=1)

    def cuts(self, solid, centre: np.ndarray, reach: float) -> bool:
        """Whether ``solid`` (a void of bounding sphere ``centre``, ``reach``) shares volume with a yarn."""
        boxes = np.flatnonzero(np.all((self.bounds[:, 0] < centre + reach) & (self.bounds[:, 1] > centre - reach),
                                      axis=1))
        for k in boxes:
            if self.solids[k] is None:
                self.solids[k] = self.to_manifold(self.meshes[k])
            if (solid ^ self.solids[k]).volume() > TOUCH_MM3:
                return True
        return False


#: The centre-line points nearest a candidate whose hulls it is tried against.
NEAREST = 64
#: Points of a yarn's centre line at which its hull is tried (mm apart).
CORE_STEP_MM = 0.1


def _hulls(yarns) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points along every yarn's centre line :data:`CORE_STEP_MM` apart, the path's frame there
    (across: level and square to the path; up: square to both) and its section's half-width and
    half-height (mm), its largest scale applied."""
    from .sweep import CubicSpline3

    out = []
    for yarn in yarns:
        spline = CubicSpline3(yarn.nodes, yarn.end_tangents)
        t = np.linspace(0.0, spline.length_parameter, int(math.ceil(spline.length_parameter / CORE_STEP_MM)) + 1)
        points, tangents = spline(t), spline(t, 1)
        tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
        across = np.cross(tangents, (0.0, 0.0, 1.0))
        across /= np.linalg.norm(across, axis=1, keepdims=True)
        up = np.cross(across, tangents)
        scale = 1.0 if yarn.section_scale is None else np.asarray(yarn.section_scale).max(axis=0)
        half = np.abs(yarn.outline).max(axis=0) * scale
        out.append((points, across, up, np.broadcast_to(half, (len(t), 2))))
    return tuple(np.concatenate(part) for part in zip(*out))
