"""Label volumes against independent inside tests (trimesh's ray parity, with its signed distance
for any centre that disagrees), an exact lattice count for a sphere, the FDK reconstruction of
the same scene, and bad input."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh

import xrayraster as xr
from xrayraster.gl.voxelize import VoxelizeError, voxelize

VOLUME = xr.VolumeGeometry((48, 56, 64), (0.25, 0.22, 0.2), offset=(0.1, -0.2, 0.15))
POINTS = 100_000
MIN_DISTANCE = 1e-3  # voxels


def _l_block(size=4.0):
    """A concave L-shaped block (union of two boxes), mm."""
    import manifold3d as m3d

    a = m3d.Manifold.cube([size, size / 2, size / 2])
    b = m3d.Manifold.cube([size / 2, size, size / 2])
    mesh = (a + b).to_mesh()
    return trimesh.Trimesh(mesh.vert_properties[:, :3], mesh.tri_verts)


def _tube(outer=3.0, wall=0.35, height=6.0):
    """A thin-walled tube (wall under two voxels), closed: outer cylinder minus inner."""
    o = trimesh.creation.cylinder(radius=outer, height=height, sections=64)
    i = trimesh.creation.cylinder(radius=outer - wall, height=height + 1.0, sections=64)
    return o.difference(i, engine="manifold")


def _rot(ax, ay, az):
    """Rotation about x, then y, then z (degrees)."""
    return (xr.Transform.rotation((0, 0, 1), np.radians(az)) @ xr.Transform.rotation((0, 1, 0), np.radians(ay))
            @ xr.Transform.rotation((1, 0, 0), np.radians(ax)))


def _scene(parts):
    """parts: (mesh, label, priority, transform) -> (Scene, [(placed trimesh, label, priority)])."""
    scene = xr.Scene()
    placed = []
    for mesh, label, priority, transform in parts:
        scene.add(mesh, "m", label=label, priority=priority, transform=transform)
        copy = mesh.copy()
        if transform is not None:
            copy.apply_transform(transform.array)
        placed.append((copy, label, priority))
    return scene, placed


def _random_voxels(volume, count, seed, bounds=None):
    """``count`` random voxel indices (k, j, i) and their centres (x, y, z) mm, drawn among the
    voxels whose centres lie in ``bounds`` ((2, 3) mm box; default: all)."""
    rng = np.random.default_rng(seed)
    axes = [volume.axis_centres(a) for a in range(3)]  # z, y, x
    ranges = [np.arange(len(c)) for c in axes]
    if bounds is not None:
        ranges = [r[(c >= bounds[0][2 - a]) & (c <= bounds[1][2 - a])] for a, (r, c) in enumerate(zip(ranges, axes))]
    idx = np.stack([rng.choice(r, count) for r in ranges], axis=1)
    centres = np.stack([axes[2][idx[:, 2]], axes[1][idx[:, 1]], axes[0][idx[:, 0]]], axis=1)
    return idx, centres


def _reference_labels(placed, points):
    """Label by trimesh's ray-parity inside test (Trimesh.contains), priority rule applied."""
    label = np.zeros(len(points), np.int64)
    best = np.full(len(points), -np.inf)
    for number, (mesh, lab, priority) in enumerate(placed):
        rank = priority + 1e-6 * number  # later-added wins ties, as in the scene
        owns = mesh.contains(points) & (rank > best)
        label[owns] = lab
        best[owns] = rank
    return label


def _near_a_surface(placed, points, voxel_mm):
    """Whether each point lies within MIN_DISTANCE voxel of any object's surface (trimesh)."""
    distance = np.min([np.abs(trimesh.proximity.signed_distance(m, points)) for m, _, _ in placed], axis=0)
    return distance <= MIN_DISTANCE * voxel_mm


CASES = {
    "convex": [(trimesh.creation.box((5.0, 4.0, 3.0)), 1, 0, _rot(20, 35, 50))],
    "concave": [(_l_block(), 3, 0, xr.Transform.translation((-2.0, -1.5, -1.0)))],
    "nested": [(trimesh.creation.box((7.0, 7.0, 6.0)), 1, 0, None),
               (trimesh.creation.icosphere(subdivisions=3, radius=2.0), 2, 1, xr.Transform.translation((0.5, 0.3, -0.4)))],
    "overlapping": [(trimesh.creation.box((5.0, 3.0, 3.0)), 5, 2, xr.Transform.translation((-1.0, 0.0, 0.0))),
                    (trimesh.creation.icosphere(subdivisions=3, radius=2.2), 7, 1, xr.Transform.translation((1.2, 0.4, 0.2))),
                    (trimesh.creation.box((2.0, 6.0, 2.0)), 9, 3, _rot(0, 0, 30))],
    "thin-walled": [(_tube(), 4, 0, _rot(90, 0, 0))],
    "moved sample": [(_l_block(3.0), 1, 0, xr.Transform.translation((0.8, -1.1, 0.6)) @ _rot(30, -20, 75)),
                     (trimesh.creation.icosphere(subdivisions=2, radius=1.0), 2, 1, xr.Transform.translation((-1.5, 1.5, -1.0)))],
}


@functools.lru_cache(maxsize=None)
def _reference_sample(case):
    """Voxel indices, centres and reference labels of POINTS centres near the case's objects
    (computed once per case: both methods are checked against the same sample)."""
    scene, placed = _scene(CASES[case])
    idx, points = _random_voxels(VOLUME, POINTS, seed=len(case), bounds=scene.bounds + [[-0.5], [0.5]])
    return idx, points, _reference_labels(placed, points)


SLOW_CASES = {"nested", "overlapping", "thin-walled"}  # trimesh's inside test on 100k points: 8–16 s each


@pytest.mark.parametrize("method", ["exact", "stencil"])
@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_CASES else c for c in sorted(CASES)])
def test_labels_agree_with_an_independent_inside_test(gl, case, method):
    scene, placed = _scene(CASES[case])
    labels = voxelize(scene, VOLUME, method=method, context=gl)
    assert labels.data.dtype == np.uint8 and labels.data.shape == VOLUME.shape and labels.geometry == VOLUME
    idx, points, want = _reference_sample(case)
    got = labels.data[idx[:, 0], idx[:, 1], idx[:, 2]]
    differ = np.flatnonzero(got != want)
    # Only centres within 1e-3 voxel of a surface may differ (either inside test may go either way there).
    wrong = differ[~_near_a_surface(placed, points[differ], min(VOLUME.voxel_size))] if differ.size else differ
    assert wrong.size == 0, f"{wrong.size} of {POINTS} voxels disagree, e.g. at {points[wrong[:3]]}: {got[wrong[:3]]} vs {want[wrong[:3]]}"
    assert differ.size <= 1e-3 * POINTS
    assert set(np.unique(want)) == {0} | {lab for _, lab, _ in placed}  # every label (and 0) was tested


def test_sphere_count_is_the_exact_lattice_count_and_the_volume(gl):
    """256³ voxels, an icosphere: the labelled voxels are exactly the voxel centres inside the
    polyhedron (counted independently: per column, the z-interval inside every face's half-space,
    float64), and their volume equals the mesh volume within the derived bound: per column the
    count of centres in an interval of length ℓ is ℓ/v ± 1, so |N·v³ − V| ≤ M·v³ + E, M the
    columns crossed, E the midpoint-rule error of Σ ℓ·v² (bounded by the rim columns' chords)."""
    v = 0.1
    volume = xr.VolumeGeometry((256, 256, 256), v)
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=11.0)
    scene = xr.Scene()
    scene.add(sphere, "m")
    n = int(np.count_nonzero(voxelize(scene, volume, context=gl).data))
    normals = sphere.face_normals
    offsets = np.einsum("ij,ij->i", normals, sphere.triangles[:, 0])
    x, y = np.meshgrid(volume.axis_centres(2), volume.axis_centres(1))
    xy = np.stack([x.ravel(), y.ravel()], 1)
    lo, hi = np.full(len(xy), -np.inf), np.full(len(xy), np.inf)
    for f in range(len(normals)):  # n·p <= offset for p = (x, y, z): bounds on z per column
        nz = normals[f, 2]
        rest = offsets[f] - xy @ normals[f, :2]
        if nz > 0:
            hi = np.minimum(hi, rest / nz)
        elif nz < 0:
            lo = np.maximum(lo, rest / nz)
        else:
            lo[rest < 0] = np.inf
    z = volume.axis_centres(0)
    inside = lo < hi
    counts = np.searchsorted(z, hi[inside], side="right") - np.searchsorted(z, lo[inside], side="left")
    assert n == int(counts.sum())
    columns = int(inside.sum())
    rim = np.sort(hi[inside] - lo[inside])[: columns // 20].sum() * v**2  # chords of the thinnest 5 %: a generous E
    error = abs(n * v**3 - sphere.volume)
    print(f"sphere: {n} voxels, volume {n * v**3:.4f} vs mesh {sphere.volume:.4f} mm³ "
          f"(error {error / sphere.volume:.2e}, bound {(columns * v**3 + rim) / sphere.volume:.2e})")
    assert error <= columns * v**3 + rim


def test_more_than_255_labels_are_uint16(gl):
    scene = xr.Scene()
    scene.add(trimesh.creation.box((2.0, 2.0, 2.0)), "m", label=300)
    labels = voxelize(scene, xr.VolumeGeometry((8, 8, 8), 0.5), context=gl)
    assert labels.data.dtype == np.uint16 and labels.data.max() == 300 and labels.data[4, 4, 4] == 300


def test_slabs_give_the_same_labels(gl):
    scene, _ = _scene(CASES["overlapping"])
    whole = voxelize(scene, VOLUME, context=gl).data
    sliced = voxelize(scene, VOLUME, context=gl, slab_bytes=4 * 56 * 64 * 3).data  # 12 slices a slab
    assert np.array_equal(whole, sliced)


def test_bad_input(gl):
    with pytest.raises(VoxelizeError, match="VolumeGeometry"):
        voxelize(xr.Scene(), (10, 10, 10), context=gl)
    open_box = trimesh.creation.box((1.0, 1.0, 1.0))
    open_box.faces = open_box.faces[:-1]
    with pytest.raises(xr.MeshError, match="open|watertight|closed"):
        xr.Scene().add(open_box, "m")
    with pytest.raises(xr.SceneError, match="label must be an integer in"):
        xr.Scene().add(trimesh.creation.box((1.0, 1.0, 1.0)), "m", label=70000)
    scene = xr.Scene()
    scene.add(trimesh.creation.box((1.0, 1.0, 1.0)), "m")
    with pytest.raises(VoxelizeError, match="method must be"):
        voxelize(scene, xr.VolumeGeometry((4, 4, 4), 0.5), method="stencil", fractions=2, context=gl)
    with pytest.raises(VoxelizeError, match="GiB"):
        voxelize(scene, xr.VolumeGeometry((20000, 20000, 20000), 0.1), context=gl)


def test_labels_line_up_with_the_fdk_reconstruction(gl, cl, render):
    """An off-centre L-shaped block, scanned (our renderer), reconstructed (FDK) and voxelized on
    one VolumeGeometry: centroids within 0.25 voxel; and on lines crossing its faces (away from
    its edges, where the face is locally flat across the neighbouring lines) the reconstruction
    crosses half its value in the same voxel interval where the label changes, so the two
    boundaries agree within half a voxel."""
    mu = 0.03  # mm⁻¹
    g = xr.ConeBeamGeometry(100, 200, (100, 100), 0.4, xr.full_circle(180))
    vol = xr.VolumeGeometry((40, 48, 56), 0.3, offset=(0.2, -0.4, 0.5))
    scene = xr.Scene()
    scene.add(_l_block(5.0), "m", label=1, transform=xr.Transform.translation((-1.37, -3.11, -2.23)))
    lengths = np.stack([render(g, scene, view)[0] for view in range(g.num_views)])
    rec = xr.fdk(mu * lengths, g, vol, context=cl).data / 10
    labels = voxelize(scene, vol, context=gl).data
    index = np.indices(vol.shape).reshape(3, -1).T  # (k, j, i)
    shift = index[(rec > mu / 2).ravel()].mean(axis=0) - index[(labels > 0).ravel()].mean(axis=0)
    print(f"label vs reconstruction centroid (k, j, i): {shift} voxels")
    assert np.all(np.abs(shift) < 0.25)
    offsets = []
    for axis in range(3):
        lab = np.moveaxis(labels, axis, -1).astype(int)
        val = np.moveaxis(rec, axis, -1)
        step = np.diff(lab, axis=-1) != 0  # (a, b, n - 1): a label change between s and s + 1
        flat = step[1:-1, 1:-1].copy()  # the same change on the 8 neighbouring parallel lines
        for da in (-1, 0, 1):
            for db in (-1, 0, 1):
                flat &= step[1 + da : step.shape[0] - 1 + da, 1 + db : step.shape[1] - 1 + db]
        for a, b, s in np.argwhere(flat):
            lo, hi = val[a + 1, b + 1, s] - mu / 2, val[a + 1, b + 1, s + 1] - mu / 2
            assert lo * hi <= 0, f"axis {axis}: the label changes between {s} and {s + 1}, the reconstruction does not"
            offsets.append(s + lo / (lo - hi) - (s + 0.5))
    offsets = np.abs(offsets)
    print(f"{len(offsets)} face crossings: |half-maximum − label boundary| median {np.median(offsets):.3f}, "
          f"max {offsets.max():.3f} voxel")
    assert len(offsets) > 300 and offsets.max() <= 0.5


def test_fractions_are_partial_volumes(gl):
    """k³ sub-voxel centres: a box whose faces cut voxels in half gives 0.5 there, shares add to
    1, the majority label is the hard label away from surfaces, and a sphere's summed share is
    its volume far closer than the hard labels' count."""
    volume = xr.VolumeGeometry((10, 12, 14), 0.5)
    scene = xr.Scene()
    scene.add(trimesh.creation.box((3.5, 2.0, 2.5)), "m", label=3)  # x faces at ±1.75: through voxel centres
    soft = voxelize(scene, volume, fractions=4, context=gl)
    assert soft.labels == (0, 3) and soft.fractions.shape == (2, 10, 12, 14) and soft.fractions.dtype == np.float32
    np.testing.assert_allclose(soft.fractions.sum(axis=0), 1.0, atol=1e-6)
    x = volume.axis_centres(2)
    k, j = 5, 6  # a voxel row through the middle of the box
    edge = int(np.argmin(np.abs(x - 1.75)))
    assert soft.fractions[1, k, j, edge] == pytest.approx(0.5) and soft.fractions[1, k, j, edge - 1] == 1.0
    hard = voxelize(scene, volume, context=gl).data
    assert np.array_equal(soft.data[soft.fractions.max(axis=0) == 1.0], hard[soft.fractions.max(axis=0) == 1.0])
    ball = xr.Scene()
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=2.1)
    ball.add(sphere, "m", label=1)
    grid = xr.VolumeGeometry((12, 12, 12), 0.4)
    soft_error = abs(voxelize(ball, grid, fractions=8, context=gl).fractions[1].sum() * 0.4**3 - sphere.volume)
    hard_error = abs(np.count_nonzero(voxelize(ball, grid, context=gl).data) * 0.4**3 - sphere.volume)
    print(f"sphere volume error: hard labels {hard_error:.4f}, 8³ fractions {soft_error:.4f} mm³")
    assert soft_error < 0.1 * hard_error


def test_tiles_give_the_same_labels(gl, monkeypatch):
    from xrayraster.gl import voxelize as module

    scene, _ = _scene(CASES["moved sample"])
    whole = voxelize(scene, VOLUME, context=gl).data
    monkeypatch.setattr(module, "TILE_COLUMNS", 20)  # 3 × 4 tiles of the 56 × 64 columns
    assert np.array_equal(voxelize(scene, VOLUME, context=gl).data, whole)


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_labels_do_not_depend_on_the_unit_size(gl, scale):
    """The overlapping scene and grid scaled to micrometres or metres: the same labels."""
    scene, _ = _scene(CASES["overlapping"])
    want = voxelize(scene, VOLUME, context=gl).data
    scaled = xr.Scene()
    for o in scene.objects:
        scaled.add((o.mesh.vertices * scale, o.mesh.faces), "m", label=o.label, priority=o.priority)
    vol = xr.VolumeGeometry(VOLUME.shape, tuple(v * scale for v in VOLUME.voxel_size), tuple(o * scale for o in VOLUME.offset))
    got = voxelize(scaled, vol, context=gl).data
    assert np.array_equal(got, want)  # measured: identical (float32 rounding is relative to the scene size)


def test_columns_with_more_crossings_than_the_first_pass_holds(gl):
    """12 separate plates stacked along z: 24 crossings a column, more than the 16 the resolve
    pass first makes room for; it widens and runs again, and every plate is where it should be."""
    scene = xr.Scene()
    for n in range(12):  # plate n spans z in [n − 5.75, n − 5.25] mm
        scene.add(trimesh.creation.box((3.0, 3.0, 0.5)), "m", label=n + 1,
                  transform=xr.Transform.translation((0.0, 0.0, n - 5.5)))
    volume = xr.VolumeGeometry((48, 4, 4), 0.25)  # centres at z = ±0.125, ±0.375, ...
    labels = voxelize(scene, volume, context=gl).data
    z = volume.axis_centres(0)
    plate = np.floor(z + 5.75)
    want = np.where((plate >= 0) & (plate < 12) & (np.abs(z - (plate - 5.5)) < 0.25), plate + 1, 0)
    assert np.array_equal(labels[:, 1, 1], want) and np.array_equal(labels[:, 2, 2], want)
    assert set(np.unique(want)) == set(range(13))


def test_columns_through_hundreds_of_surfaces(gl):
    """200 cubes stacked along z, two objects taking them in turn: 400 crossings a voxel column,
    past the 65535 loop steps llvmpipe allows a shader invocation when the sort took n² of them."""
    count, pitch, half = 200, 0.6, 0.25
    centres = (np.arange(count) - (count - 1) / 2) * pitch
    scene = xr.Scene()
    for first, label in ((0, 3), (1, 7)):
        cubes = [trimesh.creation.box((2 * half,) * 3, transform=xr.Transform.translation((0, 0, z)).matrix)
                 for z in centres[first::2]]
        scene.add(trimesh.util.concatenate(cubes), f"m{label}", label=label)
    volume = xr.VolumeGeometry((600, 4, 4), (0.2, 0.1, 0.1))  # centres 0.05 mm or more from every face
    z = volume.axis_centres(0)
    nearest = np.abs(z[:, None] - centres[None, :]).argmin(axis=1)
    want = np.where(np.abs(z - centres[nearest]) < half, np.where(nearest % 2, 7, 3), 0)
    got = voxelize(scene, volume, context=gl).data
    assert np.array_equal(got, np.broadcast_to(want[:, None, None], volume.shape).astype(got.dtype))
