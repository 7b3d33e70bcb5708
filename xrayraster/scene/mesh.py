"""Loading and checking closed triangle meshes.

A path length is only defined inside a closed surface, so every mesh is checked once, on entry:
finite coordinates, triangles that collapse onto a repeated vertex removed, every edge matched
by its reverse (watertight and consistently wound), and outward orientation (a mesh that is
only inside out is flipped silently).
"""

from __future__ import annotations

import io
import os
import warnings
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..core.errors import MeshError
from ..core.inputs import BINARY_MARK, decode_text, read_file_bytes
from ..core.transform import Transform

# A binary STL: an 80-byte header, a little-endian uint32 triangle count, then 50 bytes a triangle.
_STL_HEADER_BYTES, _STL_TRIANGLE_BYTES = 84, 50
# Mesh formats that are text throughout (an ASCII STL, when it is not a binary one).
_TEXT_MESH_FORMATS = ("stl", "obj", "off")


@dataclass(frozen=True, eq=False)
class Mesh:
    """A closed, outward-oriented triangle mesh in mm (read-only float64 vertices, int64 faces)."""

    vertices: np.ndarray
    faces: np.ndarray

    @cached_property
    def bounds(self) -> np.ndarray:
        """``(2, 3)`` min and max corners, mm (read-only; computed once: the vertices are read-only too,
        and a renderer asks every view)."""
        corners = np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])
        corners.setflags(write=False)
        return corners

    @property
    def volume(self) -> float:
        """Enclosed volume, mm³ (divergence theorem in float64)."""
        a, b, c = (self.vertices[self.faces[:, k]] for k in range(3))
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    def __repr__(self) -> str:
        return f"<Mesh {len(self.vertices)} vertices, {len(self.faces)} triangles>"


def load_mesh(source, *, name: str = "mesh", transform: Transform | None = None, unit_scale: float = 1.0) -> Mesh:
    """Read and check a mesh from a path (STL/OBJ/PLY), a ``trimesh.Trimesh`` or ``(vertices, faces)``.

    ``unit_scale`` converts the file's units to mm (e.g. 1000 for a mesh in metres) and is
    applied before ``transform`` (which places the object in the scanner frame).
    """
    vertices, faces = _read(source, name)
    if not np.all(np.isfinite(vertices)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(vertices), axis=1)))
        raise MeshError(f"object {name!r}: {bad} vertices are NaN or infinite; fix the mesh file")
    if not (np.isfinite(unit_scale) and unit_scale > 0):
        raise MeshError(f"object {name!r}: unit_scale must be a positive number, got {unit_scale!r}")
    vertices = vertices * float(unit_scale)
    if transform is not None:
        vertices = transform.apply(vertices)
        if transform.flips_orientation:
            faces = faces[:, ::-1]
    vertices, faces = _merge_duplicate_vertices(vertices, faces)
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
    if len(faces) == 0:
        raise MeshError(f"object {name!r}: the mesh has no triangles with three distinct vertices")
    faces = _check_closed(vertices, faces, name)
    mesh = Mesh(vertices, faces)
    if mesh.volume < 0:
        mesh = Mesh(vertices, faces[:, ::-1].copy())
    used = np.unique(mesh.faces)
    if len(used) < len(mesh.vertices):  # drop unused vertices so bounds describe the surface
        remap = np.full(len(mesh.vertices), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        mesh = Mesh(mesh.vertices[used], remap[mesh.faces])
    mesh.vertices.setflags(write=False)
    mesh.faces.setflags(write=False)
    return mesh


def _mesh_file_bytes(path, name: str) -> tuple[bytes, str]:
    """The bytes of mesh file ``path`` and its format (its suffix), with text formats checked here:
    trimesh guesses a non-UTF-8 file's encoding only when charset_normalizer happens to be
    installed, and reads binary bytes as text, so what a file holds is said here, the same on
    every install. A binary STL passes as it is."""
    what = f"object {name!r}: mesh file"
    data = read_file_bytes(path, what, MeshError)
    file_type = Path(path).suffix.lower().lstrip(".")
    if file_type == "stl" and len(data) >= _STL_HEADER_BYTES:
        triangles = int.from_bytes(data[_STL_HEADER_BYTES - 4:_STL_HEADER_BYTES], "little")
        if len(data) == _STL_HEADER_BYTES + _STL_TRIANGLE_BYTES * triangles:
            return data, file_type
        if BINARY_MARK in data:
            raise MeshError(f"{what} {path}: holds binary data that is not a binary STL ({len(data)} bytes, not "
                            f"84 + 50 × the {triangles} triangles its header counts); give an STL, OBJ or PLY mesh")
    if file_type in _TEXT_MESH_FORMATS:
        decode_text(data, path, what, MeshError)
    return data, file_type


def _read(source, name: str) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(source, (str, os.PathLike)):
        import trimesh

        data, file_type = _mesh_file_bytes(source, name)
        try:
            loaded = trimesh.load(io.BytesIO(data), file_type=file_type, force="mesh", process=False)
        except Exception as exc:  # trimesh raises many types for unreadable files
            raise MeshError(f"object {name!r}: cannot read mesh file {os.fspath(source)!r}: {exc}") from exc
        if len(loaded.faces) == 0:  # trimesh reads bytes that are no mesh (or text in another format) as empty
            raise MeshError(f"object {name!r}: mesh file {os.fspath(source)!r}: no triangles read; "
                            "give an STL, OBJ or PLY mesh")
        source = loaded
    if hasattr(source, "vertices") and hasattr(source, "faces"):
        vertices, faces = source.vertices, source.faces
    else:
        try:
            vertices, faces = source
        except (TypeError, ValueError):
            raise MeshError(
                f"object {name!r}: expected a mesh path, a trimesh.Trimesh or (vertices, faces), got {type(source).__name__}"
            ) from None
    vertices = np.array(vertices, dtype=np.float64)
    faces = np.array(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError(f"object {name!r}: vertices must have shape (n, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshError(f"object {name!r}: faces must be a non-empty (m, 3) array of triangles, got {faces.shape}")
    if faces.dtype.kind not in "iu" or faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"object {name!r}: face indices must be integers in [0, {len(vertices)})")
    return vertices, faces.astype(np.int64)


def _merge_duplicate_vertices(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Identify bit-identical vertices (STL stores every triangle's corners separately)."""
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    if len(unique) == len(vertices):
        return vertices, faces
    return unique, inverse.reshape(-1)[faces]


def _check_closed(vertices: np.ndarray, faces: np.ndarray, name: str) -> np.ndarray:
    """Every directed edge must be matched by its reverse; fix inconsistent winding if that is all."""
    odd, unmatched = _edge_balance(faces)
    if odd:
        raise MeshError(
            f"object {name!r} is not watertight: {odd} open edges (edges used by an odd number of "
            "triangles). Close the holes (e.g. trimesh.repair.fill_holes, or export a closed solid) and retry."
        )
    if unmatched == 0:
        return faces
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    trimesh.repair.fix_winding(mesh)
    fixed = np.asarray(mesh.faces, dtype=np.int64)
    left = _edge_balance(fixed)[1]
    if left:
        raise MeshError(
            f"object {name!r}: triangle winding is inconsistent and could not be repaired "
            f"({left} edges traversed twice in the same direction); the surface may be non-orientable"
        )
    warnings.warn(f"object {name!r}: inconsistent triangle winding was repaired", stacklevel=3)
    return fixed


def _edge_balance(faces: np.ndarray) -> tuple[int, int]:
    """(edges used an odd number of times, edges whose two directions are not used equally often)."""
    start = faces.ravel()
    end = faces[:, [1, 2, 0]].ravel()
    lo, hi = np.minimum(start, end), np.maximum(start, end)
    key = lo * (int(faces.max()) + 1) + hi  # one int64 per undirected edge: fast 1-D unique
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    balance = np.bincount(inverse, weights=np.where(start < end, 1.0, -1.0), minlength=len(counts))
    return int(np.count_nonzero(counts % 2)), int(np.count_nonzero(balance))
