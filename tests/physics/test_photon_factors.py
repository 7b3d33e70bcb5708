"""PhotonFactors: every view's per-pixel photon factor, computed once per relative pose, against the
definition written out in float64 (area · cos(incidence) · (1 m / distance)² from the pixel
centres), for circular scans (one pose) and geometries whose views all differ."""

from __future__ import annotations

import numpy as np
import pytest

import xrayraster as xr
from xrayraster.core.geometry import as_vector_geometry, detector_pixel_centres
from xrayraster.physics.photon_factors import PhotonFactors


def definition(geometry, view: int) -> np.ndarray:
    """mm² of fluence-at-1-m each pixel collects, from its centre's position (cone beam)."""
    vec = as_vector_geometry(geometry)
    s, _, u, v = np.split(vec.array[view], 4)
    normal = np.cross(u, v)
    ray = detector_pixel_centres(vec, view) - s
    distance = np.linalg.norm(ray, axis=-1)
    cos = np.abs(ray @ normal) / (np.linalg.norm(normal) * distance)
    return np.linalg.norm(normal) * cos * (1000.0 / distance) ** 2


def moving_detector(views: int) -> xr.VectorGeometry:
    """A cone beam whose detector steps away from the source and shifts sideways from view to view."""
    rows = []
    for k, angle in enumerate(np.linspace(0, np.pi, views, endpoint=False)):
        turn = np.array([np.cos(angle), np.sin(angle), 0.0])
        side = np.array([-np.sin(angle), np.cos(angle), 0.0])
        source = -100.0 * turn
        centre = (150.0 + 2.0 * k) * turn + 0.3 * k * side
        rows.append([*source, *centre, *(0.4 * side), 0.0, 0.0, 0.4])
    return xr.VectorGeometry("cone", (6, 9), rows)


def test_a_circular_scan_has_one_pose_and_every_view_its_factor():
    geometry = xr.ConeBeamGeometry(60.0, 140.0, (12, 16), 0.5, xr.full_circle(801), detector_offset=(0.7, -1.1))
    factors = PhotonFactors(geometry)
    assert factors.distinct == 1
    for view in (0, 1, 200, 400, 800):
        np.testing.assert_allclose(factors(view), definition(geometry, view), rtol=1e-12, atol=0)
    assert factors(800) is factors(0)  # computed once


def test_views_whose_pose_differs_each_get_their_own():
    geometry = moving_detector(7)
    factors = PhotonFactors(geometry)
    assert factors.distinct == 7
    for view in range(7):
        np.testing.assert_allclose(factors(view), definition(geometry, view), rtol=1e-12, atol=0)
    assert not np.allclose(factors(0), factors(6))


def test_the_bytes_do_not_depend_on_the_order_views_are_asked_in():
    geometry = xr.ConeBeamGeometry(100.0, 200.0, (5, 8), 0.3, xr.full_circle(90))
    forward = [PhotonFactors(geometry)(view).copy() for view in range(90)]
    backward = PhotonFactors(geometry)
    for view in reversed(range(90)):
        assert np.array_equal(backward(view), forward[view])


def test_a_shared_factor_cannot_be_written_to():
    factor = PhotonFactors(xr.ConeBeamGeometry(100.0, 200.0, (4, 4), 0.3, xr.full_circle(4)))(2)
    with pytest.raises(ValueError, match="read-only"):
        factor *= 2.0


def test_a_parallel_beam_has_one_pose_and_the_area_times_the_cosine():
    geometry = xr.ParallelBeamGeometry((3, 4), 0.5, xr.full_circle(30))
    factors = PhotonFactors(geometry)
    assert factors.distinct == 1
    np.testing.assert_allclose(factors(17), 0.25, rtol=1e-12)
