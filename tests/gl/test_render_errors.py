"""Bad input gets an error that names the problem; nothing crashes; memory stays flat."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

import xrayraster as xr


def small_geometry(shape=(16, 16)):
    return xr.ConeBeamGeometry(100.0, 200.0, shape, 0.5, [0.0])


def test_empty_scene(gl):
    with xr.Renderer(small_geometry(), context=gl) as r, pytest.raises(xr.SceneError, match="empty"):
        r.path_lengths(xr.Scene())


def test_open_mesh_is_refused_with_its_name_and_edge_count():
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    with pytest.raises(xr.MeshError, match=r"'lid'.*3 open edges"):
        xr.Scene().add((box.vertices, box.faces[1:]), "c", name="lid")


def test_non_finite_vertices_are_refused():
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    v = np.array(box.vertices)
    v[3, 1] = np.nan
    with pytest.raises(xr.MeshError, match=r"'bad'.*NaN or infinite"):
        xr.Scene().add((v, box.faces), "c", name="bad")


def test_zero_size_detector_is_refused():
    with pytest.raises(xr.GeometryError, match="detector_shape"):
        small_geometry((0, 16))


def test_detector_beyond_the_gl_limit(gl):
    limit = gl.ctx.info["GL_MAX_TEXTURE_SIZE"]
    with pytest.raises(xr.RenderError, match="exceeds this GL driver's limit"):
        xr.Renderer(small_geometry((16, limit + 1)), context=gl)
    with pytest.raises(xr.RenderError, match="supersampling"):
        xr.Renderer(small_geometry((16, limit)), supersampling=2, context=gl)


def test_detector_too_large_for_memory(gl):
    side = gl.ctx.info["GL_MAX_TEXTURE_SIZE"]  # 16384² with crossing lists: far beyond 24 GiB
    with pytest.raises(xr.RenderError, match="GiB"):
        xr.Renderer(small_geometry((side, side)), context=gl)


def test_bad_options_and_views(gl):
    scene = xr.Scene()
    scene.add(trimesh.creation.box((1.0, 1.0, 1.0)), "c")
    with pytest.raises(xr.RenderError, match="supersampling"):
        xr.Renderer(small_geometry(), supersampling=0, context=gl)
    with pytest.raises(xr.RenderError, match="overlap"):
        xr.Renderer(small_geometry(), overlap="peel", context=gl)
    with xr.Renderer(small_geometry(), context=gl) as r, pytest.raises(xr.RenderError, match="view 3"):
        r.path_lengths(scene, view=3)


def test_unknown_gl_backend_is_named():
    with pytest.raises(xr.GLContextError, match="unknown GL backend 'vulkan'"):
        xr.GLContext("vulkan")


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


@pytest.mark.parametrize("overlap, method", [("auto", "nested"), ("resolve", "resolve")])
def test_two_hundred_renders_keep_memory_flat(gl, overlap, method):
    """200 renders in one context (a scene swapped in every 50; one pass with the overlap's term, and
    the per-pixel sort): RSS within 5 %."""
    geom = xr.ConeBeamGeometry(100.0, 200.0, (256, 256), 0.1, xr.full_circle(200))
    scenes = []
    for k in range(4):
        s = xr.Scene()
        s.add(trimesh.creation.icosphere(subdivisions=4, radius=4.0), "a", name="ball")
        s.add(trimesh.creation.box((6.0, 6.0, 6.0)), "b", name="box", transform=xr.Transform.translation((k - 1.5, 0, 0)))
        scenes.append(s)
    rss = []
    with xr.Renderer(geom, context=gl, overlap=overlap) as r:
        for view in range(200):
            out = r.path_lengths(scenes[view // 50], view)
            assert out.shape == (2, 256, 256) and r.last_method == method
            if view in (19, 199):
                rss.append(_rss_bytes())
    assert rss[1] <= 1.05 * rss[0], rss
