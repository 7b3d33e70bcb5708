"""A scene on the GPU: its triangles and object table as textures, uploaded once and kept for every view.

The crossing engine (:mod:`xrayraster.gl.crossings`) draws from it; the layout is
``shaders/scene.glsl``'s (three RGBA32F texels a triangle, its object's number, channel and
sign in the corners' w) and ``shaders/objects.glsl``'s (an RGBA32UI texel an object, written each view).
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from ..core.errors import RenderError
from ..scene.scene import Scene
from .bindings import TEXTURE_WIDTH
from .context import GLContext


@dataclass
class UploadedScene:
    """A scene uploaded once (vertices relative to ``ref``) and reused for every view.

    Objects are numbered by rank (priority, then insertion), so a resolve pass can compare
    owners by index; every triangle carries its object's number. The scene's overlap terms, when
    uploaded (:meth:`Scene.one_pass`: a one-pass sum with partial overlaps), follow the objects,
    numbered from ``len(ranked)``.
    """

    scene: Scene
    revision: int
    terms: tuple  # OverlapTerms after the objects (empty unless asked for)
    ref: np.ndarray  # (3,) mm: the point all uploaded positions are relative to
    triangles: moderngl.Texture  # 3 RGBA32F texels per triangle: corners (mm, relative to ref); in w: object, channel, sign
    objects: moderngl.Texture  # RGBA32UI per object: channel, drawn in this view, container channel + 1, label
    large: moderngl.Buffer  # indirect draw command + indices of the triangles pass 2 draws
    large_corners: moderngl.Buffer  # the six window-space corners pass 2 draws for each
    ranked: list  # SceneObjects by rank
    channels: np.ndarray  # channel of each object by rank, then of each term (its first member's)
    labels: np.ndarray  # label of each object by rank
    term_rows: np.ndarray  # each term's first member's row (rank) in the object table
    num_channels: int
    num_triangles: int
    fixed_scale: float  # fixed-point units per mm of the sum accumulators
    corners: np.ndarray  # (8, 3) bounding-box corners relative to ref

    def release(self) -> None:
        for buffer in (self.triangles, self.objects, self.large, self.large_corners):
            buffer.release()


def upload_scene(gl: GLContext, scene: Scene, terms: tuple = ()) -> UploadedScene:
    """``scene`` on ``gl``'s GPU, with ``terms`` (its :class:`~xrayraster.scene.overlap_terms.OverlapTerm`
    list) after its objects. Call inside ``gl.current()``."""
    bounds = scene.bounds
    ref = bounds.mean(axis=0)
    materials = scene.materials
    ranked = sorted(scene.objects, key=lambda o: o.rank)
    objects = scene.objects
    meshes = [o.mesh for o in ranked] + [t.mesh for t in terms]
    channels = np.array([materials.index(o.material) for o in ranked]
                        + [materials.index(objects[t.members[0]].material) for t in terms], np.uint32)
    negative = [False] * len(ranked) + [t.sign < 0 for t in terms]
    num_triangles = sum(len(m.faces) for m in meshes)
    texels = texel_rows(3 * num_triangles, 4, np.float32)  # filled in place: no list of copies
    soup = texels[:3 * num_triangles].reshape(num_triangles, 3, 4)
    start = 0
    for number, mesh in enumerate(meshes):
        part = soup[start:start + len(mesh.faces)]
        part[:, :, :3] = (mesh.vertices - ref).astype(np.float32)[mesh.faces]
        part[:, :, 3] = np.array([number, channels[number], negative[number]], np.uint32).view(np.float32)
        start += len(part)
    soup[:] = soup[by_size(soup[:, :, :3])]
    # Fixed point: the largest total (one bounding-box diagonal) must stay below 2^31 units.
    diagonal = float(np.linalg.norm(bounds[1] - bounds[0]))
    fixed_scale = 2.0 ** np.floor(np.log2(2.0**30 / diagonal))
    ctx = gl.ctx
    corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]]) - ref
    position = {o.order: k for k, o in enumerate(ranked)}
    return UploadedScene(
        scene=scene,
        revision=scene.revision,
        terms=terms,
        ref=ref,
        triangles=_texture(gl, texels, "f4", f"the scene's {num_triangles} triangles"),
        objects=_texture(gl, texel_rows(len(meshes), 4, np.uint32), "u4", f"the scene's {len(meshes)} objects"),
        large=ctx.buffer(reserve=4 * (4 + num_triangles)),
        large_corners=ctx.buffer(reserve=6 * 8 * num_triangles),
        ranked=ranked,
        channels=channels,
        labels=np.array([o.label for o in ranked], np.uint32),
        term_rows=np.array([position[t.members[0]] for t in terms], np.intp),
        num_channels=len(materials),
        num_triangles=num_triangles,
        fixed_scale=float(fixed_scale),
        corners=corners,
    )


def _texture(gl: GLContext, texels: np.ndarray, dtype: str, what: str) -> moderngl.Texture:
    """Rows of ``TEXTURE_WIDTH`` texels (:func:`texel_rows`) as a texture read by ``texelFetch``."""
    rows = len(texels) // TEXTURE_WIDTH
    limit = int(gl.ctx.info["GL_MAX_TEXTURE_SIZE"])
    if rows > limit:
        raise RenderError(f"{what} need a texture of {rows} rows of {TEXTURE_WIDTH} texels, more than this GL "
                          f"driver's {limit}: use a coarser mesh or fewer objects")
    texture = gl.ctx.texture((TEXTURE_WIDTH, rows), 4, texels, dtype=dtype)
    texture.filter = (moderngl.NEAREST, moderngl.NEAREST)  # no mipmaps: complete for texelFetch
    return texture


def by_size(corners: np.ndarray) -> np.ndarray:
    """The order of triangles ``(n, 3, 3)`` by their longest edge's largest coordinate span (mm).
    Crossing pass 1 loops over each triangle's pixel box, and the SIMD lanes of a software
    rasteriser (8 triangles at once on llvmpipe) all wait for the longest box among them: with
    triangles of like sizes side by side, a view's pass 1 and 1b took about a tenth less CPU
    (BENCHMARKS.md). Lengths and labels do not depend on the order (each triangle carries its
    object; sums are exact, lists sorted)."""
    size = np.abs(np.roll(corners, 1, axis=1) - corners).max(axis=(1, 2))
    return np.argsort(size, kind="stable")


def texel_rows(count: int, channels: int, dtype) -> np.ndarray:
    """Zeros for ``count`` texels, ``(rows × TEXTURE_WIDTH, channels)``: whole texture rows."""
    rows = max(1, -(-count // TEXTURE_WIDTH))
    return np.zeros((rows * TEXTURE_WIDTH, channels), dtype)
