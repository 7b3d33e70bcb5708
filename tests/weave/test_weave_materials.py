"""Yarn materials of a woven sample (xrayraster.weave.materials) and how Sample.scene uses them."""

from __future__ import annotations

import numpy as np
import pytest

from xrayraster import Material
from xrayraster.core.errors import WeaveError
from xrayraster.weave import FibreBundle, Sample, Tracer, UnitCell, YarnMaterials

ENERGIES_KEV = np.array([15.0, 40.0, 80.0, 150.0])
RTOL = 5e-12  # Material rounds mass fractions to 12 significant digits
CARBON = Material.named("carbon_fibre")
EPOXY = Material.named("epoxy")
GLASS = Material.named("e_glass")


@pytest.fixture(scope="module")
def sample():
    return Sample(UnitCell(), cells=(1, 1), points_per_section=12, samples_per_mm=2.0)


def _by_name(scene):
    return {o.name: o for o in scene.objects}


@pytest.mark.parametrize("fibre, matrix, f", [(CARBON, EPOXY, 0.6), (GLASS, EPOXY, 0.55), (CARBON, GLASS, 1.0)])
def test_a_bundle_attenuates_as_its_fibre_and_matrix_by_volume(fibre, matrix, f):
    """A ray through the yarn crosses fibre over a fraction f of its path and matrix over the rest."""
    yarn = FibreBundle(fibre, f).material(matrix)
    expected = f * fibre.attenuation_per_mm(ENERGIES_KEV) + (1 - f) * matrix.attenuation_per_mm(ENERGIES_KEV)
    np.testing.assert_allclose(yarn.attenuation_per_mm(ENERGIES_KEV), expected, rtol=RTOL, atol=0)
    assert yarn.density == pytest.approx(f * fibre.density + (1 - f) * matrix.density, rel=1e-15)


def test_default_scene_is_epoxy_and_carbon_bundles(sample):
    scene = sample.scene()
    objects = _by_name(scene)
    assert objects["matrix"].material == EPOXY
    yarn = objects["weft_c0_l0_y0"].material
    assert yarn.density == pytest.approx(0.6 * 1.76 + 0.4 * 1.16, rel=1e-15)
    # C mass fraction: all of the fibre's carbon plus the epoxy's, over the yarn's mass per cm³
    w_c = (0.6 * 1.76 + 0.4 * 1.16 * EPOXY.mass_fractions["C"]) / (0.6 * 1.76 + 0.4 * 1.16)
    assert yarn.mass_fractions["C"] == pytest.approx(w_c, rel=1e-11)
    assert all(o.material == yarn for o in scene.objects[1:])
    assert scene.materials == (EPOXY, yarn)  # wefts and warps of equal material share one channel


def test_families_given_directly_or_as_bundles(sample):
    materials = YarnMaterials(matrix="pmma", weft="e_glass", warp=FibreBundle("carbon_fibre", 0.5))
    objects = _by_name(sample.scene(materials))
    pmma = Material.named("pmma")
    assert objects["matrix"].material == pmma
    assert objects["weft_c0_l4_y3"].material == GLASS
    warp = objects["binder_c0_x0_b0"].material
    assert warp.density == pytest.approx(0.5 * 1.76 + 0.5 * pmma.density, rel=1e-15)  # in the sample's matrix


def test_the_dict_form_sets_families_and_defaults_the_rest(sample):
    carbon = Material("carbon", ((6, 1.0),), 1.8)
    scene = sample.scene({"weft": carbon})
    default = YarnMaterials().resolve()
    assert scene.materials == (default["matrix"], carbon, default["warp"])
    with pytest.raises(WeaveError, match="unknown families"):
        sample.scene({"resin": "epoxy"})


def test_tracers_take_their_material_and_keep_family_label_and_priority(sample):
    materials = YarnMaterials(tracers=(Tracer("weft_c0_l2_y3"), Tracer("binder_c0_x0_b5", "steel", label=7)))
    objects = _by_name(sample.scene(materials))
    family = YarnMaterials().resolve()
    weft, binder = objects["weft_c0_l2_y3"], objects["binder_c0_x0_b5"]
    glass_bundle = FibreBundle("e_glass").material(EPOXY)
    assert weft.material == glass_bundle and glass_bundle.density == pytest.approx(0.6 * 2.54 + 0.4 * 1.16)
    assert (weft.label, weft.priority) == (2, 1)                   # the weft family's
    assert binder.material == Material.named("steel") and (binder.label, binder.priority) == (7, 2)
    for name in ("weft_c0_l2_y2", "weft_c0_l1_y3", "binder_c0_x0_b4"):
        assert objects[name].material == family["weft" if name.startswith("weft") else "warp"]
    assert objects["binder_c0_x0_b4"].label == 3


def test_an_unknown_tracer_yarn_is_named_before_meshing(sample, monkeypatch):
    monkeypatch.setattr(Sample, "meshes", lambda self: pytest.fail("meshed before checking the tracers"))
    with pytest.raises(WeaveError, match=r"tracers: no yarn named 'weft_c0_l9_y3'.*'weft_c0_l0_y0'"):
        sample.scene(YarnMaterials(tracers=(Tracer("weft_c0_l9_y3"),)))


@pytest.mark.parametrize("make, match", [
    (lambda: FibreBundle(fibre_fraction=0.0), r"FibreBundle.fibre_fraction must be a number in \(0, 1\]"),
    (lambda: FibreBundle(fibre_fraction=1.2), r"fibre_fraction .* got 1.2"),
    (lambda: FibreBundle(fibre_fraction=float("nan")), r"fibre_fraction"),
    (lambda: FibreBundle(fibre_fraction=True), r"fibre_fraction"),
    (lambda: FibreBundle(fibre="carbn"), r"FibreBundle.fibre: no material named 'carbn' in the library; known:"),
    (lambda: YarnMaterials(matrix="resin"), r"matrix: no material named 'resin'"),
    (lambda: YarnMaterials(matrix=FibreBundle()), r"matrix must be .* not a FibreBundle"),
    (lambda: YarnMaterials(warp=3), r"warp must be a material name"),
    (lambda: YarnMaterials(tracers=Tracer("weft_c0_l0_y0")), r"tracers must be a tuple of Tracer"),
    (lambda: YarnMaterials(tracers=(Tracer("weft_c0_l0_y0"), Tracer("weft_c0_l0_y0", "steel"))),
     r"tracers: yarns \['weft_c0_l0_y0'\] are given more than once"),
    (lambda: Tracer(""), r"Tracer.yarn must be"),
    (lambda: Tracer("weft_c0_l0_y0", "unobtainium"), r"Tracer weft_c0_l0_y0 material: no material named"),
    (lambda: Tracer("weft_c0_l0_y0", label=0), r"Tracer weft_c0_l0_y0 label must be an integer in \[1, 65535\]"),
])
def test_bad_materials_name_the_field(make, match):
    with pytest.raises(WeaveError, match=match):
        make()


def test_materials_of_the_wrong_type(sample):
    with pytest.raises(WeaveError, match="materials must be None, a YarnMaterials or a dict"):
        sample.scene("epoxy")
