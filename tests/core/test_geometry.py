"""xrayraster.core.geometry: frame conventions, value semantics, indexing and validation.

Expected positions are written out by hand from the conventions in the module docstring
(source at R_z(θ)·(0, −SOD, 0), detector centre at R_z(θ)·(0, SDD − SOD, 0), u = R_z(θ)·(pu, 0, 0),
v = (0, 0, pv), offsets (row, col) along v and u), or come from references/chords.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import xrayraster as xr
from references.chords import cone_rays, parallel_rays
from xrayraster.core.geometry import (
    ConeBeamGeometry,
    GeometryError,
    ParallelBeamGeometry,
    VectorGeometry,
    detector_pixel_centres,
    full_circle,
)
from xrayraster.core.volume import VolumeGeometry

NAMESPACE = {name: getattr(xr, name) for name in xr.__all__}  # what `from xrayraster import *` gives a user

# The geometry of the hand-derived convention tests: rows 3, cols 4, pixel (row 0.5, col 0.25),
# offset (row 1.0, col 2.0).
HAND = dict(detector_shape=(3, 4), pixel_size=(0.5, 0.25), angles=[0.0, math.pi / 2], detector_offset=(1.0, 2.0))


def _split(row):
    row = np.asarray(row, dtype=np.float64)
    return row[0:3], row[3:6], row[6:9], row[9:12]


# --------------------------------------------------------------------------- conventions


def test_cone_to_vec_at_zero_and_quarter_turn_by_hand():
    """θ=0: source on −y, detector on +y, u=+x, v=+z, offsets along u (col) and v (row); θ=π/2 rotated CCW."""
    vec = ConeBeamGeometry(source_to_origin=100, source_to_detector=250, **HAND).to_vec()
    assert vec.beam == "cone"
    assert vec.detector_shape == (3, 4)
    assert vec.array.shape == (2, 12)
    s, d, u, v = _split(vec.vectors[0])
    np.testing.assert_allclose(s, [0.0, -100.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(d, [2.0, 150.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(u, [0.25, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(v, [0.0, 0.0, 0.5], atol=1e-12)
    # R_z(π/2): (x, y) -> (−y, x)
    s, d, u, v = _split(vec.vectors[1])
    np.testing.assert_allclose(s, [100.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(d, [-150.0, 2.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(u, [0.0, 0.25, 0.0], atol=1e-12)
    np.testing.assert_allclose(v, [0.0, 0.0, 0.5], atol=1e-12)


def test_a_source_offset_moves_the_source_in_its_plane_and_leaves_the_detector():
    """source_offset (row, col) mm moves the source along v and u, as RTK's SourceOffsetY/X do: by
    hand at θ = 0 and π/2; the detector is where it is without the offset."""
    plain = ConeBeamGeometry(source_to_origin=100, source_to_detector=250, **HAND).to_vec().array
    vec = ConeBeamGeometry(source_to_origin=100, source_to_detector=250, source_offset=(15.0, 20.0), **HAND).to_vec()
    np.testing.assert_allclose(_split(vec.vectors[0])[0], [20.0, -100.0, 15.0], atol=1e-12)
    np.testing.assert_allclose(_split(vec.vectors[1])[0], [100.0, 20.0, 15.0], atol=1e-12)
    np.testing.assert_array_equal(vec.array[:, 3:], plain[:, 3:])


def test_parallel_to_vec_at_zero_and_quarter_turn_by_hand():
    """Parallel beam: ray (0,1,0) at θ=0, (−1,0,0) at π/2; detector centre is the offset only."""
    vec = ParallelBeamGeometry(**HAND).to_vec()
    assert vec.beam == "parallel"
    r, d, u, v = _split(vec.vectors[0])
    np.testing.assert_allclose(r, [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(d, [2.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(u, [0.25, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(v, [0.0, 0.0, 0.5], atol=1e-12)
    r, d, u, v = _split(vec.vectors[1])
    np.testing.assert_allclose(r, [-1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(d, [0.0, 2.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(u, [0.0, 0.25, 0.0], atol=1e-12)
    np.testing.assert_allclose(v, [0.0, 0.0, 0.5], atol=1e-12)


@pytest.mark.parametrize("theta", [0.7, -2.1, 4.0])
def test_cone_to_vec_at_generic_angle(theta):
    """At any θ the rows are the θ=0 vectors turned counter-clockwise about z (explicit cos/sin)."""
    c, s_ = math.cos(theta), math.sin(theta)

    def rz(x, y, z):
        return [x * c - y * s_, x * s_ + y * c, z]

    vec = ConeBeamGeometry(source_to_origin=60, source_to_detector=140, angles=[theta], **{k: HAND[k] for k in ("detector_shape", "pixel_size", "detector_offset")}).to_vec()
    s, d, u, v = _split(vec.vectors[0])
    np.testing.assert_allclose(s, rz(0, -60, 0), atol=1e-12)
    np.testing.assert_allclose(d, np.add(rz(0, 80, 0), rz(2.0, 0, 1.0)), atol=1e-12)
    np.testing.assert_allclose(u, rz(0.25, 0, 0), atol=1e-12)
    np.testing.assert_allclose(v, [0, 0, 0.5], atol=1e-12)


def test_scalar_pixel_size_means_square_pixels():
    """A single pixel_size number gives |u| = |v| = that size."""
    g = ConeBeamGeometry(100, 250, (3, 4), 0.3, [0.0])
    assert g.pixel_size == (0.3, 0.3)
    _, _, u, v = _split(g.to_vec().vectors[0])
    assert np.linalg.norm(u) == pytest.approx(0.3, rel=1e-15)
    assert np.linalg.norm(v) == pytest.approx(0.3, rel=1e-15)


def test_pixel_centres_by_hand_at_zero():
    """Pixel (r, c) centre = d + (c − 1.5)·u + (r − 1)·v for a 3×4 detector: corners and one inner pixel."""
    vec = ConeBeamGeometry(source_to_origin=100, source_to_detector=250, **HAND).to_vec()
    p = detector_pixel_centres(vec, 0)
    assert p.shape == (3, 4, 3)
    np.testing.assert_allclose(p[0, 0], [2.0 - 1.5 * 0.25, 150.0, 1.0 - 0.5], atol=1e-12)
    np.testing.assert_allclose(p[0, 3], [2.0 + 1.5 * 0.25, 150.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(p[2, 0], [1.625, 150.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(p[1, 2], [2.125, 150.0, 1.0], atol=1e-12)


def test_pixel_centres_match_docstring_formula_for_tilted_vector_geometry():
    """detector_pixel_centres == d + (c − (ncol−1)/2)·u + (r − (nrow−1)/2)·v, looped pixel by pixel."""
    rng = np.random.default_rng(1)
    rows = rng.normal(size=(2, 12))
    rows[:, 0:3] = [0.0, -300.0, 0.0]
    rows[:, 3:6] = [5.0, 200.0, -3.0]
    vec = VectorGeometry("cone", (5, 6), rows)
    for view in range(2):
        s, d, u, v = _split(rows[view])
        got = detector_pixel_centres(vec, view)
        for r in range(5):
            for c in range(6):
                np.testing.assert_allclose(got[r, c], d + (c - 2.5) * u + (r - 2.0) * v, rtol=0, atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, 0.4, 2.0, -1.3])
def test_pixel_centres_agree_with_reference_cone_rays(theta):
    """Directions from the source to every pixel centre equal reference.cone_rays (independent construction)."""
    sod, sdd, shape, pixel, offset = 60.0, 140.0, (5, 7), 0.3, (0.6, -0.9)
    vec = ConeBeamGeometry(sod, sdd, shape, pixel, [theta], detector_offset=offset).to_vec()
    s = np.asarray(vec.vectors[0][0:3])
    centres = detector_pixel_centres(vec, 0)
    d = centres - s
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    ref_src, ref_dirs = cone_rays(sod, sdd, shape, pixel, theta, offset)
    np.testing.assert_allclose(ref_src[0, 0], s, atol=1e-12)
    np.testing.assert_allclose(d, ref_dirs, atol=1e-13)


@pytest.mark.parametrize("theta", [0.0, 1.1, 3.5])
def test_parallel_pixel_centres_lie_on_reference_parallel_rays(theta):
    """Each pixel centre is on the matching reference.parallel_rays line, and the ray direction agrees."""
    shape, pixel = (4, 5), 0.7
    vec = ParallelBeamGeometry(shape, pixel, [theta]).to_vec()
    ray = np.asarray(vec.vectors[0][0:3])
    origins, dirs = parallel_rays(shape, pixel, theta)
    np.testing.assert_allclose(ray, dirs[0, 0], atol=1e-13)
    off_line = np.cross(detector_pixel_centres(vec, 0) - origins, dirs)
    np.testing.assert_allclose(off_line, 0.0, atol=1e-10)


# --------------------------------------------------------------------------- value semantics


def _examples():
    return [
        ConeBeamGeometry(100, 250, (3, 4), (0.5, 0.25), [0.0, 1.0], detector_offset=(1.0, 2.0)),
        ConeBeamGeometry(600, 1200, (3, 4), 4.0, [0.0, 1.0], source_offset=(15.0, 20.0)),
        ConeBeamGeometry(
            np.float64(60.5),
            np.float32(140.25),
            (np.int64(512), np.int32(256)),
            np.float32(0.1),
            np.linspace(0, 2, 5, dtype=np.float32),
            detector_offset=np.float32(0.3),
        ),
        ParallelBeamGeometry(np.array([7, 9], dtype=np.int64), (0.1, np.float64(0.2)), np.float32([0.5, 1.5])),
        VectorGeometry("cone", (np.int64(2), 3), np.arange(24, dtype=np.float32).reshape(2, 12) + np.float32(0.1) * np.eye(2, 12, 7)),
        VectorGeometry("parallel", (4, 4), [0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
        VolumeGeometry(np.array([4, 5, 6]), np.float32(0.0289), offset=np.array([1.0, -2.0, 0.5], dtype=np.float32)),
        VolumeGeometry((np.int64(3), 3, 3), (1, 2, 3)),
    ]


@pytest.mark.parametrize("g", _examples(), ids=lambda g: type(g).__name__)
def test_eval_repr_round_trip(g):
    """eval(repr(g)) == g, also when built from numpy scalars/arrays."""
    back = eval(repr(g), NAMESPACE)
    assert type(back) is type(g)
    assert back == g
    assert repr(back) == repr(g)


def _leaves(x):
    if isinstance(x, tuple):
        for item in x:
            yield from _leaves(item)
    else:
        yield x


@pytest.mark.parametrize("g", _examples(), ids=lambda g: type(g).__name__)
def test_fields_are_plain_python_types(g):
    """numpy inputs are normalised: tuples of plain int/float (repr shows no np.float32(...))."""
    for name, value in vars(g).items():
        if name == "beam":
            assert type(value) is str
            continue
        if name in ("source_to_origin", "source_to_detector"):
            assert type(value) is float, name
            continue
        assert isinstance(value, tuple), name
        for leaf in _leaves(value):
            expected = int if name in ("detector_shape", "shape") else float
            assert type(leaf) is expected, (name, leaf)
    assert "np." not in repr(g) and "array" not in repr(g)


def test_numpy_inputs_keep_their_values():
    """Normalising numpy scalars keeps the exact value (float32 angle 0.3 stays float32(0.3) in float64)."""
    g = ConeBeamGeometry(100, 250, (np.int64(3), np.int64(4)), 0.5, np.float32([0.3]))
    assert g.detector_shape == (3, 4)
    assert g.angles == (float(np.float32(0.3)),)


def test_geometries_are_immutable_and_hashable():
    """Frozen values: assigning raises, equal geometries hash equal."""
    a = ConeBeamGeometry(100, 250, (3, 4), 0.5, [0.0, 1.0])
    b = ConeBeamGeometry(100.0, 250.0, [3, 4], (0.5, 0.5), (0.0, 1.0))
    assert a == b and hash(a) == hash(b)
    with pytest.raises(AttributeError):
        a.source_to_origin = 1.0
    assert a != ConeBeamGeometry(100, 250, (3, 4), 0.5, [0.0, 1.1])


# --------------------------------------------------------------------------- indexing

ANGLES = [0.0, 0.1, 0.2, 0.3]


@pytest.mark.parametrize(
    "index, expected",
    [
        (1, [0.1]),
        (np.int64(2), [0.2]),
        (-1, [0.3]),
        (slice(1, 3), [0.1, 0.2]),
        (slice(None, None, -2), [0.3, 0.1]),
        ([0, 2], [0.0, 0.2]),
        (np.array([3, 0]), [0.3, 0.0]),
        (np.array([True, False, True, True]), [0.0, 0.2, 0.3]),
        ([False, True, False, False], [0.1]),
    ],
)
def test_indexing_selects_views(index, expected):
    """g[int | slice | int array | bool mask] keeps the chosen angles in order and every other field."""
    g = ConeBeamGeometry(100, 250, (3, 4), (0.5, 0.25), ANGLES, detector_offset=(1.0, 2.0))
    sub = g[index]
    assert type(sub) is ConeBeamGeometry
    assert sub.angles == tuple(expected)
    assert len(sub) == sub.num_views == len(expected)
    assert (sub.source_to_origin, sub.source_to_detector, sub.detector_shape, sub.pixel_size, sub.detector_offset) == (
        100.0,
        250.0,
        (3, 4),
        (0.5, 0.25),
        (1.0, 2.0),
    )


@pytest.mark.parametrize("make", [ConeBeamGeometry, ParallelBeamGeometry], ids=["cone", "parallel"])
def test_to_vec_row_k_equals_to_vec_of_view_k(make):
    """g.to_vec()[k] == g[k].to_vec() for every view, and the vector geometry indexes the same way."""
    args = (100, 250) if make is ConeBeamGeometry else ()
    g = make(*args, (3, 4), (0.5, 0.25), full_circle(5, 0.2), detector_offset=(1.0, 2.0))
    vec = g.to_vec()
    assert len(vec) == 5
    for k in range(5):
        assert vec[k] == g[k].to_vec()
        assert vec[k].vectors == (vec.vectors[k],)
    assert vec[[4, 1]].vectors == (vec.vectors[4], vec.vectors[1])
    assert vec[1:3] == g[1:3].to_vec()


def test_vector_geometry_bool_mask():
    """A boolean mask over a VectorGeometry keeps the True rows."""
    rows = np.zeros((3, 12))
    rows[:, 1] = [-10, -20, -30]
    rows[:, 4] = 50
    rows[:, 6] = 1
    rows[:, 11] = 1
    vec = VectorGeometry("cone", (2, 2), rows)
    sub = vec[np.array([True, False, True])]
    assert [row[1] for row in sub.vectors] == [-10.0, -30.0]


# --------------------------------------------------------------------------- validation

CONE = dict(source_to_origin=100, source_to_detector=250, detector_shape=(3, 4), pixel_size=(0.5, 0.25), angles=[0.0, 1.0])


@pytest.mark.parametrize(
    "change, field",
    [
        ({"source_to_origin": 0}, r"^source_to_origin\b"),
        ({"source_to_origin": -5.0}, r"^source_to_origin\b"),
        ({"source_to_origin": float("nan")}, r"^source_to_origin\b"),
        ({"source_to_origin": float("inf")}, r"^source_to_origin\b"),
        ({"source_to_origin": "far"}, r"^source_to_origin\b"),
        ({"source_to_detector": 100}, r"^source_to_detector\b"),
        ({"source_to_detector": 50}, r"^source_to_detector\b"),
        ({"source_to_detector": -250}, r"^source_to_detector\b"),
        ({"source_to_detector": float("nan")}, r"^source_to_detector\b"),
        ({"source_to_detector": float("inf")}, r"^source_to_detector\b"),
        ({"detector_shape": (0, 5)}, r"^detector_shape\[0\]"),
        ({"detector_shape": (3, -1)}, r"^detector_shape\[1\]"),
        ({"detector_shape": (2.5, 4)}, r"^detector_shape\[0\]"),
        ({"detector_shape": (3,)}, r"^detector_shape\b"),
        ({"detector_shape": (3, 4, 5)}, r"^detector_shape\b"),
        ({"pixel_size": 0}, r"^pixel_size\[0\]"),
        ({"pixel_size": (0.5, 0)}, r"^pixel_size\[1\]"),
        ({"pixel_size": (0.5, -0.1)}, r"^pixel_size\[1\]"),
        ({"pixel_size": (0.5, float("nan"))}, r"^pixel_size\[1\]"),
        ({"pixel_size": (0.1, 0.2, 0.3)}, r"^pixel_size\b"),
        ({"angles": []}, r"^angles\b"),
        ({"angles": [0.0, float("nan")]}, r"^angles\b"),
        ({"angles": [0.0, float("inf")]}, r"^angles\b"),
        ({"angles": [[0.0, 1.0], [2.0, 3.0]]}, r"^angles\b"),
        ({"detector_offset": (float("nan"), 0.0)}, r"^detector_offset\[0\]"),
        ({"detector_offset": (1.0, 2.0, 3.0)}, r"^detector_offset\b"),
        ({"source_offset": (0.0, float("nan"))}, r"^source_offset\[1\]"),
        ({"source_offset": "left"}, r"^source_offset\b"),
    ],
)
def test_cone_validation_names_the_field(change, field):
    """Each bad field raises GeometryError (a ValueError) whose message starts with that field's name."""
    with pytest.raises(GeometryError, match=field):
        ConeBeamGeometry(**{**CONE, **change})
    assert issubclass(GeometryError, ValueError)


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_non_finite_detector_shape_names_the_field(bad):
    """detector_shape=(nan|inf, 4) must be a GeometryError that names detector_shape, like (2.5, 4) is."""
    with pytest.raises(GeometryError, match=r"^detector_shape\[0\]"):
        ConeBeamGeometry(**{**CONE, "detector_shape": (bad, 4)})


def test_valid_cone_is_accepted():
    """Control for the validation table: the unchanged base arguments construct."""
    g = ConeBeamGeometry(**CONE)
    assert g.num_views == 2


@pytest.mark.parametrize(
    "change, field",
    [
        ({"detector_shape": (0, 5)}, r"^detector_shape\[0\]"),
        ({"pixel_size": 0}, r"^pixel_size\[0\]"),
        ({"angles": []}, r"^angles\b"),
        ({"angles": [float("nan")]}, r"^angles\b"),
        ({"detector_offset": (0.0, float("inf"))}, r"^detector_offset\[1\]"),
    ],
)
def test_parallel_validation_names_the_field(change, field):
    """ParallelBeamGeometry validates the same shared fields with named errors."""
    base = dict(detector_shape=(3, 4), pixel_size=0.5, angles=[0.0])
    with pytest.raises(GeometryError, match=field):
        ParallelBeamGeometry(**{**base, **change})


def _cone_row(s=(0, -100, 0), d=(0, 150, 0), u=(1, 0, 0), v=(0, 0, 1)):
    return np.concatenate([s, d, u, v]).astype(np.float64)


@pytest.mark.parametrize(
    "beam, vectors, pattern",
    [
        ("cone", np.zeros((2, 11)), r"^vectors\b"),
        ("cone", np.zeros((0, 12)), r"^vectors\b"),
        ("cone", np.zeros((2, 3, 12)), r"^vectors\b"),
        ("cone", np.where(np.arange(12) == 4, np.nan, _cone_row()), r"^vectors\b"),
        ("cone", np.where(np.arange(12) == 0, np.inf, _cone_row()), r"^vectors\b"),
        ("cone", _cone_row(v=(2, 0, 0)), r"^vectors\b.*u and v"),
        ("cone", _cone_row(u=(0, 0, 0)), r"^vectors\b.*u and v"),
        ("cone", _cone_row(s=(5, 150, 3)), r"^vectors\b.*source"),
        ("cone", np.stack([_cone_row(), _cone_row(s=(-7, 150, 0))]), r"^vectors\b.*source"),
        ("parallel", _cone_row(s=(1, 0, 0), d=(0, 0, 0)), r"^vectors\b.*ray"),
        ("parallel", _cone_row(s=(0, 0, 0), d=(0, 0, 0)), r"^vectors\b"),
        ("fan", _cone_row(), r"^beam\b"),
    ],
    ids=[
        "11-columns",
        "no-views",
        "3-d",
        "nan",
        "inf",
        "u-parallel-v",
        "u-zero",
        "source-in-plane",
        "source-in-plane-view-1",
        "ray-in-plane",
        "ray-zero",
        "bad-beam",
    ],
)
def test_vector_geometry_validation(beam, vectors, pattern):
    """Bad vector rows raise GeometryError naming `vectors` (and which check), bad beam names `beam`."""
    with pytest.raises(GeometryError, match=pattern):
        VectorGeometry(beam, (3, 4), vectors)


def test_vector_geometry_bad_detector_shape():
    with pytest.raises(GeometryError, match=r"^detector_shape\[1\]"):
        VectorGeometry("cone", (3, 0), _cone_row())


def _tilted_plane():
    d = np.array([0.3, 150.7, -0.9])
    u = np.array([0.21, 0.13, 0.05])
    v = np.array([-0.07, 0.11, 0.29])
    return d, u, v


@pytest.mark.parametrize("a, b", [(0.3, 0.8), (3.0, -7.0), (0.7, 0.45)])
def test_parallel_ray_in_tilted_detector_plane_is_rejected(a, b):
    """A ray r = a·u + b·v (in the plane up to float rounding) is rejected for a tilted detector."""
    d, u, v = _tilted_plane()
    r = a * u + b * v
    if (a, b) != (0.3, 0.8):  # these leave a rounding residual, so an exact-zero test would miss them
        assert np.dot(np.cross(u, v), r) != 0.0
    with pytest.raises(GeometryError, match=r"^vectors\b.*ray"):
        VectorGeometry("parallel", (3, 4), np.concatenate([r, d, u, v]))


def test_source_in_tilted_detector_plane_is_rejected():
    """s = d + 0.1u + 0.2v lies in the detector plane (height ~1e-15 from rounding): must be rejected."""
    d, u, v = _tilted_plane()
    with pytest.raises(GeometryError, match=r"^vectors\b.*source"):
        VectorGeometry("cone", (3, 4), np.concatenate([d + 0.1 * u + 0.2 * v, d, u, v]))


def test_valid_tilted_vector_geometries_are_accepted():
    """Controls: a source 1 mm off the tilted plane and an oblique parallel ray are valid."""
    d, u, v = _tilted_plane()
    n = np.cross(u, v)
    n /= np.linalg.norm(n)
    assert len(VectorGeometry("cone", (3, 4), np.concatenate([d + 0.1 * u + 0.2 * v - n, d, u, v]))) == 1
    assert len(VectorGeometry("parallel", (3, 4), np.concatenate([0.3 * u + 0.8 * v + 0.01 * n, d, u, v]))) == 1


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"shape": (2, 3)}, r"^shape\b"),
        ({"shape": (2, 3, 4, 5)}, r"^shape\b"),
        ({"shape": (0, 3, 4)}, r"^shape\[0\]"),
        ({"shape": (2, 3, 1.5)}, r"^shape\[2\]"),
        ({"shape": (2, -3, 4)}, r"^shape\[1\]"),
        ({"voxel_size": 0}, r"^voxel_size\[0\]"),
        ({"voxel_size": -0.5}, r"^voxel_size\[0\]"),
        ({"voxel_size": (1.0, float("nan"), 1.0)}, r"^voxel_size\[1\]"),
        ({"voxel_size": (1.0, 1.0, float("inf"))}, r"^voxel_size\[2\]"),
        ({"voxel_size": (1.0, 1.0)}, r"^voxel_size\b"),
        ({"offset": (0.0, 0.0)}, r"^offset\b"),
        ({"offset": (0.0, float("inf"), 0.0)}, r"^offset\[1\]"),
    ],
)
def test_volume_validation_names_the_field(kwargs, pattern):
    base = dict(shape=(2, 3, 4), voxel_size=1.0)
    with pytest.raises(GeometryError, match=pattern):
        VolumeGeometry(**{**base, **kwargs})


# --------------------------------------------------------------------------- full_circle


@pytest.mark.parametrize("n, start", [(1, 0.0), (4, 0.0), (7, 0.25), (801, -1.0)])
def test_full_circle(n, start):
    """n angles from `start`, spacing 2π/n, the end point start + 2π excluded."""
    a = np.array(full_circle(n, start))
    assert a.shape == (n,)
    assert a[0] == start
    np.testing.assert_allclose(np.diff(a), 2 * math.pi / n, rtol=1e-12)
    assert a[-1] == pytest.approx(start + 2 * math.pi * (n - 1) / n, rel=1e-14, abs=1e-14)
    assert a[-1] < start + 2 * math.pi - 0.5 * (2 * math.pi / n)


def test_full_circle_four_views_by_hand():
    assert full_circle(4) == pytest.approx((0.0, math.pi / 2, math.pi, 3 * math.pi / 2), abs=1e-15)
    assert all(type(x) is float for x in full_circle(np.int64(3), np.float32(0.5)))


@pytest.mark.parametrize("n", [0, -3, 2.5])
def test_full_circle_rejects_bad_count(n):
    with pytest.raises(GeometryError, match="num_views"):
        full_circle(n)


# --------------------------------------------------------------------------- VolumeGeometry


def test_axis_centres_odd_and_even_with_offset():
    """(index − (n−1)/2)·voxel + offset, written out: n=3 (odd) on z, n=4 and n=5 on y and x."""
    g = VolumeGeometry((3, 4, 5), (0.5, 1.0, 2.0), offset=(10.0, -1.0, 0.5))
    np.testing.assert_allclose(g.axis_centres(0), [9.5, 10.0, 10.5], atol=1e-12)
    np.testing.assert_allclose(g.axis_centres(1), [-2.5, -1.5, -0.5, 0.5], atol=1e-12)
    np.testing.assert_allclose(g.axis_centres(2), [-3.5, -1.5, 0.5, 2.5, 4.5], atol=1e-12)


def test_axis_centres_without_offset_straddle_origin():
    """No offset: odd n has a voxel centred on 0, even n has 0 on a voxel boundary."""
    g = VolumeGeometry((5, 4, 1), 0.25)
    np.testing.assert_allclose(g.axis_centres(0), [-0.5, -0.25, 0.0, 0.25, 0.5], atol=1e-15)
    np.testing.assert_allclose(g.axis_centres(1), [-0.375, -0.125, 0.125, 0.375], atol=1e-15)
    np.testing.assert_allclose(g.axis_centres(2), [0.0], atol=1e-15)


def test_bounds_are_xyz_corners():
    """bounds = (x, y, z) outer corners: centre offset ± shape·voxel/2, reversed from (z, y, x)."""
    g = VolumeGeometry((3, 4, 5), (0.5, 1.0, 2.0), offset=(10.0, -1.0, 0.5))
    lo, hi = g.bounds
    np.testing.assert_allclose(lo, [0.5 - 5.0, -1.0 - 2.0, 10.0 - 0.75], atol=1e-12)
    np.testing.assert_allclose(hi, [0.5 + 5.0, -1.0 + 2.0, 10.0 + 0.75], atol=1e-12)
    # outer corners are half a voxel beyond the outermost centres
    assert lo[0] == pytest.approx(g.axis_centres(2)[0] - 1.0)
    assert hi[2] == pytest.approx(g.axis_centres(0)[-1] + 0.25)


def test_scalar_volume_arguments_broadcast():
    g = VolumeGeometry(4, 0.5)
    assert g.shape == (4, 4, 4)
    assert g.voxel_size == (0.5, 0.5, 0.5)
    assert g.offset == (0.0, 0.0, 0.0)


# --------------------------------------------------------------------------- many views


def test_vector_array_is_made_once_and_read_only():
    """``.to_vec()`` and ``.array`` are built once per geometry (a renderer reads one row per view)
    and the array cannot be written through; neither is a field, so equality, hash and repr are the
    fields' alone."""
    circular = ConeBeamGeometry(100, 250, **HAND)
    vec = circular.to_vec()
    assert circular.to_vec() is vec  # the renderer and the FDK of one scan share it
    array = vec.array
    assert vec.array is array
    assert not array.flags.writeable
    with pytest.raises(ValueError):
        array[0, 0] = 1.0
    np.testing.assert_array_equal(array, np.array(vec.vectors))
    again = VectorGeometry(vec.beam, vec.detector_shape, vec.vectors)
    assert again == vec and hash(again) == hash(vec) and repr(again) == repr(vec)


def test_one_view_costs_the_same_at_any_view_count():
    """One view's pixel centres take no longer at 10⁵ views than at 100: nothing per view is
    rebuilt for every view (before, each call copied the whole geometry: ~1000× slower here)."""
    import time

    def per_call(n: int) -> float:
        vec = ConeBeamGeometry(100, 250, (3, 4), 0.5, full_circle(n)).to_vec()
        detector_pixel_centres(vec, 0)
        best = math.inf
        for _ in range(5):
            start = time.perf_counter()
            for view in range(0, n, n // 50):
                detector_pixel_centres(vec, view)
            best = min(best, (time.perf_counter() - start) / 50)
        return best

    assert per_call(100_000) < 10 * per_call(100) + 1e-4  # coarse: a loaded machine's noise passes


def test_view_counts_whose_geometry_cannot_fit_are_refused_before_any_view_is_made(monkeypatch):
    """num_views is checked against the memory first (1.5 KB a view), naming the key and the memory:
    10⁷ views (15 GB) against 1 GiB available, in the API and in the dict form."""
    import time

    monkeypatch.setattr(xr.core.memory, "available_memory", lambda: 2**30)
    start = time.perf_counter()
    with pytest.raises(GeometryError, match=r"num_views = 10000000 .*GiB, more than half the 1.00 GiB available; "
                                            "use fewer views"):
        full_circle(10**7)
    d = {"source_to_origin": 100, "source_to_detector": 250, "detector_shape": [3, 4], "pixel_size": 0.5,
         "num_views": 10**7}
    with pytest.raises(xr.ConfigError, match=r"^scan\.toml \[geometry\]: num_views = 10000000 .*GiB"):
        xr.core.geometry.geometry_from_dict(d, "scan.toml [geometry]")
    assert time.perf_counter() - start < 1.0
    assert len(full_circle(1000)) == 1000


def test_a_geometry_that_exists_writes_its_dict_whatever_the_free_memory(monkeypatch):
    """to_dict does not check the memory again: a long scan's metadata is written at its end."""
    g = ConeBeamGeometry(100, 250, (3, 4), 0.5, full_circle(1000))
    monkeypatch.setattr(xr.core.memory, "available_memory", lambda: 1)
    assert g.to_dict()["num_views"] == 1000
