"""The CPU backprojection by voxel columns (``backproject_columns`` in shaders/fdk_backproject.cl,
built where PoCL targets AVX-512) against the general kernel and the float64 reference.

It runs by default for upright detectors (every circular orbit) on column-major views: here it
must give the volumes of the general path within 1e-5 of their range, on every scan, through the
volume's edges (tiles past nx, work-groups past ny, a z-chunk past nz), with voxels off the
detector, rows running down the detector, voxels coarser than the pixels and batches that do not
fill a chunk of views. A detector that is not upright (a vector geometry) keeps the general
kernel."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from fdk_cases import BALL, CASES, MU, SMALL_VOLUME, max_rel

import xrayraster as xr
from references.fdk import fdk_reference
from references.phantoms import project, sphere
from xrayraster.recon import fdk_stream as reconstruction
from xrayraster.recon.fdk import FDKStream, fdk

# 37 × 13 × 70 voxels: three tiles of 16 columns along x (the last 5 wide), 13 rows along y
# (work-groups of 16: three work-items idle), 70 planes along z (a second z-chunk of 6); 17.5 mm tall, where the detector
# sees 12 mm at the axis, so the top and bottom groups lie off the detector.
EDGES = xr.VolumeGeometry((70, 13, 37), (0.25, 0.45, 0.4), offset=(0.4, -0.3, 0.2))
COARSE = xr.VolumeGeometry((6, 10, 10), 2.0)  # voxels spanning 5 detector rows
# 64 planes 9.6 mm tall: every voxel column on the detector in every view (the kernel's fast path).
INSIDE = xr.VolumeGeometry((64, 24, 28), (0.15, 0.45, 0.4), offset=(0.8, -0.2, 0.1))


def flipped() -> xr.VectorGeometry:
    """The full scan with the detector's v reversed: rows run down, the row step along z is negative."""
    vec = CASES["full"].to_vec().array.copy()
    vec[:, 9:12] *= -1
    return xr.VectorGeometry("cone", CASES["full"].detector_shape, vec)


GEOMETRIES = {**CASES, "flipped": flipped()}


@functools.cache
def _data(case: str, volume=SMALL_VOLUME):
    g = GEOMETRIES[case]
    p = project([BALL, sphere(2.0, MU / 2, (-3.0, 2.0, -6.5))], g)
    return p, fdk_reference(p, g, volume)


def _built(cl, monkeypatch) -> list:
    """(kernel name, its defines) for every kernel ``cl`` builds from now on."""
    built, kernel = [], cl.kernel

    def recording(source, name, defines=None, optional=False):
        made = kernel(source, name, defines, optional)
        if made is not None:
            built.append((name, dict(defines or {})))
        return made

    monkeypatch.setattr(cl, "kernel", recording)
    return built


def _general(cl, monkeypatch, g, volume, p) -> np.ndarray:
    """The volume from the general kernel (no upright specialisation), on the same device."""
    with monkeypatch.context() as m:
        m.setattr(reconstruction, "UPRIGHT", False)
        built = _built(cl, m)
        data = fdk(p, g, volume, context=cl).data
    assert [name for name, _ in built if name.startswith("backproject")] == ["backproject"]
    assert "UPRIGHT" not in built[-1][1]
    return data


def _columns(cl, monkeypatch, g, volume, p, **options) -> np.ndarray:
    """The volume from the default choice, which must be backproject_columns (skips where the device lacks it)."""
    built = _built(cl, monkeypatch)
    data = fdk(p, g, volume, context=cl, **options).data
    names = [name for name, _ in built if name.startswith("backproject")]
    if "backproject_columns" not in names:
        pytest.skip("this OpenCL device does not build backproject_columns (no AVX-512)")
    assert names[0] == "backproject_columns"
    return data


@pytest.mark.parametrize("case", sorted(set(GEOMETRIES) - {"tilted"}))
def test_columns_equal_the_general_path_and_the_reference(cl, monkeypatch, case):
    g = GEOMETRIES[case]
    p, want = _data(case)
    got = _columns(cl, monkeypatch, g, SMALL_VOLUME, p)
    general = _general(cl, monkeypatch, g, SMALL_VOLUME, p)
    assert np.abs(got - general).max() <= 1e-5 * np.ptp(general)
    assert max_rel(got / 10, want) <= 1e-4


@pytest.mark.parametrize("case", ["full", "flipped"])
@pytest.mark.parametrize("volume", [INSIDE, EDGES, COARSE], ids=["inside", "edges", "coarse"])
def test_columns_inside_at_the_edges_off_the_detector_and_coarse(cl, monkeypatch, case, volume):
    """Whole voxel columns on the detector; tiles, work-groups and z-chunks cut by the volume's
    edges, groups wholly or partly off the detector; rows running down; voxels 5 rows tall (the
    window cannot hold them)."""
    g = GEOMETRIES[case]
    p, want = _data(case, volume)
    got = _columns(cl, monkeypatch, g, volume, p)
    general = _general(cl, monkeypatch, g, volume, p)
    assert np.abs(got - general).max() <= 1e-5 * np.ptp(general)
    assert max_rel(got / 10, want) <= 1e-4


def test_batches_that_do_not_fill_a_chunk_of_views(cl, monkeypatch):
    """Batches of 7 views (chunks of 4: one short chunk a launch) and two slabs give fdk's volume."""
    g = CASES["full"]
    p, _ = _data("full", EDGES)
    whole = _columns(cl, monkeypatch, g, EDGES, p)
    with FDKStream(g, EDGES, context=cl, batch_views=7) as stream:
        for first in range(0, len(p), 7):
            stream.add(first, p[first : first + 7])
        streamed = stream.result().data
    np.testing.assert_allclose(streamed, whole, rtol=0, atol=1e-6 * np.abs(whole).max())
    rows, cols = g.detector_shape
    per_view = rows * cols * 4 + (rows + 2) * (cols + 2) * 4
    sliced = fdk(p, g, EDGES, context=cl, memory_limit=64 * 13 * 37 * 4 + 2 * per_view).data  # slabs of 64 + 6
    np.testing.assert_allclose(sliced, whole, rtol=0, atol=1e-6 * np.abs(whole).max())


def test_a_vector_geometry_keeps_the_general_kernel(cl, monkeypatch):
    """The tilted scanner's detector columns are not parallel to z: the general kernel, and the reference's volume."""
    g = GEOMETRIES["tilted"]
    p, want = _data("tilted")
    built = _built(cl, monkeypatch)
    got = fdk(p, g, SMALL_VOLUME, context=cl).data
    kernels = [(name, defines) for name, defines in built if name.startswith("backproject")]
    assert [name for name, _ in kernels] == ["backproject"] and "UPRIGHT" not in kernels[0][1]
    assert max_rel(got / 10, want) <= 1e-4
