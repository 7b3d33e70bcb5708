"""Scan geometries, a volume and a ball shared by the FDK tests (tests/recon/test_fdk*.py)."""

from __future__ import annotations

import math

import numpy as np

import xrayraster as xr
from references.phantoms import sphere

MU = 0.02  # mm⁻¹
SMALL_VOLUME = xr.VolumeGeometry((20, 24, 28), (0.5, 0.45, 0.4), offset=(0.3, -0.2, 0.1))
BALL = sphere(4.0, MU, (1.5, -1.0, 0.8))
FAN = math.atan(32 * 0.8 / 200)  # half fan angle of the 64-column detector below


def tilted() -> xr.VectorGeometry:
    """A misaligned scanner: detector rolled 3° in its plane, pitched 4°, shifted; source 1 mm high."""
    base = xr.ConeBeamGeometry(100, 200, (30, 64), 0.8, xr.full_circle(60)).to_vec().array
    out = base.copy()
    for i, row in enumerate(base):
        s, d, u, v = np.split(row, 4)
        n = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
        roll = math.radians(3.0)
        u2 = math.cos(roll) * u + math.sin(roll) * v * (np.linalg.norm(u) / np.linalg.norm(v))
        v2 = -math.sin(roll) * u * (np.linalg.norm(v) / np.linalg.norm(u)) + math.cos(roll) * v
        pitch = math.radians(4.0)
        v3 = math.cos(pitch) * v2 + math.sin(pitch) * n * np.linalg.norm(v2)
        out[i] = np.concatenate([s + (0, 0, 1.0), d + 0.7 * u + 0.4 * v, u2, v3])
    return xr.VectorGeometry("cone", (30, 64), out)


CASES = {
    "full": xr.ConeBeamGeometry(100, 200, (30, 64), 0.8, xr.full_circle(60)),
    "short": xr.ConeBeamGeometry(100, 200, (30, 64), 0.8, np.linspace(0, math.pi + 2 * FAN, 50)),
    "displaced": xr.ConeBeamGeometry(100, 200, (30, 40), 0.8, xr.full_circle(60), detector_offset=(0.0, 9.0)),
    "offsets": xr.ConeBeamGeometry(100, 200, (30, 64), 0.8, xr.full_circle(60), detector_offset=(1.3, -0.6)),
    "tilted": tilted(),
    "parallel half": xr.ParallelBeamGeometry((30, 64), 0.4, np.linspace(0, math.pi, 45, endpoint=False)),
    "parallel full": xr.ParallelBeamGeometry((30, 64), 0.4, xr.full_circle(60)),
}


def max_rel(got, want) -> float:
    return float(np.abs(got - want).max() / np.abs(want).max())
