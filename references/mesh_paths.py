"""float64 path lengths inside closed triangle meshes along a circular cone-beam view's pixel rays,
written from the geometry's definition (docs/geometry.md) apart from the renderer: the exact
projections scripts/bench_scan.py scores both pipelines against, checked on a box by
tests/scripts/test_bench_scan_reference.py."""

from __future__ import annotations

import numpy as np


def exact_path_lengths(vertices, faces, sod: float, sdd: float, pixel: float, shape, theta: float,
                       rows: tuple[int, int]) -> np.ndarray:
    """float64 length (mm) inside a closed, outward-oriented mesh along the ray to every pixel centre
    of detector rows ``rows[0]`` … ``rows[1]``, one circular cone-beam view at ``theta`` (radians).

    Source at R_z(θ)(0, −sod, 0), detector centre R_z(θ)(0, sdd − sod, 0), columns along R_z(θ)x̂,
    rows along ẑ (docs/geometry.md). A triangle in front of the source projects centrally onto the
    detector plane as a triangle, so the pixel centres inside its projection are the rays that
    cross it; each crossing adds its distance from the source, + where the ray leaves (outward
    normal along the ray) and − where it enters. A pixel centre exactly on a projected edge (a set
    of measure zero) would count twice or not at all.
    """
    nrow, ncol = shape
    lo, hi = rows
    c, s = np.cos(theta), np.sin(theta)
    tri = vertices[faces]
    depth = -tri[..., 0] * s + tri[..., 1] * c + sod  # along the central ray, from the source
    scale = sdd / (depth * pixel)
    col = (tri[..., 0] * c + tri[..., 1] * s) * scale + (ncol - 1) / 2
    row = tri[..., 2] * scale + (nrow - 1) / 2
    c0 = np.maximum(np.ceil(col.min(1)).astype(np.int64), 0)
    c1 = np.minimum(np.floor(col.max(1)).astype(np.int64), ncol - 1)
    r0 = np.maximum(np.ceil(row.min(1)).astype(np.int64), lo)
    r1 = np.minimum(np.floor(row.max(1)).astype(np.int64), hi)
    width = np.maximum(c1 - c0 + 1, 0)
    count = width * np.maximum(r1 - r0 + 1, 0)  # pixel centres in each projected bounding box
    hit = np.flatnonzero(count)
    k = np.repeat(hit, count[hit])
    local = np.arange(len(k)) - np.repeat(np.cumsum(count[hit]) - count[hit], count[hit])
    cc, rr = c0[k] + local % width[k], r0[k] + local // width[k]
    pc, pr = col[k], row[k]
    edges = [(pc[:, j] - pc[:, i]) * (rr - pr[:, i]) - (pr[:, j] - pr[:, i]) * (cc - pc[:, i])
             for i, j in ((0, 1), (1, 2), (2, 0))]
    inside = np.all([e >= 0 for e in edges], axis=0) | np.all([e <= 0 for e in edges], axis=0)
    k, cc, rr = k[inside], cc[inside], rr[inside]
    source = np.array([sod * s, -sod * c, 0.0])
    pixels = (np.array([-(sdd - sod) * s, (sdd - sod) * c, 0.0])
              + ((cc - (ncol - 1) / 2) * pixel)[:, None] * np.array([c, s, 0.0])
              + ((rr - (nrow - 1) / 2) * pixel)[:, None] * np.array([0.0, 0.0, 1.0]))
    ray = pixels - source
    t = tri[k]
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    ahead = np.einsum("ij,ij->i", normal, t[:, 0] - source)  # > 0: the face looks away from the source
    along = np.einsum("ij,ij->i", normal, ray)  # same sign as ``ahead`` for a crossing in front of the source
    signed = ahead / np.abs(along) * np.linalg.norm(ray, axis=1)  # ± distance from the source
    out = np.bincount((rr - lo) * ncol + cc, signed, minlength=(hi - lo + 1) * ncol)
    return out.reshape(hi - lo + 1, ncol)
