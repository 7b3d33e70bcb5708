"""The host filter's cosine weights against ŝ·(p − s) / |p − s| written out per pixel in float64."""

from __future__ import annotations

import numpy as np

from xrayraster.recon.host_filter import cosine_weights


def direct(vectors: np.ndarray, toward_axis: np.ndarray, rows: int, cols: int) -> np.ndarray:
    s, d, u, v = (vectors[:, 3 * k : 3 * k + 3] for k in range(4))
    c = np.arange(cols) - 0.5 * (cols - 1)
    r = np.arange(rows) - 0.5 * (rows - 1)
    p = d[:, None, None] + r[None, :, None, None] * v[:, None, None] + c[None, None, :, None] * u[:, None, None]
    ray = p - s[:, None, None]
    return np.einsum("vrck,vk->vrc", ray, toward_axis) / np.linalg.norm(ray, axis=-1)


def circular(angles: np.ndarray, sod: float, sdd: float, pitch: float, offset: float = 0.0) -> tuple:
    cos, sin = np.cos(angles), np.sin(angles)
    s = np.stack([sod * sin, -sod * cos, np.zeros_like(cos)], axis=1)
    d = np.stack([-(sdd - sod) * sin, (sdd - sod) * cos, np.full_like(cos, offset)], axis=1)
    u = pitch * np.stack([cos, sin, np.zeros_like(cos)], axis=1)
    v = pitch * np.tile([0.0, 0.0, 1.0], (len(angles), 1))
    toward = -s / np.linalg.norm(s, axis=1, keepdims=True)
    return np.concatenate([s, d, u, v], axis=1), toward


def test_a_circular_orbit_shares_one_plane_equal_to_every_views_own():
    vectors, toward = circular(np.linspace(0.0, 2 * np.pi, 40, endpoint=False), 80.0, 230.0, 0.5, offset=1.5)
    got = cosine_weights(vectors, toward, 12, 20)
    assert got.shape == (1, 12, 20)
    np.testing.assert_allclose(np.broadcast_to(got, (40, 12, 20)), direct(vectors, toward, 12, 20), rtol=1e-13)


def test_views_that_differ_keep_planes_of_their_own():
    """A source whose distance changes from view to view (a helix or a wobbling stage): one plane each."""
    angles = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    vectors, toward = circular(angles, 80.0, 230.0, 0.5)
    vectors[:, :3] *= (1.0 + 0.01 * np.sin(angles))[:, None]
    got = cosine_weights(vectors, toward, 12, 20)
    assert got.shape == (16, 12, 20)
    np.testing.assert_allclose(got, direct(vectors, toward, 12, 20), rtol=1e-13)
