"""An in-memory scene written as a scene file reads back as the same scene: the same vertices to the
last bit, names, labels, priorities and materials, so its path lengths are the same bytes."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

import xrayraster as xr
from xrayraster.core.errors import ConfigError
from xrayraster.io.scene_file import load_scene_file
from xrayraster.io.scene_writer import write_scene_file


def mixed_scene() -> xr.Scene:
    """Overlapping objects placed off the origin, turned, scaled; a library material by name, and two
    different materials that share a name (the file must tell them apart)."""
    scene = xr.Scene()
    scene.add(trimesh.creation.box((6.0, 5.0, 4.0)), "aluminium", priority=0, name="block")
    ball = xr.Transform.translation((0.7, -0.3, 0.2)) @ xr.Transform.rotation((1, 1, 0), math.radians(33))
    scene.add(trimesh.creation.icosphere(3, radius=1.8), xr.Material.from_formula("H2O", 1.0, name="water"),
              priority=2, label=7, name="ball/left", transform=ball)
    scene.add(trimesh.creation.cylinder(radius=0.9, height=3.0, sections=40),
              xr.Material.from_formula("H2O", 0.92, name="water"), priority=1, name="ice", unit_scale=1.1)
    scene.add(trimesh.creation.icosphere(2, radius=0.6), xr.Material.element("Al", name="aluminium"), name="pellet",
              transform=xr.Transform.translation((-2.0, 1.0, 0.5)))
    return scene


def test_a_written_scene_file_loads_as_the_same_scene(tmp_path):
    scene = mixed_scene()
    geometry = xr.ConeBeamGeometry(60.0, 120.0, (24, 32), 0.5, xr.full_circle(4))
    path = write_scene_file(tmp_path / "scene.toml", scene, geometry, source={"kvp": 60.0, "filters": {"Al": 1.0}})
    loaded = load_scene_file(path)
    assert loaded.geometry == geometry and loaded.spectrum is not None
    assert len(loaded.scene.objects) == len(scene.objects)
    for a, b in zip(scene.objects, loaded.scene.objects):
        assert (a.name, a.label, a.priority, a.order) == (b.name, b.label, b.priority, b.order)
        np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)  # OBJ with 17 digits: float64 exactly
        np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)
        if isinstance(a.material, str):
            assert b.material == xr.Material.named(a.material)
        else:
            assert b.material.density == a.material.density
            for (za, wa), (zb, wb) in zip(a.material.composition, b.material.composition, strict=True):
                assert za == zb and wb == pytest.approx(wa, rel=1e-14)
    assert sorted(loaded.materials) == ["aluminium", "aluminium_2", "water", "water_2"]
    with xr.Renderer(geometry) as renderer:
        for view in range(geometry.num_views):
            np.testing.assert_array_equal(renderer.path_lengths(loaded.scene, view), renderer.path_lengths(scene, view))


def test_a_material_that_no_file_can_name_is_refused(tmp_path):
    scene = xr.Scene()
    scene.add(trimesh.creation.box((1.0, 1.0, 1.0)), 42, name="cube")
    with pytest.raises(ConfigError, match=r"object 'cube': material 42 cannot be written to a scene file"):
        write_scene_file(tmp_path / "scene.toml", scene, xr.ConeBeamGeometry(60.0, 120.0, (8, 8), 0.5, [0.0]))
    assert not any(tmp_path.iterdir())  # nothing half-written
