"""Partial overlaps written as signed terms, so a scene whose objects cut into each other renders in one pass.

Where objects overlap, the highest-ranked one owns the space (:mod:`~xrayraster.scene.scene`). An
object X owns X minus the union of the higher-ranked objects H that overlap it; by
inclusion–exclusion its length along a ray is the sum, over the subsets S of H, of
(−1)^|S| · chord(X ∩ ⋂S). So a one-pass sum, in which every crossing adds its signed distance to a
channel, gives each object what it owns when the scene also holds each set of mutually overlapping
objects' intersection as a closed mesh (a *term*) whose chord counts (−1)^(k−1) times in the
channel of its lowest-ranked member, k being the number of members. As a nested object takes its
length off its container's channel, so does each term, with its sign: the container then owns its
length minus the union of the objects inside it.

Woven samples need this: their yarns cut into each other at a few percent of their volume (a
binder turning between two wefts), so their scenes took the per-pixel sort (method "resolve" in
:mod:`xrayraster.gl.pathlengths`), several times slower than a sum on a GPU. Their overlaps are
pairs, rarely triples. The intersections are manifold3d's exact booleans (float64 arithmetic on the
float32 vertices the renderer uploads), already computed to find the overlaps; each lies on its
members' surfaces, so a ray meets it where it meets them, to float32 rounding.

Terms apply when (else :func:`overlap_terms` returns None and the renderer sorts per pixel):

* every object manifold3d reads;
* the members of a partial overlap are visible (not inside a higher-ranked container), contain no
  object, and share one container (or none): the container then loses the union of its objects;
* no four objects share space (a term of four or more would be needed; never seen in a weave).

Volumes in mm³.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Mesh

__all__ = ["MAX_MEMBERS", "NOISE", "OverlapTerm", "overlap_terms"]

#: An intersection counts when its volume exceeds this share of its smallest member's: booleans of
#: meshes that merely touch leave float rounding (about 1e-16 of a yarn), and any real cut is far
#: above it. Unlike the overlap test's 1e-6 (which picks the method), a term is exact at any size,
#: so the smallest real sliver gets one.
NOISE = 1e-12
#: The most objects a term may have: four objects sharing space send the scene to the per-pixel sort.
MAX_MEMBERS = 3


@dataclass(frozen=True, eq=False)
class OverlapTerm:
    """The intersection of ``members`` (insertion indices, lowest rank first) as a closed mesh,
    whose chord counts ``sign`` (+1 or −1) times in the first member's channel and −``sign``
    times in that member's container's channel."""

    mesh: Mesh
    members: tuple[int, ...]
    sign: int


def overlap_terms(ranks: list, intersections: dict, solids: list, nesting: list,
                  containers: set) -> tuple[OverlapTerm, ...] | None:
    """The terms that stand in for the partial overlaps (module docstring), or None where they cannot.

    ``ranks``: each object's rank (insertion order); ``intersections``: ``(i, j) → manifold3d solid``
    for the pairs i < j that overlap partially (any volume above :data:`NOISE` of the smaller);
    ``solids``: each object's manifold3d solid (the pairs' members' at least); ``nesting``: the
    containers from the containments alone (:meth:`Scene.nesting`'s form: an object's own index
    when hidden); ``containers``: the objects some other object lies wholly inside.
    """
    if not intersections:
        return ()
    members = {k for pair in intersections for k in pair}
    if any(nesting[k] == k for k in members) or members & containers:
        return None
    if any(nesting[i] != nesting[j] for i, j in intersections):
        return None
    volume = {k: solids[k].volume() for k in members}
    neighbours: dict[int, set[int]] = {}
    for i, j in intersections:
        neighbours.setdefault(i, set()).add(j)
        neighbours.setdefault(j, set()).add(i)

    terms = []
    pending = [((i, j), solid) for (i, j), solid in sorted(intersections.items())]
    while pending:
        group, solid = pending.pop(0)
        if len(group) > MAX_MEMBERS:
            return None
        ordered = tuple(sorted(group, key=lambda k: ranks[k]))
        terms.append(OverlapTerm(_mesh(solid), ordered, -1 if len(group) % 2 == 0 else 1))
        # A larger term for each object that overlaps every member, counted once (its index above theirs).
        for k in sorted(set.intersection(*(neighbours[m] for m in group))):
            if k > max(group):
                shared = solid ^ solids[k]
                if shared.volume() > NOISE * min(volume[m] for m in (*group, k)):
                    pending.append(((*group, k), shared))
    return tuple(terms)


def _mesh(solid) -> Mesh:
    """A manifold3d solid as a read-only :class:`Mesh` (closed and outward, as manifold3d keeps it)."""
    out = solid.to_mesh()
    vertices = np.array(out.vert_properties[:, :3], dtype=np.float64)
    faces = np.array(out.tri_verts, dtype=np.int64)
    vertices.setflags(write=False)
    faces.setflags(write=False)
    return Mesh(vertices, faces)
