"""Independent float64 references: pixel rays from the geometry's definition, analytic chords."""

from __future__ import annotations

import numpy as np


def rot_z(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def cone_rays(sod, sdd, shape, pixel, theta, offset=(0.0, 0.0)):
    """Source and unit directions to every pixel centre, straight from the documented convention."""
    rows, cols = shape
    r = rot_z(theta)
    src = r @ np.array([0.0, -sod, 0.0])
    c = (np.arange(cols) - (cols - 1) / 2) * pixel + offset[1]
    z = (np.arange(rows) - (rows - 1) / 2) * pixel + offset[0]
    local = np.stack(np.broadcast_arrays(c[None, :], sdd - sod, z[:, None]), axis=-1)
    centres = local @ r.T
    d = centres - src
    return np.broadcast_to(src, d.shape), d / np.linalg.norm(d, axis=-1, keepdims=True)


def parallel_rays(shape, pixel, theta):
    rows, cols = shape
    r = rot_z(theta)
    c = (np.arange(cols) - (cols - 1) / 2) * pixel
    z = (np.arange(rows) - (rows - 1) / 2) * pixel
    local = np.stack(np.broadcast_arrays(c[None, :], -1000.0, z[:, None]), axis=-1)
    origins = local @ r.T
    return origins, np.broadcast_to(r @ np.array([0, 1.0, 0]), origins.shape)


def box_chord(origins, dirs, centre, rotation, half):
    """Length of each ray (half-line from its origin) inside an oriented box (slab method)."""
    o = (origins - centre) @ rotation  # into the box frame (rotation columns = box axes)
    d = dirs @ rotation
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-np.asarray(half) - o) / d
        t2 = (np.asarray(half) - o) / d
    lo = np.where(d == 0, np.where(np.abs(o) <= half, -np.inf, np.inf), np.minimum(t1, t2))
    hi = np.where(d == 0, np.where(np.abs(o) <= half, np.inf, -np.inf), np.maximum(t1, t2))
    enter = np.maximum(lo.max(axis=-1), 0.0)
    leave = hi.min(axis=-1)
    return np.maximum(leave - enter, 0.0)


def sphere_chord(origins, dirs, centre, radius):
    o = origins - centre
    b = np.einsum("...i,...i", o, dirs)
    c = np.einsum("...i,...i", o, o) - radius**2
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0))
    enter = np.maximum(-b - root, 0)
    leave = -b + root
    return np.where(disc > 0, np.maximum(leave - enter, 0), 0.0)


def cylinder_chord(origins, dirs, radius, half_height):
    """Cylinder of the given radius along z, centred at the origin, capped at ±half_height."""
    o, d = origins, dirs
    a = d[..., 0] ** 2 + d[..., 1] ** 2
    b = o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1]
    c = o[..., 0] ** 2 + o[..., 1] ** 2 - radius**2
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = b * b - a * c
        root = np.sqrt(np.maximum(disc, 0))
        lo = np.where(a > 0, (-b - root) / a, np.where(c <= 0, -np.inf, np.inf))
        hi = np.where(a > 0, (-b + root) / a, np.where(c <= 0, np.inf, -np.inf))
        lo = np.where((a > 0) & (disc <= 0), np.inf, lo)
        tz1 = (-half_height - o[..., 2]) / d[..., 2]
        tz2 = (half_height - o[..., 2]) / d[..., 2]
    inside_z = np.abs(o[..., 2]) <= half_height
    zlo = np.where(d[..., 2] == 0, np.where(inside_z, -np.inf, np.inf), np.minimum(tz1, tz2))
    zhi = np.where(d[..., 2] == 0, np.where(inside_z, np.inf, -np.inf), np.maximum(tz1, tz2))
    enter = np.maximum(np.maximum(lo, zlo), 0)
    leave = np.minimum(hi, zhi)
    return np.maximum(leave - enter, 0.0)


def random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def convex_chord(origins, dirs, vertices, faces):
    """Exact chord of a convex polyhedron (intersection of its face half-spaces), float64."""
    a, b, c = (np.asarray(vertices, dtype=np.float64)[np.asarray(faces)[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    offsets = np.einsum("ij,ij->i", normals, a)
    enter = np.zeros(origins.shape[:-1])
    leave = np.full(origins.shape[:-1], np.inf)
    for n, h in zip(normals, offsets):
        nd = dirs @ n
        dist = h - origins @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = dist / nd
        enter = np.where(nd < 0, np.maximum(enter, t), enter)
        leave = np.where(nd > 0, np.minimum(leave, t), leave)
        leave = np.where((nd == 0) & (dist < 0), -np.inf, leave)
    return np.maximum(leave - enter, 0.0)


def box_interval(origins, dirs, centre, rotation, half):
    """(enter, leave) ray parameters of an oriented box (slab method), enter clipped to the half-line
    (t ≥ 0); a miss has leave ≤ enter. ``rotation``'s columns are the box axes."""
    o = (origins - np.asarray(centre, np.float64)) @ rotation
    d = dirs @ rotation
    half = np.asarray(half, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - o) / d
        t2 = (half - o) / d
    inside = np.abs(o) <= half
    lo = np.where(d == 0, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
    hi = np.where(d == 0, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
    return np.maximum(lo.max(axis=-1), 0.0), hi.min(axis=-1)


def convex_interval(origins, dirs, vertices, faces, chunk: int = 2048):
    """(enter, leave) ray parameters of a convex polyhedron with outward-wound faces (the
    intersection of its face half-spaces), float64, enter clipped to t ≥ 0; a miss has leave ≤ enter.
    ``origins``/``dirs`` (n, 3)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    normals = np.cross(b - a, c - a)
    offsets = np.einsum("ij,ij->i", normals, a)
    enter = np.zeros(len(origins))
    leave = np.full(len(origins), np.inf)
    for start in range(0, len(normals), chunk):
        n, h = normals[start : start + chunk], offsets[start : start + chunk]
        nd = dirs @ n.T  # (rays, faces)
        dist = h[None, :] - origins @ n.T
        with np.errstate(divide="ignore", invalid="ignore"):
            t = dist / nd
        enter = np.maximum(enter, np.where(nd < 0, t, -np.inf).max(axis=1))
        leave = np.minimum(leave, np.where(nd > 0, t, np.inf).min(axis=1))
        leave = np.where(((nd == 0) & (dist < 0)).any(axis=1), -np.inf, leave)
    return enter, leave
