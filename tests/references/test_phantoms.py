"""The analytic phantom reference (references/phantoms.py) against independent facts: closed-form chords,
brute-force ray marching, mass conservation, phantom3d's own membership formula, and where the
scanner convention says an off-axis object must appear on the detector."""

from __future__ import annotations

import math

import numpy as np
import pytest

from references.phantoms import (
    _PHANTOM3D_MODIFIED_SHEPP_LOGAN,
    RTK_SHEPP_LOGAN,
    SHEPP_LOGAN_3D,
    Ellipsoid,
    chord_lengths,
    from_phantom3d_row,
    project,
    rtk_shepp_logan,
    shepp_logan_3d,
    sphere,
    voxel_values,
)
from xrayraster.core.geometry import (
    ConeBeamGeometry,
    ParallelBeamGeometry,
    VectorGeometry,
    as_vector_geometry,
    detector_pixel_centres,
)
from xrayraster.core.volume import VolumeGeometry


def test_sphere_chords_closed_form():
    r, centre = 7.5, np.array([1.0, -2.0, 3.0])
    ball = sphere(r, mu=1.0, centre=centre)
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(50, 3)) * rng.uniform(0.01, 100.0, size=(50, 1))  # length must not matter
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    # Through the centre, from a far origin on the line: 2R.
    np.testing.assert_allclose(chord_lengths(ball, centre - 900.0 * unit, dirs), 2 * r, rtol=1e-12)
    # At distance p from the centre: 2·sqrt(R² − p²); beyond R: 0.
    normal = np.cross(unit, rng.normal(size=(50, 3)))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    p = np.linspace(0.0, 1.2 * r, 50)
    origins = centre + p[:, None] * normal + rng.uniform(-500, 500, size=(50, 1)) * unit
    expected = 2 * np.sqrt(np.clip(r**2 - p**2, 0, None))
    np.testing.assert_allclose(chord_lengths(ball, origins, dirs), expected, rtol=1e-9, atol=1e-9)


def _marched_chord(e: Ellipsoid, origin, direction, half_span: float, n: int = 200_000) -> float:
    """Midpoint-rule length of the line inside ``e``: n point samples over ±half_span mm."""
    unit = direction / np.linalg.norm(direction)
    t = (np.arange(n) + 0.5) / n * 2 * half_span - half_span
    pts = origin + t[:, None] * unit
    q = ((pts - np.asarray(e.centre)) @ e.rotation) / np.asarray(e.semi_axes)
    return np.count_nonzero(np.einsum("ij,ij->i", q, q) <= 1.0) * (2 * half_span / n)


@pytest.mark.parametrize(
    "e",
    [
        Ellipsoid((12.0, -7.0, 4.0), (9.0, 4.0, 2.5), phi=0.6, mu=1.0),
        Ellipsoid((-5.0, 3.0, -8.0), (3.0, 8.0, 5.0), phi=-1.1, mu=1.0, theta=0.7, psi=0.4),
    ],
)
def test_rotated_offaxis_ellipsoid_matches_ray_marching(e):
    rng = np.random.default_rng(1)
    centre = np.asarray(e.centre)
    for _ in range(4):
        direction = rng.normal(size=3)
        # A line passing within ~half the smallest semi-axis of the centre, so it surely hits.
        origin = centre + rng.normal(size=3) * 0.5 * min(e.semi_axes) / math.sqrt(3)
        exact = chord_lengths(e, origin, direction)
        assert exact > 1.0
        marched = _marched_chord(e, origin, direction, half_span=2 * max(e.semi_axes))
        assert abs(exact - marched) <= 1e-3 * exact, (exact, marched)


def test_parallel_projection_of_sphere_conserves_mass():
    # Σ pixels × pixel area = ∫∫ line integrals = mu × volume, for every view. The residual is the
    # midpoint rule on a disc with a sqrt-shaped edge: measured 7.6e-4 with 0.25 mm pixels on a
    # 5 mm sphere (tolerance 2e-3), 3e-5 with 4×4 sub-pixel rays (tolerance 2e-4).
    r, mu, px = 5.0, 0.02, 0.25
    ball = sphere(r, mu, centre=(1.0, -2.0, 0.5))
    geom = ParallelBeamGeometry((56, 64), px, angles=(0.0, 0.9, 2.5))
    proj = project([ball], geom)
    assert proj.shape == (3, 56, 64) and proj.dtype == np.float64
    np.testing.assert_allclose(proj.sum(axis=(1, 2)) * px * px, mu * ball.volume, rtol=2e-3)
    fine = project([ball], geom, supersample=4)
    np.testing.assert_allclose(fine.sum(axis=(1, 2)) * px * px, mu * ball.volume, rtol=2e-4)
    # The brightest pixel centre is within half a pixel diagonal (0.18 mm) of the sphere's axis,
    # so its chord is within 6e-4 of the diameter.
    assert proj.max() == pytest.approx(2 * r * mu, rel=1e-3)


def test_supersample_equals_block_mean_of_finer_detector():
    # k×k sub-pixel rays of a pixel are the pixel centres of a k-times finer detector.
    e = Ellipsoid((0.5, 0.0, -0.3), (2.0, 1.2, 0.9), phi=0.4, mu=0.05)
    k = 3
    coarse = ConeBeamGeometry(50.0, 120.0, (7, 9), (0.6, 0.5), angles=(0.3, 2.0))
    fine = ConeBeamGeometry(50.0, 120.0, (7 * k, 9 * k), (0.6 / k, 0.5 / k), angles=(0.3, 2.0))
    got = project([e], coarse, supersample=k)
    want = project([e], fine).reshape(2, 7, k, 9, k).mean(axis=(2, 4))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    # The same for voxels: k³ sub-voxel points are the voxel centres of a k-times finer grid.
    vg = VolumeGeometry((4, 5, 6), (0.7, 0.6, 0.5), offset=(0.1, 0.0, 0.3))
    vfine = VolumeGeometry((4 * k, 5 * k, 6 * k), (0.7 / k, 0.6 / k, 0.5 / k), offset=(0.1, 0.0, 0.3))
    want = voxel_values([e], vfine).reshape(4, k, 5, k, 6, k).mean(axis=(1, 3, 5))
    np.testing.assert_allclose(voxel_values([e], vg, supersample=k), want, rtol=1e-12)


def test_voxelised_sphere_volume():
    # 27 points per voxel on a sphere 10 voxels across: measured 6e-5, tolerance 5e-3.
    r, mu = 4.0, 0.3
    vg = VolumeGeometry((24, 24, 24), 0.4, offset=(0.3, -0.2, 0.1))
    vox = voxel_values([sphere(r, mu, centre=(0.1, -0.2, 0.3))], vg, supersample=3)
    assert vox.sum() * 0.4**3 == pytest.approx(mu * 4 / 3 * math.pi * r**3, rel=5e-3)


def test_shepp_logan_known_points():
    def value_at(x, y, z):
        # A 1-voxel volume whose only voxel centre is (x, y, z).
        return voxel_values(SHEPP_LOGAN_3D, VolumeGeometry((1, 1, 1), 0.01, offset=(z, y, x)))[0, 0, 0]

    assert [e.mu for e in SHEPP_LOGAN_3D] == [1.0, -0.8, -0.2, -0.2, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]
    assert value_at(0, 0, 0) == pytest.approx(0.2)  # skull + brain
    assert value_at(0, 0.9, 0) == pytest.approx(1.0)  # skull only
    assert value_at(0.95, 0, 0) == 0.0 and value_at(0, 0, 0.9) == 0.0  # outside the head
    assert value_at(0, 0.1, 0.25) == pytest.approx(0.3)  # small blob above the centre
    # Ventricle centre, rotated as phantom3d does (see from_phantom3d_row): 1 − 0.8 − 0.2.
    c = 0.22 * np.array([math.cos(math.radians(-8)), math.sin(math.radians(-8))])
    assert value_at(c[0], c[1], 0.0) == pytest.approx(0.0, abs=1e-12)
    assert value_at(c[0], c[1], 0.0) != value_at(0.0, 0.0, 0.0)

    scaled = shepp_logan_3d(radius_mm=50.0, mu_scale_per_mm=0.02)
    origin = VolumeGeometry((1, 1, 1), 1.0)
    assert voxel_values(scaled, origin)[0, 0, 0] == pytest.approx(0.2 * 0.02)
    assert scaled[0].semi_axes == pytest.approx((34.5, 46.0, 40.5))


def _phantom3d_volume(rows, n: int) -> np.ndarray:
    """Schabel's phantom3d.m membership test, transcribed: (z, y, x) grid on linspace(−1, 1, n)."""
    rng = np.linspace(-1, 1, n)
    z, y, x = np.meshgrid(rng, rng, rng, indexing="ij")
    coord = np.stack([x.ravel(), y.ravel(), z.ravel()])
    p = np.zeros(coord.shape[1])
    for A, a, b, c, x0, y0, z0, phi, theta, psi in rows:
        phi, theta, psi = np.radians([phi, theta, psi])
        cphi, sphi, ct, st, cp, sp = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta), np.cos(psi), np.sin(psi)
        alpha = np.array(
            [
                [cp * cphi - ct * sphi * sp, cp * sphi + ct * cphi * sp, sp * st],
                [-sp * cphi - ct * sphi * cp, -sp * sphi + ct * cphi * cp, cp * st],
                [st * sphi, -st * cphi, ct],
            ]
        )
        q = alpha @ coord
        p += A * ((q[0] - x0) ** 2 / a**2 + (q[1] - y0) ** 2 / b**2 + (q[2] - z0) ** 2 / c**2 <= 1)
    return p.reshape(n, n, n)


def test_shepp_logan_matches_phantom3d_formula():
    n = 41
    grid = VolumeGeometry((n, n, n), 2 / (n - 1))  # voxel centres = linspace(−1, 1, n)
    want = _phantom3d_volume(_PHANTOM3D_MODIFIED_SHEPP_LOGAN, n)
    got = voxel_values(SHEPP_LOGAN_3D, grid)
    assert np.count_nonzero(np.abs(got - want) > 1e-12) == 0
    # A made-up row with all three Euler angles non-zero maps just as exactly.
    row = (0.5, 0.5, 0.3, 0.2, 0.1, -0.2, 0.15, 30.0, 40.0, -25.0)
    got = voxel_values([from_phantom3d_row(row)], grid)
    assert np.count_nonzero(got) > 100
    assert np.count_nonzero(np.abs(got - _phantom3d_volume([row], n)) > 1e-12) == 0


def _rtk_quadric_volume(n: int) -> np.ndarray:
    """RTK's membership test for its Shepp–Logan, transcribed from rtk::QuadricShape::SetEllipsoid
    (a quadric A x² + B y² + C z² + E x z − 1 ≤ 0 about the centre, the axes turned about RTK's y),
    in RTK's frame, sampled on our (z, y, x) grid over [−1, 1]: RTK (x, y, z) = (x, z, −y)."""
    table = [  # semi-axes, centre (RTK frame), angle about y (deg), density: RTK's SheppLoganPhantom
        ((0.69, 0.90, 0.92), (0, 0, 0), 0, 2.0), ((0.6624, 0.880, 0.874), (0, 0, 0), 0, -0.98),
        ((0.41, 0.21, 0.16), (-0.22, -0.25, 0), 108, -0.02), ((0.31, 0.22, 0.11), (0.22, -0.25, 0), 72, -0.02),
        ((0.21, 0.50, 0.25), (0, -0.25, 0.35), 0, 0.02), ((0.046, 0.046, 0.046), (0, -0.25, 0.10), 0, 0.02),
        ((0.046, 0.02, 0.023), (-0.08, -0.25, -0.65), 0, 0.01), ((0.046, 0.02, 0.023), (0.06, -0.25, -0.65), 90, 0.01),
        ((0.056, 0.1, 0.04), (0.06, 0.625, -0.105), 90, 0.02), ((0.056, 0.1, 0.056), (0, 0.625, 0.1), 0, -0.02),
    ]
    rng = np.linspace(-1, 1, n)
    z, y, x = np.meshgrid(rng, rng, rng, indexing="ij")
    rx, ry, rz = x, z, -y
    out = np.zeros(x.shape)
    for (a, b, c), (cx, cy, cz), angle, density in table:
        co, si = math.cos(math.radians(angle)), math.sin(math.radians(angle))
        qa = co**2 / a**2 + si**2 / c**2
        qc = si**2 / a**2 + co**2 / c**2
        qe = 2 * co * si * (1 / a**2 - 1 / c**2)
        dx, dy, dz = rx - cx, ry - cy, rz - cz
        out += density * (qa * dx**2 + dy**2 / b**2 + qc * dz**2 + qe * dx * dz <= 1)
    return out


def test_rtk_shepp_logan_matches_rtks_quadrics():
    """RTK's table in our frame (references.phantoms.RTK_SHEPP_LOGAN) against RTK's own quadric
    formula: every point of a 49³ grid, including the two tilted ventricles (the turn's sign)."""
    n = 49
    grid = VolumeGeometry((n, n, n), 2 / (n - 1))
    want = _rtk_quadric_volume(n)
    got = voxel_values(RTK_SHEPP_LOGAN, grid)
    assert set(np.unique(want).round(6)) >= {0.0, 2.0, 1.02, 1.0}
    assert np.count_nonzero(np.abs(got - want) > 1e-9) == 0
    mirrored = [Ellipsoid(e.centre, e.semi_axes, -e.phi, e.mu) for e in RTK_SHEPP_LOGAN]
    assert np.count_nonzero(np.abs(voxel_values(mirrored, grid) - want) > 1e-9) > 10  # the sign matters
    head = rtk_shepp_logan(128.0)
    assert head[0].semi_axes == pytest.approx((0.69 * 128, 0.92 * 128, 0.90 * 128))


def _geometry(theta: float) -> ConeBeamGeometry:
    return ConeBeamGeometry(100.0, 200.0, (65, 65), 0.5, angles=(theta,))


@pytest.mark.parametrize(
    "theta, centre",
    # Magnification 2: the source→centre ray meets the detector 12 pixels along +u and 8 rows
    # towards −z from the middle pixel (32, 32); u = (1,0,0) at θ = 0 and (0,1,0) at θ = π/2.
    [(0.0, (3.0, 0.0, -2.0)), (math.pi / 2, (0.0, 3.0, -2.0))],
)
def test_cone_beam_offaxis_sphere_peaks_where_convention_says(theta, centre):
    proj = project([sphere(2.0, 0.1, centre=centre)], _geometry(theta))[0]
    assert np.unravel_index(np.argmax(proj), proj.shape) == (24, 44)
    assert proj[24, 44] == pytest.approx(2 * 2.0 * 0.1, rel=1e-12)  # the ray through the centre


def test_cone_beam_peak_any_view_and_vector_geometry():
    geom = ConeBeamGeometry(80.0, 150.0, (40, 50), (0.4, 0.3), angles=(0.37, 4.0), detector_offset=(1.1, -2.3))
    vec = as_vector_geometry(geom)
    for view, pixel in enumerate([(9, 37), (30, 6)]):
        s = vec.array[view, :3]
        centre = s + 0.55 * (detector_pixel_centres(vec, view)[pixel] - s)  # on the ray to `pixel`
        ball = sphere(1.5, 0.2, centre=centre)
        proj = project([ball], VectorGeometry("cone", vec.detector_shape, vec.array[view]))[0]
        assert np.unravel_index(np.argmax(proj), proj.shape) == pixel
        np.testing.assert_allclose(proj, project([ball], geom)[view], rtol=1e-12)
