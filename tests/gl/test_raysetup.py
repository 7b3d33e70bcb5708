"""xrayraster.gl.rays.view_rays: the float64 per-view ray coefficients the shaders evaluate.

Every check is made against the geometry's definition, computed here: the centre of the pixel at
centred offsets (c', r') is P = d + c'·u + r'·v, a cone-beam ray runs from the source s through P,
and a parallel-beam ray runs through P along the given direction r.
"""

from __future__ import annotations

import numpy as np
import pytest

from references.chords import cone_rays, random_rotation
from xrayraster.core.geometry import ConeBeamGeometry, ParallelBeamGeometry, VectorGeometry
from xrayraster.gl.rays import view_rays


def _unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _random_cone(rng, source_distance, tilt=True):
    """Source at `source_distance` from the origin, detector 50–200 mm beyond, random (tilted) u, v."""
    rot = random_rotation(rng)
    axis = rot[:, 1]  # source → detector direction
    s = -source_distance * axis + rng.normal(size=3) * 2.0
    d = (rng.uniform(50, 200)) * axis + rng.normal(size=3) * 3.0
    if tilt:
        # u, v: random lengths, not orthogonal, detector plane tilted up to ~30° from face-on
        tilt_rot = random_rotation(rng)
        frame = rot @ _small_rotation(tilt_rot, 0.5)
        u = frame[:, 0] * rng.uniform(0.05, 0.5) + frame[:, 2] * rng.uniform(-0.05, 0.05)
        v = frame[:, 2] * rng.uniform(0.05, 0.5) + frame[:, 0] * rng.uniform(-0.05, 0.05)
    else:
        u, v = rot[:, 0] * 0.2, rot[:, 2] * 0.2
    return VectorGeometry("cone", (64, 80), [np.concatenate([s, d, u, v])])


def _small_rotation(rot, fraction):
    """A rotation part-way between identity and `rot` (via its axis-angle), so tilts stay moderate."""
    angle = np.arccos(np.clip((np.trace(rot) - 1) / 2, -1, 1))
    if angle < 1e-12:
        return np.eye(3)
    axis = _unit(np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]]))
    a = fraction * angle
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * (k @ k)


def _random_parallel(rng):
    rot = random_rotation(rng)
    r = rot[:, 1] * rng.uniform(0.5, 3.0)  # not unit length on purpose
    tilt = _small_rotation(random_rotation(rng), 0.5)
    frame = rot @ tilt
    u = frame[:, 0] * rng.uniform(0.05, 0.5) + frame[:, 2] * 0.03
    v = frame[:, 2] * rng.uniform(0.05, 0.5) - frame[:, 0] * 0.02
    d = rng.normal(size=3) * 30.0
    return VectorGeometry("parallel", (64, 80), [np.concatenate([r, d, u, v])])


def _offsets(rng, n=200):
    """Centred pixel offsets: the centre, the corners of a 64×80 detector, and random non-integers."""
    fixed = [(0.0, 0.0), (-39.5, -31.5), (39.5, 31.5), (-39.5, 31.5), (39.5, -31.5), (1.0, 0.0), (0.0, 1.0)]
    rand = np.column_stack([rng.uniform(-60, 60, n), rng.uniform(-50, 50, n)])
    return np.vstack([fixed, rand])  # columns: c', r'


def _evaluate(rays, cr):
    """Ray origin Q − ref, direction and denominators for offsets `cr` (n, 2), per the module docstring."""
    w = np.column_stack([np.ones(len(cr)), cr])  # (1, c', r')
    num = w @ rays.origin_num
    den = w @ rays.origin_den
    return num / den[:, None], w @ rays.direction, den


def _pixel(rays, x, ref):
    h = np.column_stack([x - ref, np.ones(len(x))]) @ rays.world_to_pixel.T
    return h


CONE_CASES = [
    ("near", 150.0, True),
    ("near-face-on", 300.0, False),
    ("far-10m", 10_000.0, True),
]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("name, dist, tilt", CONE_CASES, ids=[c[0] for c in CONE_CASES])
def test_cone_ray_origin_direction_and_pixel_mapping(name, dist, tilt, seed):
    """Cone beam: Q on the source→pixel line and on the plane through ref facing the source; D ∥ (P − s)
    pointing at the detector; world_to_pixel maps P and points on its ray back to (c', r') with h2 > 0."""
    rng = np.random.default_rng(1000 * seed + int(dist))
    vec = _random_cone(rng, dist, tilt)
    s, d, u, v = np.split(vec.array[0], 4)
    ref = rng.normal(size=3) * 20.0
    rays = view_rays(vec, 0, ref)
    cr = _offsets(rng)
    P = d + cr[:, :1] * u + cr[:, 1:] * v  # pixel centres from the definition

    q_rel, D, den = _evaluate(rays, cr)
    Q = ref + q_rel
    to_p = P - s
    line = _unit(to_p)
    # Q on the line from s through P: perpendicular distance, relative to the distance from the source
    dist_from_line = np.linalg.norm(np.cross(Q - s, line), axis=1)
    assert np.all(dist_from_line < 1e-9 * np.linalg.norm(ref - s))
    # ... and on the plane through ref facing the source (normal ref − s)
    n0 = _unit(ref - s)
    assert np.all(np.abs((Q - ref) @ n0) < 1e-9 * np.linalg.norm(ref - s))
    # ... and between the source and the far side (not behind the source)
    assert np.all((Q - s) @ n0 > 0)
    assert np.all(den > 0)

    # direction parallel to P − s and pointing from the source towards the detector
    cos = np.einsum("ij,ij->i", _unit(D), line)
    assert np.all(cos > 1 - 1e-13)

    # world_to_pixel: the pixel centre and points along its ray in front of the source
    for t in (1.0, 1e-3, 0.3, 0.9, 2.5):
        h = _pixel(rays, s + t * to_p, ref)
        assert np.all(h[:, 2] > 0), t
        np.testing.assert_allclose(h[:, 0] / h[:, 2], cr[:, 0], rtol=0, atol=1e-8 * (1 + np.abs(cr[:, 0])).max())
        np.testing.assert_allclose(h[:, 1] / h[:, 2], cr[:, 1], rtol=0, atol=1e-8 * (1 + np.abs(cr[:, 1])).max())
    # behind the source h2 changes sign
    assert np.all(_pixel(rays, s - 0.5 * to_p, ref)[:, 2] < 0)


@pytest.mark.parametrize("seed", range(6))
def test_parallel_ray_origin_direction_and_pixel_mapping(seed):
    """Parallel beam: Q on the line through P along r and on the plane through ref ⊥ r; D ∥ +r;
    world_to_pixel maps any point of that line to (c', r') with h2 == 1."""
    rng = np.random.default_rng(seed)
    vec = _random_parallel(rng)
    r, d, u, v = np.split(vec.array[0], 4)
    rhat = _unit(r)
    ref = rng.normal(size=3) * 20.0
    rays = view_rays(vec, 0, ref)
    cr = _offsets(rng)
    P = d + cr[:, :1] * u + cr[:, 1:] * v

    q_rel, D, den = _evaluate(rays, cr)
    Q = ref + q_rel
    scale = 1.0 + np.linalg.norm(P - ref, axis=1)
    assert np.all(np.linalg.norm(np.cross(Q - P, rhat), axis=1) < 1e-12 * scale)
    assert np.all(np.abs((Q - ref) @ rhat) < 1e-12 * scale)
    np.testing.assert_array_equal(den, 1.0)

    cos = _unit(D) @ rhat
    assert np.all(cos > 1 - 1e-13)

    for t in (0.0, -500.0, 37.5, 2000.0):
        h = _pixel(rays, P + t * rhat, ref)
        np.testing.assert_array_equal(h[:, 2], 1.0)
        np.testing.assert_allclose(h[:, 0], cr[:, 0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(h[:, 1], cr[:, 1], rtol=0, atol=1e-9)


@pytest.mark.parametrize("theta", [0.0, 0.9, -2.4])
def test_circular_cone_directions_match_reference(theta):
    """For a ConeBeamGeometry view, D at every integer pixel equals reference.cone_rays' unit directions."""
    sod, sdd, shape, pixel, offset = 60.0, 140.0, (6, 9), 0.25, (0.4, -1.1)
    vec = ConeBeamGeometry(sod, sdd, shape, pixel, [theta], detector_offset=offset).to_vec()
    rays = view_rays(vec, 0, ref=(1.0, -2.0, 0.5))
    rows, cols = shape
    c = np.arange(cols) - (cols - 1) / 2
    r = np.arange(rows) - (rows - 1) / 2
    cc, rr = np.meshgrid(c, r)  # (rows, cols) like the reference
    cr = np.column_stack([cc.ravel(), rr.ravel()])
    q_rel, D, _ = _evaluate(rays, cr)
    src, dirs = cone_rays(sod, sdd, shape, pixel, theta, offset)
    np.testing.assert_allclose(_unit(D), dirs.reshape(-1, 3), atol=1e-13)
    # Q lies on the reference ray from the source
    Q = np.array([1.0, -2.0, 0.5]) + q_rel
    off = np.cross(Q - src.reshape(-1, 3), dirs.reshape(-1, 3))
    np.testing.assert_allclose(off, 0.0, atol=1e-10)


def test_circular_parallel_direction_and_mapping():
    """ParallelBeamGeometry at θ=π/2: rays along −x; pixel (c', r') at (0, c'·p, r'·p) maps back."""
    p = 0.5
    vec = ParallelBeamGeometry((4, 6), p, [np.pi / 2]).to_vec()
    rays = view_rays(vec, 0, ref=(3.0, 0.0, 0.0))
    np.testing.assert_allclose(_unit(rays.direction[0]), [-1.0, 0.0, 0.0], atol=1e-15)
    cr = np.array([[2.5, -1.5], [-0.5, 0.5]])
    x = np.column_stack([np.full(2, 17.0), cr[:, 0] * p, cr[:, 1] * p])
    h = _pixel(rays, x, np.array([3.0, 0.0, 0.0]))
    np.testing.assert_allclose(h, np.column_stack([cr, np.ones(2)]), atol=1e-12)


def test_far_source_float32_coefficients_keep_scene_scale_error():
    """The point of measuring from ref: with a 10 m source, evaluating Q in float32 errs by ~1e-7 of the
    scene size (tens of mm), far below the ~1e-3 mm a float32 source position would cost."""
    rng = np.random.default_rng(7)
    vec = _random_cone(rng, 10_000.0, True)
    s, d, u, v = np.split(vec.array[0], 4)
    ref = rng.normal(size=3) * 5.0
    rays = view_rays(vec, 0, ref)
    cr = _offsets(rng)
    P = d + cr[:, :1] * u + cr[:, 1:] * v
    num = rays.origin_num.astype(np.float32)
    den = rays.origin_den.astype(np.float32)
    w = np.column_stack([np.ones(len(cr)), cr]).astype(np.float32)
    q32 = (w @ num) / (w @ den)[:, None]  # float32 arithmetic throughout
    assert q32.dtype == np.float32
    Q = ref + q32.astype(np.float64)
    err = np.linalg.norm(np.cross(Q - s, _unit(P - s)), axis=1)
    assert err.max() < 2e-5  # measured ~4e-6; a float32 source position alone costs ~1e-4 here


def test_reference_at_source_is_rejected():
    vec = ConeBeamGeometry(100, 250, (3, 4), 0.5, [0.0]).to_vec()
    with pytest.raises(ValueError):
        view_rays(vec, 0, ref=(0.0, -100.0, 0.0))


def test_view_index_selects_the_view():
    """view_rays(vec, k) uses row k: view 1 of a two-view scan equals view 0 of the one-view subset."""
    g = ConeBeamGeometry(100, 250, (3, 4), 0.5, [0.0, 1.3]).to_vec()
    a = view_rays(g, 1, ref=(1.0, 2.0, 3.0))
    b = view_rays(g[1], 0, ref=(1.0, 2.0, 3.0))
    c = view_rays(g, 0, ref=(1.0, 2.0, 3.0))
    np.testing.assert_array_equal(a.world_to_pixel, b.world_to_pixel)
    assert not np.allclose(a.direction, c.direction)
