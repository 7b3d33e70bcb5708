"""trimesh ↔ manifold3d in double precision, for the exact booleans of the weave (clip, resolve, volumes)."""

from __future__ import annotations

import manifold3d
import numpy as np
import trimesh

from ..core.errors import WeaveError

__all__ = ["from_manifold", "to_manifold", "union"]


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
