"""The two crossing paths (compute pass for small triangles, rasteriser for large ones) are both
exact, agree with each other, and meet at shared edges without gaps or double counts."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from references.chords import box_chord, cone_rays, convex_chord, random_rotation

import xrayraster as xr
from xrayraster.gl.crossings import MAX_SMALL_TRIANGLE_PIXELS

ALL_RASTER, DEFAULT, ALL_COMPUTE = 0, None, MAX_SMALL_TRIANGLE_PIXELS  # None: the renderer's own split
N = 160


def convex_scene(rng):
    """Convex meshes with triangles from sub-pixel to hundreds of pixels, slivers and needles."""
    meshes = [
        trimesh.creation.icosphere(subdivisions=3, radius=3.0),  # ~0.5-3 px triangles: both paths
        trimesh.creation.cylinder(radius=1.0, height=14.0, sections=200),  # 14 mm slivers
        trimesh.creation.box((0.05, 0.05, 12.0)),  # a needle
        trimesh.creation.box((6.0, 4.0, 2.0)),  # large faces
    ]
    placed = []
    for k, m in enumerate(meshes):
        t = np.eye(4)
        t[:3, :3] = random_rotation(rng)
        t[:3, 3] = [(-1) ** k * 4.0, (k - 1.5) * 4.0, rng.uniform(-1, 1)]
        placed.append(m.copy().apply_transform(t))
    return placed


def one_material_scene(seed) -> xr.Scene:
    scene = xr.Scene()
    for m in convex_scene(np.random.default_rng(seed)):
        scene.add(m, "m")
    return scene


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_both_paths_are_exact_on_convex_meshes(gl, seed):
    rng = np.random.default_rng(seed)
    meshes = convex_scene(rng)
    theta = rng.uniform(0, 2 * np.pi)
    geom = xr.ConeBeamGeometry(40.0, 100.0, (N, N), 0.2, [theta])
    origins, dirs = cone_rays(40.0, 100.0, (N, N), 0.2, theta)
    exact = sum(convex_chord(origins, dirs, m.vertices, m.faces) for m in meshes)
    scene = xr.Scene()
    for m in meshes:
        scene.add(m, "m")
    results = {}
    for split in (ALL_RASTER, DEFAULT, ALL_COMPUTE):
        options = {} if split is None else {"small_triangle_pixels": split}
        with xr.Renderer(geom, context=gl, **options) as r:
            results[split] = r.path_lengths(scene)[0]
        err = np.abs(results[split] - exact)
        assert np.percentile(err, 99.9) <= 1e-4, split
        assert err.max() <= 1e-3, split
    # The same crossings are summed in exact fixed point: the paths agree to float32 output rounding.
    np.testing.assert_allclose(results[ALL_RASTER], results[ALL_COMPUTE], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(results[DEFAULT], results[ALL_COMPUTE], rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("split", [ALL_RASTER, ALL_COMPUTE])
def test_needles_at_every_orientation(gl, split):
    """Needle boxes (1000:1) at random poses exercise the edge-aligned rectangles of pass 2."""
    rng = np.random.default_rng(7)
    geom = xr.ConeBeamGeometry(50.0, 120.0, (96, 96), 0.25, [0.0])
    origins, dirs = cone_rays(50.0, 120.0, (96, 96), 0.25, 0.0)
    worst = []
    with xr.Renderer(geom, context=gl, small_triangle_pixels=split) as r:
        for _ in range(20):
            rot, centre = random_rotation(rng), rng.uniform(-2, 2, 3)
            half = np.array([0.006, 0.006, 6.0])
            t = np.eye(4)
            t[:3, :3], t[:3, 3] = rot, centre
            scene = xr.Scene()
            scene.add(trimesh.creation.box(2 * half), "n", transform=xr.Transform(t))
            got = r.path_lengths(scene)[0]
            worst.append(np.abs(got - box_chord(origins, dirs, centre, rot, half)).max())
    assert max(worst) <= 1e-3


def test_sums_are_deterministic(gl):
    """Fixed-point accumulation: the same view renders to the same bytes every time."""
    scene = one_material_scene(5)
    geom = xr.ConeBeamGeometry(40.0, 100.0, (N, N), 0.2, [0.4])
    with xr.Renderer(geom, context=gl) as r:
        first = r.path_lengths(scene).tobytes()
        assert all(r.path_lengths(scene).tobytes() == first for _ in range(3))


def test_resolve_agrees_with_sum_on_both_paths(gl):
    rng = np.random.default_rng(11)
    scene = xr.Scene()
    for k, m in enumerate(convex_scene(rng)):
        scene.add(m, f"m{k % 2}")
    geom = xr.ConeBeamGeometry(40.0, 100.0, (N, N), 0.2, [1.0])
    outs = []
    for split in (ALL_RASTER, ALL_COMPUTE):
        for overlap in ("sum", "resolve"):
            with xr.Renderer(geom, context=gl, small_triangle_pixels=split, overlap=overlap) as r:
                outs.append(r.path_lengths(scene))
    for out in outs[1:]:
        np.testing.assert_allclose(out, outs[0], atol=2e-5)


@pytest.mark.parametrize("split", [-1, MAX_SMALL_TRIANGLE_PIXELS + 1, 2.5])
def test_bad_split_is_refused(gl, split):
    geom = xr.ConeBeamGeometry(40.0, 100.0, (8, 8), 0.2, [0.0])
    with pytest.raises(xr.RenderError, match="small_triangle_pixels must be an integer from 0 to 16384"):
        xr.Renderer(geom, context=gl, small_triangle_pixels=split)


def test_triangle_pass_spans_two_dispatch_dimensions(gl):
    """Scenes beyond 65535 × 64 triangles (or candidate entries) need a 2-D dispatch; force both
    passes into one with a tiny row limit."""
    scene = one_material_scene(2)
    geom = xr.ConeBeamGeometry(40.0, 100.0, (N, N), 0.2, [0.2])
    with xr.Renderer(geom, context=gl) as r:
        want = r.path_lengths(scene)
        r.engine._max_groups = 7  # 2,104 triangles: 33 groups in rows of 7, the last row partly empty
        assert scene.num_triangles > 7 * 64 * 2
        np.testing.assert_array_equal(r.path_lengths(scene), want)


@pytest.mark.parametrize("overlap", ["sum", "resolve"])
def test_a_full_candidate_buffer_grows_and_the_view_runs_again(gl, overlap):
    """Pass 1 lists more candidates than its buffer holds: nothing of the cut-short run stays
    (its sums, or its list nodes), and the lengths are the same bytes as with room to spare."""
    scene = one_material_scene(4)
    geom = xr.ConeBeamGeometry(40.0, 100.0, (N, N), 0.2, [0.7])
    with xr.Renderer(geom, context=gl, overlap=overlap) as r:
        engine = r.engine

        def nodes():  # crossing-list nodes taken in the view
            with gl.current():
                return np.frombuffer(engine._buffers["stripes"].read(), np.uint32).sum()

        want = r.path_lengths(scene)
        crossings = nodes() if overlap == "resolve" else None
        engine._candidate_capacity = 1000  # about a fifth of what the view lists: crossings are cut short
        got = r.path_lengths(scene)
        assert engine._candidate_capacity > 4000
        assert overlap == "sum" or nodes() == crossings
    np.testing.assert_array_equal(got, want)
    assert want.max() > 5.0  # the spheres, slivers and boxes were drawn
