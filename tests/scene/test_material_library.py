"""The named-material library against the published values it cites (NIST/ICRU tables, data
sheets), μ/ρ of water against NIST, stoichiometry by xraydb's own atomic weights, and its use by
name in scene files; and scene-file mesh errors naming the file and the object entry."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import xraydb

import xrayraster as xr
from xrayraster.io.scene_file import load_scene_file
from xrayraster.scene.material_library import LIBRARY

# Transcribed from Hubbell & Seltzer, NISTIR 5632 (physics.nist.gov/PhysRefData/XrayMassCoef):
# Table 1 (elements: density) and Table 2 (compounds and mixtures: density, mass fractions).
NIST_TABLE_1 = {"aluminium": ("Al", 2.699), "titanium": ("Ti", 4.540), "iron": ("Fe", 7.874), "copper": ("Cu", 8.960)}
NIST_TABLE_2 = {
    "air": (1.205e-3, {"C": 0.000124, "N": 0.755268, "O": 0.231781, "Ar": 0.012827}),
    "water": (1.000, {"H": 0.111894, "O": 0.888106}),
    "pmma": (1.190, {"H": 0.080538, "C": 0.599848, "O": 0.319614}),
    "bone": (1.920, {"H": 0.034, "C": 0.155, "N": 0.042, "O": 0.435, "Na": 0.001, "Mg": 0.002, "P": 0.103,
                     "S": 0.003, "Ca": 0.225}),
}
# NIST μ/ρ (cm²/g) of liquid water, same tables (= XCOM total attenuation with coherent scattering).
WATER_MU_RHO = {10: 5.329, 20: 0.8096, 40: 0.2683, 60: 0.2059, 100: 0.1707, 150: 0.1505}


def _fractions_from_formula(counts: dict[str, float]) -> dict[str, float]:
    """Mass fractions from atom counts with xraydb's atomic masses (not xraylib's)."""
    masses = {el: n * xraydb.atomic_mass(el) for el, n in counts.items()}
    total = sum(masses.values())
    return {el: m / total for el, m in masses.items()}


def test_the_names_are_listed_and_each_has_a_source():
    names = xr.Material.library_names()
    for required in ("air", "water", "pmma", "aluminium", "epoxy", "carbon_fibre", "e_glass", "titanium", "iron",
                     "steel", "copper", "bone", "csi", "gd2o2s"):
        assert required in names
    for name in names:
        source = LIBRARY[name][3]
        assert len(source) > 15 and xr.Material.named(name).name == name


@pytest.mark.parametrize("name", sorted(NIST_TABLE_1))
def test_elements_have_nist_table_1_densities(name):
    symbol, density = NIST_TABLE_1[name]
    m = xr.Material.named(name)
    assert m.mass_fractions == {symbol: 1.0} and m.density == density


@pytest.mark.parametrize("name", sorted(NIST_TABLE_2))
def test_mixtures_have_nist_table_2_compositions(name):
    density, fractions = NIST_TABLE_2[name]
    m = xr.Material.named(name)
    assert m.density == density
    assert m.mass_fractions.keys() == fractions.keys()
    for el, w in fractions.items():
        assert m.mass_fractions[el] == pytest.approx(w, rel=1e-6)


def test_water_mu_over_rho_matches_nist_within_one_percent():
    energies = np.array(sorted(WATER_MU_RHO), dtype=float)
    nist = np.array([WATER_MU_RHO[e] for e in sorted(WATER_MU_RHO)])
    water = xr.Material.named("water")
    np.testing.assert_allclose(water.mass_attenuation(energies), nist, rtol=0.01)
    # μ in mm⁻¹ = μ/ρ (cm²/g) · ρ (g/cm³) / 10, under its documented name and the old one
    np.testing.assert_allclose(water.attenuation_per_mm(energies), nist * 1.000 / 10, rtol=0.01)
    np.testing.assert_array_equal(water.attenuation(energies), water.attenuation_per_mm(energies))


@pytest.mark.parametrize("name, counts, density", [
    ("epoxy", {"C": 21, "H": 24, "O": 4}, 1.16),           # DGEBA C21H24O4, Sigma-Aldrich D3415
    ("csi", {"Cs": 1, "I": 1}, 4.51),                       # CRC Handbook
    ("gd2o2s", {"Gd": 2, "O": 2, "S": 1}, 7.34),            # Nikl 2006, Table 1
])
def test_compounds_by_stoichiometry(name, counts, density):
    m = xr.Material.named(name)
    assert m.density == density
    for el, w in _fractions_from_formula(counts).items():
        assert m.mass_fractions[el] == pytest.approx(w, rel=3e-3)  # xraylib rounds some atomic weights (H 1.01)


def test_e_glass_from_its_oxides_and_the_fibres():
    oxides = {"SiO2": ({"Si": 1, "O": 2}, 0.54), "Al2O3": ({"Al": 2, "O": 3}, 0.14), "B2O3": ({"B": 2, "O": 3}, 0.10),
              "CaO": ({"Ca": 1, "O": 1}, 0.175), "MgO": ({"Mg": 1, "O": 1}, 0.045)}
    assert math.isclose(sum(share for _, share in oxides.values()), 1.0)
    want: dict[str, float] = {}
    for counts, share in oxides.values():
        for el, w in _fractions_from_formula(counts).items():
            want[el] = want.get(el, 0.0) + share * w
    glass = xr.Material.named("e_glass")
    assert glass.density == 2.54 and glass.mass_fractions.keys() == want.keys()
    for el, w in want.items():
        assert glass.mass_fractions[el] == pytest.approx(w, rel=3e-3)  # xraylib rounds some atomic weights (H 1.01)
    assert xr.Material.named("carbon_fibre") == xr.Material.element("C", 1.76)
    steel = xr.Material.named("steel")
    assert steel.density == 7.87 and steel.mass_fractions == {"C": 0.002, "Mn": 0.0045, "Fe": 0.9935}


def test_names_are_forgiving_and_unknown_names_list_the_library():
    assert xr.Material.named("Aluminum") == xr.Material.named("aluminium") == xr.Material.named(" ALUMINIUM ")
    assert xr.Material.named("carbon-fiber") == xr.Material.named("carbon fibre")
    assert xr.Material.named("Perspex") == xr.Material.named("pmma")
    with pytest.raises(xr.MaterialError, match=r"no material named 'unobtainium'.*water.*gd2o2s"):
        xr.Material.named("unobtainium")


# ----------------------------------------------------------------------------- scene files

HEAD = """
[geometry]
source_to_origin = 100.0
source_to_detector = 200.0
detector_shape = [8, 8]
pixel_size = 1.0
num_views = 2
"""


def _load(tmp_path: Path, text: str):
    path = tmp_path / "scene.toml"
    path.write_text(HEAD + text)
    return load_scene_file(path)


def test_scene_objects_use_library_names_and_materials_tables_win(tmp_path):
    loaded = _load(tmp_path, """
[[objects]]
mesh = { box = [2, 2, 2] }
material = "water"
[[objects]]
mesh = { sphere = 1 }
material = "Aluminium"
[[objects]]
mesh = { sphere = 0.5 }
material = "steel"
[materials.steel]
mass_fractions = { Fe = 0.98, C = 0.02 }
density = 7.85
""")
    water, al, steel = (o.material for o in loaded.scene.objects)
    assert water == xr.Material.named("water") and water.name == "water"
    assert al == xr.Material.element("Al", 2.699) and al.name == "Aluminium"
    assert steel == xr.Material.from_mass_fractions({"Fe": 0.98, "C": 0.02}, 7.85)  # [materials] wins
    assert loaded.materials["steel"] is steel and loaded.materials["water"] == water


def test_a_scene_without_materials_table_gets_library_materials(tmp_path):
    loaded = _load(tmp_path, """
[[objects]]
mesh = { box = [2, 2, 2] }
material = "pmma"
[detector]
scintillator = "csi"
scintillator_mm = 0.5
""")
    assert loaded.materials == {"pmma": xr.Material.named("pmma")}
    assert loaded.detector.scintillator == xr.Material.named("csi")
    plain = _load(tmp_path, '[[objects]]\nmesh = { box = [2, 2, 2] }\nmaterial = "mystery"\n')
    assert plain.materials is None and plain.scene.materials == ("mystery",)  # path lengths only, as before


def test_unknown_names_mention_the_library(tmp_path):
    with pytest.raises(xr.ConfigError, match=r"#1.*'mystery' is not defined in \[materials\].*nor a library material"):
        _load(tmp_path, '[[objects]]\nmesh = { box = [2, 2, 2] }\nmaterial = "mystery"\n[materials.a]\nelement = "Al"\n')


def _open_box(path: Path) -> None:
    import trimesh

    box = trimesh.creation.box((2.0, 2.0, 2.0))
    trimesh.Trimesh(box.vertices, box.faces[:-2], process=False).export(path)


@pytest.mark.parametrize("kind, match", [
    ("open", r"open edges|not closed|watertight"),
    ("nan", r"NaN or infinite"),
    ("junk", r"cannot read|mesh"),
    ("missing", r"no such file"),
])
def test_mesh_errors_name_the_scene_file_the_entry_and_the_mesh_file(tmp_path, kind, match):
    mesh = tmp_path / f"{kind}.obj"
    if kind == "open":
        _open_box(mesh)
    elif kind == "nan":
        mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    elif kind == "junk":
        mesh = tmp_path / "junk.stl"
        mesh.write_bytes(b"\x00\x01 this is not a mesh")
    text = f'[[objects]]\nmesh = {{ box = [1, 1, 1] }}\nmaterial = "a"\n[[objects]]\nname = "part"\nmesh = "{mesh.name}"\nmaterial = "a"\n'
    with pytest.raises(xr.ConfigError, match=match) as info:
        _load(tmp_path, text)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'scene.toml'} [[objects]] #2 (part): mesh file '{mesh}'")
