"""Meshes as manifold3d solids in float64, written apart from the package's own conversion so the
tests that check yarn meshes do not lean on the code they check."""

from __future__ import annotations

import manifold3d
import numpy as np


def solid(mesh) -> manifold3d.Manifold:
    """``mesh`` (anything with ``vertices`` and ``faces``) as a manifold3d solid (``Mesh64``); check ``.status()``."""
    return manifold3d.Manifold(manifold3d.Mesh64(
        vert_properties=np.array(mesh.vertices, dtype=np.float64, order="C"),
        tri_verts=np.array(mesh.faces, dtype=np.uint64, order="C")))


def is_manifold(mesh) -> bool:
    """Whether manifold3d reads ``mesh`` as a closed, non-empty 2-manifold."""
    s = solid(mesh)
    return s.status() == manifold3d.Error.NoError and not s.is_empty()
