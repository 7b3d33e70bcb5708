"""trimesh ↔ manifold3d in double precision, for the exact booleans of the weave (clip, resolve, volumes)."""

from __future__ import annotations

import manifold3d
import numpy as np
import trimesh

from ..core.errors import WeaveError

__all__ = ["SLIVER_TOLERANCE_MM", "box_minus", "from_manifold", "to_manifold", "union", "without_slivers"]

#: Subtracting yarns from the sample box leaves a few sliver triangles (heights of ~1e-8 mm, which
#: trimesh and finite-element meshers count as degenerate) where the yarns' cut faces lie in the
#: box's faces. The matrix is simplified to this tolerance: its surface moves by less than 1e-7 mm,
#: its volume by ~1e-10 of itself, and the slivers go.
SLIVER_TOLERANCE_MM = 1e-7


def to_manifold(mesh: trimesh.Trimesh, name: str = "a yarn") -> manifold3d.Manifold:
    """``mesh`` as a manifold3d solid (``Mesh64``: float64 vertices, no rounding to float32)."""
    solid = manifold3d.Manifold(manifold3d.Mesh64(
        vert_properties=np.array(mesh.vertices, dtype=np.float64, order="C"),
        tri_verts=np.array(mesh.faces, dtype=np.uint64, order="C")))
    if solid.status() != manifold3d.Error.NoError:
        raise WeaveError(f"manifold3d cannot read the mesh of {name} ({solid.status()})")
    return solid


def from_manifold(solid: manifold3d.Manifold) -> trimesh.Trimesh:
    """A manifold3d solid as a trimesh, float64 vertices as computed."""
    out = solid.to_mesh64()
    return trimesh.Trimesh(vertices=np.array(np.asarray(out.vert_properties)[:, :3], dtype=np.float64),
                           faces=np.array(out.tri_verts, dtype=np.int64), process=False)


def union(solids: list[manifold3d.Manifold]) -> manifold3d.Manifold:
    """The union of ``solids`` (empty for none), in one batch boolean."""
    if not solids:
        return manifold3d.Manifold()
    return manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add)


def box_minus(box_mm, solids: list[manifold3d.Manifold]) -> manifold3d.Manifold:
    """The ``(2, 3)`` min/max box (mm) minus ``solids``: the matrix, before :func:`without_slivers`."""
    lo, hi = np.asarray(box_mm, dtype=np.float64)
    box = manifold3d.Manifold.cube(tuple(hi - lo)).translate(tuple(lo))
    return manifold3d.Manifold.batch_boolean([box, *solids], manifold3d.OpType.Subtract)


def without_slivers(solid: manifold3d.Manifold) -> manifold3d.Manifold:
    """``solid`` simplified to :data:`SLIVER_TOLERANCE_MM`: the box-minus-yarns slivers removed."""
    return solid.simplify(SLIVER_TOLERANCE_MM)
