"""Scenes: closed meshes with a material, a label and a priority, placed in the scanner frame.

Overlap rule (shared by the renderer and the voxelizer): where objects overlap, the object of
highest ``priority`` owns the space; between equal priorities the one added later wins. This is
how yarns displace matrix and a nested object displaces its container.

Objects whose materials compare equal share one output channel, in order of first appearance.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Hashable, Mapping

import numpy as np

from ..core.errors import SceneError
from ..core.transform import Transform
from .mesh import Mesh, load_mesh
from .overlap_terms import NOISE, OverlapTerm, overlap_terms


@dataclass(frozen=True, eq=False)
class SceneObject:
    name: str
    mesh: Mesh
    material: Hashable
    label: int
    priority: float
    order: int  # insertion order: breaks priority ties (later wins)

    @property
    def rank(self) -> tuple[float, int]:
        return (self.priority, self.order)


class Scene:
    """An ordered collection of :class:`SceneObject`; build it with :meth:`add`."""

    def __init__(self):
        self._objects: list[SceneObject] = []
        self.revision = 0  # bumped by every change, so renderers know to re-upload
        self._overlaps: _Overlaps | None = None
        self._nesting: tuple[list[int | None] | None] | None = None  # (result,) once computed
        self._one_pass: tuple[OnePass | None] | None = None

    def add(
        self,
        mesh,
        material: Hashable,
        *,
        label: int | None = None,
        priority: float = 0,
        name: str | None = None,
        transform: Transform | None = None,
        unit_scale: float = 1.0,
    ) -> SceneObject:
        """Add a closed mesh (path, ``trimesh.Trimesh``, ``(vertices, faces)`` or :class:`Mesh`).

        ``label`` defaults to the object's position + 1 (0 is background). ``unit_scale``
        converts mesh units to mm; ``transform`` then places the object in the scanner frame.
        """
        order = len(self._objects)
        taken = {o.name for o in self._objects}
        if name is None:
            name = next(f"object{k}" for k in range(order, order + len(taken) + 1) if f"object{k}" not in taken)
        if name in taken:
            raise SceneError(f"an object named {name!r} is already in the scene; names must be unique")
        try:
            hash(material)
        except TypeError:
            raise SceneError(f"object {name!r}: material must be hashable (a name or a Material)") from None
        label = order + 1 if label is None else label
        if int(label) != label or not 0 < label < 65536:
            raise SceneError(f"object {name!r}: label must be an integer in [1, 65535], got {label!r}")
        if not np.isfinite(priority):
            raise SceneError(f"object {name!r}: priority must be a finite number, got {priority!r}")
        if isinstance(mesh, Mesh) and transform is None and unit_scale == 1.0:
            checked = mesh
        else:
            if isinstance(mesh, Mesh):
                mesh = (mesh.vertices, mesh.faces)
            checked = load_mesh(mesh, name=name, transform=transform, unit_scale=unit_scale)
        obj = SceneObject(name, checked, material, int(label), float(priority), order)
        self._objects.append(obj)
        self.revision += 1
        self._overlaps = None
        self._nesting = None
        self._one_pass = None
        return obj

    def with_materials(self, replaced: Mapping) -> "Scene":
        """A copy whose objects' materials are replaced where ``replaced`` maps them, the meshes shared
        (no mesh is checked again): the same channels in the same order, as the path lengths of this
        scene have them."""
        out = Scene()
        for o in self._objects:
            out.add(o.mesh, replaced.get(o.material, o.material), label=o.label, priority=o.priority, name=o.name)
        if len(out.materials) != len(self.materials):
            raise SceneError("with_materials: two materials became one; the path lengths' channels would not match")
        return out

    @property
    def objects(self) -> tuple[SceneObject, ...]:
        return tuple(self._objects)

    def __len__(self) -> int:
        return len(self._objects)

    @property
    def materials(self) -> tuple[Hashable, ...]:
        """Distinct materials in order of first appearance: the output channels."""
        out: list = []
        for o in self._objects:
            if o.material not in out:
                out.append(o.material)
        return tuple(out)

    def channel(self, obj: SceneObject) -> int:
        return self.materials.index(obj.material)

    @property
    def bounds(self) -> np.ndarray:
        """``(2, 3)`` min/max corners of all objects, mm."""
        self.require_objects()
        b = np.stack([o.mesh.bounds for o in self._objects])
        return np.stack([b[:, 0].min(axis=0), b[:, 1].max(axis=0)])

    @property
    def num_triangles(self) -> int:
        return sum(len(o.mesh.faces) for o in self._objects)

    def require_objects(self) -> None:
        if not self._objects:
            raise SceneError("the scene is empty: add at least one object with Scene.add(mesh, material)")

    def overlaps(self) -> list[tuple[str, str]]:
        """Pairs of objects whose interiors overlap (exact booleans with manifold3d; cached).

        Pairs whose bounding boxes intersect are tested; an intersection volume above 1e-6 of
        the smaller object counts. Those that manifold3d cannot read count as overlapping, so the
        renderer errs on the side of resolving priorities.
        """
        return [(self._objects[o.a].name, self._objects[o.b].name) for o in self._find_overlaps().pairs]

    def nesting(self) -> list[int | None] | None:
        """When every overlap is one object wholly inside another: per object (insertion order),
        the object whose length it subtracts from, or None.

        Then ownership needs no sorting: an object owns its length minus that of the visible
        objects nested directly in it. Each visible object therefore subtracts its length from
        its smallest visible container; an object inside a container that outranks it is
        hidden (its entry is its own index: it contributes nothing). Returns None when some
        overlap is partial (the renderer then resolves per ray). "Wholly inside" allows 1e-6 of
        the object's volume outside, the tolerance of the overlap test; shared boundary faces
        (a yarn cut flush with its matrix block) count as inside.
        """
        if self._nesting is None:
            pairs = self._find_overlaps().pairs
            self._nesting = (None if any(o.inner is None for o in pairs) else _nesting(self._objects, pairs),)
        return self._nesting[0]

    def one_pass(self) -> "OnePass | None":
        """How the scene renders in one pass although some objects overlap partially: the nesting
        of the containments, and the partial overlaps as signed intersection meshes
        (:mod:`~xrayraster.scene.overlap_terms`); None when they cannot stand in for the priority
        rule (then the renderer resolves per ray). Computed once, from the booleans that found the
        overlaps."""
        if self._one_pass is None:
            found = self._find_overlaps()
            if any(o.inner is None and (o.a, o.b) not in found.partial for o in found.pairs):
                self._one_pass = (None,)  # manifold3d could not read an object: no intersection to draw
                return None
            inside = [o for o in found.pairs if o.inner is not None]
            nesting = _nesting(self._objects, inside)
            containers = {o.a if o.inner == o.b else o.b for o in inside}
            terms = overlap_terms([o.rank for o in self._objects], found.partial, found.solids, nesting, containers)
            self._one_pass = (None if terms is None else OnePass(nesting, terms),)
        return self._one_pass[0]

    def _find_overlaps(self) -> "_Overlaps":
        if self._overlaps is None:
            self._overlaps = _find_overlaps(self._objects)
        return self._overlaps


@dataclass(frozen=True)
class OnePass:
    """:meth:`Scene.one_pass`: per object (insertion order) the object whose length it subtracts
    from, or None, or its own index when hidden (as :meth:`Scene.nesting`); and the terms."""

    nesting: list[int | None]
    terms: tuple[OverlapTerm, ...]


def _nesting(objects: list[SceneObject], overlaps: list["_Overlap"]) -> list[int | None]:
    """The containers of :meth:`Scene.nesting`, from ``overlaps`` that are all containments."""
    containers: dict[int, list[int]] = {}
    for o in overlaps:
        containers.setdefault(o.inner, []).append(o.b if o.inner == o.a else o.a)
    volume = [o.mesh.volume for o in objects]
    rank = [o.rank for o in objects]
    hidden = {i for i, outer in containers.items() if any(rank[j] > rank[i] for j in outer)}
    out: list[int | None] = []
    for i in range(len(objects)):
        visible = [j for j in containers.get(i, []) if j not in hidden]
        out.append(i if i in hidden else min(visible, key=lambda j: volume[j], default=None))
    return out


@dataclass(frozen=True)
class _Overlap:
    a: int  # insertion indices, a < b
    b: int
    inner: int | None  # the one wholly inside the other, if either is


@dataclass(frozen=True)
class _Overlaps:
    pairs: list[_Overlap]  # the overlaps above 1e-6 of the smaller object: they pick the method
    partial: dict  # (i, j) -> their intersection (manifold3d), for every partial overlap above NOISE
    solids: list  # each object's manifold3d solid; None where unread (no box overlap) or unreadable


def _find_overlaps(objects: list[SceneObject]) -> _Overlaps:
    bounds = [o.mesh.bounds for o in objects]
    solids: dict[int, object] = {}
    found, partial = [], {}
    for i in range(len(objects)):
        for j in range(i + 1, len(objects)):
            (lo_a, hi_a), (lo_b, hi_b) = bounds[i], bounds[j]
            if np.any(hi_a <= lo_b) or np.any(hi_b <= lo_a):
                continue
            a, b = (_solid(objects[k], solids) for k in (i, j))
            if a is None or b is None:
                found.append(_Overlap(i, j, None))
                continue
            intersection = a ^ b
            shared = intersection.volume()
            small, inner = min((a.volume(), i), (b.volume(), j))
            contains = shared >= (1 - 1e-6) * small
            if shared > 1e-6 * small:
                found.append(_Overlap(i, j, inner if contains else None))
            if shared > NOISE * small and not contains:
                partial[(i, j)] = intersection
    return _Overlaps(found, partial, [solids.get(o.order) for o in objects])


def _solid(obj: SceneObject, cache: dict):
    if obj.order not in cache:
        import manifold3d

        mesh = manifold3d.Mesh(
            vert_properties=np.ascontiguousarray(obj.mesh.vertices, dtype=np.float32),
            tri_verts=np.ascontiguousarray(obj.mesh.faces, dtype=np.uint32),
        )
        solid = manifold3d.Manifold(mesh)
        if solid.status() != manifold3d.Error.NoError:
            warnings.warn(f"object {obj.name!r}: manifold3d cannot read it ({solid.status()}); overlap assumed")
            solid = None
        cache[obj.order] = solid
    return cache[obj.order]
