"""Interpenetrating yarns: how much they overlap, and a boolean resolution into disjoint meshes.

Generated yarns may touch or cut into each other, as TexGen's do (a binder turning between two
wefts cuts into their edges). Scanning and labels need no fix: the scene's priorities (warp over
weft over matrix, :meth:`Sample.scene`) give shared space to one object. Finite-element tools
need disjoint meshes instead; :func:`resolve_boolean` makes them with manifold3d, in float64.

The rule: a yarn's *rank* is its family's priority (:data:`~xrayraster.weave.sample.PRIORITIES`:
warp over weft), then its position in the list of pieces (``Sample.meshes()`` order); the yarn of
higher rank keeps shared space. So wefts lose what warps take from them (weft minus warp, as the
reference pipeline does), and of two yarns of one family the later one keeps the overlap. This is the
scene's own overlap rule (higher priority wins; between equal priorities the one added later), so
a scene of the resolved meshes renders and voxelizes as the priority-resolved one. The matrix is
the box minus the yarns.

Volumes in mm³, lengths in mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import manifold3d
import numpy as np
import trimesh

from ..core.errors import WeaveError
from ..core.validate import show
from .manifold_mesh import box_minus, from_manifold, to_manifold, without_slivers
from .yarn import PRIORITIES, Yarn

__all__ = ["NOISE", "Interpenetration", "Resolved", "interpenetration", "resolve_boolean"]

#: A pair of yarns counts as intersecting when its intersection volume exceeds this fraction of
#: the smaller yarn's volume. Booleans of meshes that merely touch (as resolved yarns do) give
#: float64 rounding, about ±1e-16 mm³; the floor sits far above that and far below any real cut
#: (a binder cutting a weft's edge takes ~1e-2 of the weft).
NOISE = 1e-12

#: Before subtracting a winner from a yarn, the winner is clipped to the yarn's bounding box grown
#: by this much (mm): only that part can touch the yarn, and the small piece makes the subtraction
#: cheap. The margin keeps the clip's cut faces clear of the yarn; any positive value gives the
#: same yarn.
CLIP_MARGIN = 0.01


@dataclass(frozen=True)
class Interpenetration:
    """How much yarn meshes overlap, pair by pair (mm³).

    ``volume``: the summed intersection volume of the ``pairs`` pairs of yarns that intersect
    (above :data:`NOISE`). ``largest_pair`` (two yarn names) and ``largest_volume``: the measured
    pair with the largest intersection, even below the noise floor, so a resolved sample shows its
    residual; None and 0.0 when no pair was measured. ``yarn_volume``: the yarns' total volume.
    """

    volume: float
    pairs: int
    largest_pair: tuple[str, str] | None
    largest_volume: float
    yarn_volume: float

    @property
    def relative(self) -> float:
        """``volume`` as a fraction of ``yarn_volume``."""
        return self.volume / self.yarn_volume


@dataclass(frozen=True)
class Resolved:
    """Disjoint yarn meshes and the matrix around them (see :func:`resolve_boolean`).

    ``pieces``: ``(Yarn, mesh)`` pairs in the input's order, each mesh what its yarn keeps;
    ``dropped``: names of the yarns that kept nothing (left out of ``pieces``); ``matrix``: the
    box minus the yarns; ``before`` and ``after``: the interpenetration of the input (every pair
    whose bounding boxes overlap) and of ``pieces`` (the pairs that intersected before: a resolved
    yarn lies inside its input, so no other pair can), ``after`` None when not measured.
    ``excess``: the resolved yarns' summed volume minus the volume of their union (= the input's
    union, the box minus the matrix before its slivers go), mm³: 0 exactly when they are disjoint,
    their shared volume otherwise (counted once per extra yarn), at the cost of three sums.
    """

    pieces: tuple[tuple[Yarn, trimesh.Trimesh], ...]
    matrix: trimesh.Trimesh
    dropped: tuple[str, ...]
    before: Interpenetration
    after: Interpenetration | None
    excess: float


def interpenetration(pieces) -> Interpenetration:
    """The pairwise overlap of ``pieces``, ``(Yarn, trimesh.Trimesh)`` pairs as ``Sample.meshes()`` gives.

    Every pair whose bounding boxes overlap is intersected exactly (manifold3d, float64).
    """
    yarns, meshes = _check_pieces(pieces)
    solids = [to_manifold(m) for m in meshes]
    return _measure(yarns, solids, *_candidates(_bounds(solids)))[0]


def resolve_boolean(pieces, box, *, measure_after: bool = True) -> Resolved:
    """Make ``pieces`` disjoint (module docstring: the higher rank keeps shared space) and the matrix.

    ``pieces``: ``(Yarn, trimesh.Trimesh)`` pairs as ``Sample.meshes()`` gives; ``box``: the
    ``(2, 3)`` min/max corners (mm) of the matrix, ``Sample.box``. Each yarn loses the union of the
    yarns of higher rank that cut into it; the matrix is the box minus the union of the yarns. Every
    mesh comes out closed, manifold and outward (volume > 0). ``measure_after=False`` skips the
    pairwise ``after`` (a third of the time: booleans of touching meshes are manifold3d's slowest);
    ``excess`` still says whether the result is disjoint.
    """
    yarns, meshes = _check_pieces(pieces)
    lo, hi = _check_box(box, yarns, meshes)
    solids = [to_manifold(m) for m in meshes]
    bounds = _bounds(solids)
    first, second = _candidates(bounds)
    before, cut = _measure(yarns, solids, first, second)
    first, second = first[cut], second[cut]  # the pairs that intersect

    rank = [(PRIORITIES[y.family], k) for k, y in enumerate(yarns)]
    winners: list[list[int]] = [[] for _ in yarns]
    for a, b in zip(first, second):
        loser, winner = (a, b) if rank[a] < rank[b] else (b, a)
        winners[loser].append(winner)
    kept: dict[int, int] = {}  # input index -> index among the resolved
    out_yarns, out_solids, dropped = [], [], []
    for k, (yarn, solid) in enumerate(zip(yarns, solids)):
        if winners[k]:
            grown = bounds[k] + np.array([[-CLIP_MARGIN], [CLIP_MARGIN]])
            clip = manifold3d.Manifold.cube(tuple(grown[1] - grown[0])).translate(tuple(grown[0]))
            solid = manifold3d.Manifold.batch_boolean([solid, *(solids[w] ^ clip for w in winners[k])],
                                                      manifold3d.OpType.Subtract)
        if solid.is_empty():
            dropped.append(yarn.name)
            continue
        kept[k] = len(out_yarns)
        out_yarns.append(yarn)
        out_solids.append(solid)

    # Only pairs that intersected before can intersect after (Resolved). The solids measured are
    # the meshes handed back: to_mesh64 copies their float64 vertices and triangles.
    again = np.array([(kept[a], kept[b]) for a, b in zip(first, second) if a in kept and b in kept],
                     dtype=np.int64).reshape(-1, 2)
    after = _measure(out_yarns, out_solids, again[:, 0], again[:, 1])[0] if measure_after else None

    # The union of the resolved yarns is the union of the input yarns; subtracting the input (no
    # touching faces between its meshes) keeps matrix + yarns = box to float64 rounding.
    matrix = box_minus(np.array([lo, hi]), solids)
    excess = sum(s.volume() for s in out_solids) - (float(np.prod(hi - lo)) - matrix.volume())
    return Resolved(tuple((y, from_manifold(s)) for y, s in zip(out_yarns, out_solids)),
                    from_manifold(without_slivers(matrix)), tuple(dropped), before, after, excess)


# Helpers ----------------------------------------------------------------------------------


def _check_pieces(pieces) -> tuple[list[Yarn], list[trimesh.Trimesh]]:
    fix = "pass Sample.meshes(), a list of (Yarn, trimesh.Trimesh) pairs"
    if isinstance(pieces, (str, bytes)) or not hasattr(pieces, "__len__") or len(pieces) == 0:
        raise WeaveError(f"pieces must be a non-empty list of (Yarn, mesh) pairs, got {show(pieces)}; {fix}")
    yarns, meshes = [], []
    for k, piece in enumerate(pieces):
        if not (isinstance(piece, tuple) and len(piece) == 2 and isinstance(piece[0], Yarn)
                and isinstance(piece[1], trimesh.Trimesh)):
            raise WeaveError(f"pieces[{k}] must be a (Yarn, trimesh.Trimesh) pair, got {type(piece).__name__}; {fix}")
        yarn, mesh = piece
        if yarn.family not in PRIORITIES or yarn.family == "matrix":
            raise WeaveError(f"pieces[{k}] ({yarn.name}): family must be 'weft' or 'warp', got {show(yarn.family)}")
        if len(mesh.faces) == 0:
            raise WeaveError(f"pieces[{k}] ({yarn.name}): the mesh has no faces; {fix}")
        yarns.append(yarn)
        meshes.append(mesh)
    names = [y.name for y in yarns]
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise WeaveError(f"pieces: yarn names must be unique (the report names pairs), repeated: {show(twice)}")
    return yarns, meshes


def _check_box(box, yarns, meshes) -> tuple[np.ndarray, np.ndarray]:
    try:
        corners = np.array(box, dtype=np.float64)
    except (TypeError, ValueError):
        corners = None
    if corners is None or corners.shape != (2, 3) or not np.all(np.isfinite(corners)) \
            or not np.all(corners[0] < corners[1]):
        raise WeaveError(f"box must be (2, 3) min/max corners in mm with min < max, got {show(box)}; "
                         "pass Sample.box")
    lo, hi = corners
    slack = 1e-9 * float(np.max(hi - lo))
    for yarn, mesh in zip(yarns, meshes):
        if np.any(mesh.bounds[0] < lo - slack) or np.any(mesh.bounds[1] > hi + slack):
            raise WeaveError(f"box: yarn {yarn.name} reaches outside it (the matrix would not hold it); "
                             "pass the sample's box, Sample.box")
    return lo, hi


def _bounds(solids) -> np.ndarray:
    """``(n, 2, 3)`` min/max corners (mm) of each solid."""
    return np.array([s.bounding_box() for s in solids], dtype=np.float64).reshape(-1, 2, 3)


def _candidates(bounds) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(first, second)``, first < second, whose bounding boxes overlap in a volume."""
    lo, hi = bounds[:, 0], bounds[:, 1]
    overlap = np.all((lo[:, None] < hi[None]) & (lo[None] < hi[:, None]), axis=2)
    return np.nonzero(np.triu(overlap, 1))


def _measure(yarns, solids, first, second) -> tuple[Interpenetration, np.ndarray]:
    """The interpenetration over the pairs ``(first[k], second[k])``, and which of them intersect."""
    volumes = np.array([s.volume() for s in solids])
    total = float(volumes.sum())
    if len(first) == 0:
        return Interpenetration(0.0, 0, None, 0.0, total), np.zeros(0, bool)
    shared = np.array([(solids[a] ^ solids[b]).volume() for a, b in zip(first, second)], dtype=np.float64)
    cut = shared > NOISE * np.minimum(volumes[first], volumes[second])
    top = int(np.argmax(shared))
    found = Interpenetration(float(shared[cut].sum()), int(cut.sum()), (yarns[first[top]].name, yarns[second[top]].name),
                             float(shared[top]), total)
    return found, cut
