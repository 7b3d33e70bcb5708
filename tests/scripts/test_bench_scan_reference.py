"""scripts/bench_scan.py scores both pipelines against exact float64 projections of meshes
(references/mesh_paths.py); here those ray–mesh path lengths meet the analytic box chords of
references/chords.py (the script's ``--self-check`` does the same)."""

import numpy as np
import trimesh

from references.chords import box_chord, cone_rays
from references.mesh_paths import exact_path_lengths


def test_the_benchmark_reference_path_lengths_match_box_chords():
    centre, half = np.array([1.5, -2.0, 0.7]), np.array([4.0, 2.5, 1.5])
    box = trimesh.creation.box(extents=2 * half)
    box.apply_translation(centre)
    shape = (48, 64)
    for theta in (0.0, 0.9, 4.0):  # every pixel of three views of an off-centre box (its 12 triangles)
        got = exact_path_lengths(np.asarray(box.vertices), np.asarray(box.faces), 60.0, 140.0, 0.3, shape, theta,
                                 (0, shape[0] - 1))
        origins, directions = cone_rays(60.0, 140.0, shape, 0.3, theta)
        expected = box_chord(origins, directions, centre, np.eye(3), half)
        assert np.abs(got - expected).max() < 1e-9, theta  # mm
        assert (expected > 0).sum() > 100  # the box is in view
