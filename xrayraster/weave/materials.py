"""The materials of a woven sample: its matrix, each yarn family's material, and tracer yarns.

A yarn family (``weft``, ``warp``) takes a material directly (a library name such as ``"e_glass"``,
or a :class:`~xrayraster.Material`) or a :class:`FibreBundle`: fibres impregnated with the
sample's matrix at an intra-yarn fibre volume fraction ``f``. The bundle is an ideal mixture by
volume (:meth:`~xrayraster.Material.mixture`): density ``f·ρ_fibre + (1 − f)·ρ_matrix``, element
mass fractions weighted by each part's mass, so its linear attenuation is
``f·μ_fibre + (1 − f)·μ_matrix``; no voids. The reference pipeline's later code builds its yarn
material from fibre and resin the same way.

The defaults: an epoxy matrix (``"epoxy"``, DGEBA, 1.16 g/cm³) and carbon-fibre bundles
(``"carbon_fibre"``, 1.76 g/cm³) at ``fibre_fraction`` 0.6 for both families, giving yarns of
1.52 g/cm³. Compacted carbon tows usually hold 0.5–0.7 of their volume in fibres; we cite no
single published value for it: set it from your sample (a tow of ``N`` fibres of diameter ``d``
in a cross-section of area ``A`` has ``f = N·π·d²/4 / A``).

Real samples carry a few tracer yarns (typically glass fibre, bright in a scan of carbon): a
:class:`Tracer` names one yarn as :meth:`Sample.yarns() <xrayraster.weave.Sample.yarns>` does
(e.g. ``"weft_c0_l2_y3"``) and gives its material, by default e-glass fibres at fraction 0.6 in
the matrix. A tracer keeps its family's label and priority unless it gives a ``label``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from ..core.errors import MaterialError, WeaveError
from ..core.validate import show
from ..scene.materials import Material

__all__ = ["FAMILIES", "FibreBundle", "Tracer", "YarnMaterials", "as_yarn_materials"]

FAMILIES = ("matrix", "weft", "warp")


def _material(value, field: str) -> Material:
    """``value`` (a library name or a Material) as a Material; errors name ``field``."""
    if isinstance(value, Material):
        return value
    if isinstance(value, str):
        try:
            return Material.named(value)
        except MaterialError as exc:
            raise WeaveError(f"{field}: {exc}") from None
    raise WeaveError(f"{field} must be a material name of the library (e.g. 'epoxy') or an xr.Material, "
                     f"got {show(value)}")


@dataclass(frozen=True)
class FibreBundle:
    """A yarn of ``fibre`` (a library name or a Material) and the sample's matrix, the fibres
    taking ``fibre_fraction`` of the yarn's volume, in (0, 1] (1: no matrix in the yarn)."""

    fibre: str | Material = "carbon_fibre"
    fibre_fraction: float = 0.6

    def __post_init__(self):
        _material(self.fibre, "FibreBundle.fibre")
        f = self.fibre_fraction
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0 < f <= 1:
            raise WeaveError(f"FibreBundle.fibre_fraction must be a number in (0, 1], the fibres' share of "
                             f"the yarn's volume (usually 0.5-0.7), got {show(f)}")

    def material(self, matrix: Material) -> Material:
        """The yarn: fibre and ``matrix`` mixed by volume."""
        f = float(self.fibre_fraction)
        return Material.mixture([(_material(self.fibre, "FibreBundle.fibre"), f), (matrix, 1.0 - f)])


def _yarn_material(value, matrix: Material, field: str) -> Material:
    if isinstance(value, FibreBundle):
        return value.material(matrix)
    return _material(value, field)


@dataclass(frozen=True)
class Tracer:
    """Yarn ``yarn`` (named as ``Sample.yarns()`` names it) made of ``material`` (a library name,
    a Material or a FibreBundle in the sample's matrix), with scene label ``label`` (None: its
    family's)."""

    yarn: str
    material: str | Material | FibreBundle = FibreBundle("e_glass")
    label: int | None = None

    def __post_init__(self):
        if not isinstance(self.yarn, str) or not self.yarn:
            raise WeaveError(f"Tracer.yarn must be a yarn's name as Sample.yarns() gives it "
                             f"(e.g. 'weft_c0_l2_y3'), got {show(self.yarn)}")
        if not isinstance(self.material, FibreBundle):
            _material(self.material, f"Tracer {self.yarn} material")
        label = self.label
        if label is not None and (isinstance(label, bool) or not isinstance(label, int) or not 0 < label < 65536):
            raise WeaveError(f"Tracer {self.yarn} label must be an integer in [1, 65535] or None (its family's "
                             f"label), got {show(label)}")


@dataclass(frozen=True)
class YarnMaterials:
    """The sample's materials: ``matrix`` (a library name or a Material), ``weft`` and ``warp``
    (a name, a Material or a FibreBundle in the matrix), and ``tracers`` (a tuple of Tracer, one
    per yarn at most)."""

    matrix: str | Material = "epoxy"
    weft: str | Material | FibreBundle = FibreBundle()
    warp: str | Material | FibreBundle = FibreBundle()
    tracers: tuple[Tracer, ...] = ()

    def __post_init__(self):
        if isinstance(self.matrix, FibreBundle):
            raise WeaveError("matrix must be a material name or an xr.Material, not a FibreBundle: it is what "
                             "the bundles are impregnated with")
        tracers = self.tracers
        if not isinstance(tracers, (tuple, list)) or not all(isinstance(t, Tracer) for t in tracers):
            raise WeaveError(f"tracers must be a tuple of Tracer (e.g. (Tracer('weft_c0_l2_y3'),)), "
                             f"got {show(tracers)}")
        object.__setattr__(self, "tracers", tuple(tracers))
        names = [t.yarn for t in self.tracers]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise WeaveError(f"tracers: yarns {twice} are given more than once; give one Tracer per yarn")
        self.resolve()  # checks every material name now (cheap: library materials are cached)

    def resolve(self) -> dict[str, Material]:
        """The concrete Material of each family: ``{"matrix": ..., "weft": ..., "warp": ...}``."""
        matrix = _material(self.matrix, "matrix")
        return {"matrix": matrix, "weft": _yarn_material(self.weft, matrix, "weft"),
                "warp": _yarn_material(self.warp, matrix, "warp")}

    def tracer_materials(self) -> dict[str, tuple[Material, int | None]]:
        """``{yarn name: (Material, label or None)}`` for the tracers."""
        matrix = _material(self.matrix, "matrix")
        return {t.yarn: (_yarn_material(t.material, matrix, f"Tracer {t.yarn} material"), t.label)
                for t in self.tracers}


def as_yarn_materials(materials) -> YarnMaterials:
    """``materials`` as YarnMaterials: None (the defaults), a YarnMaterials, or a dict
    ``{family: material}`` of its ``matrix``, ``weft`` and ``warp`` fields (the rest default)."""
    if materials is None:
        return YarnMaterials()
    if isinstance(materials, YarnMaterials):
        return materials
    if isinstance(materials, Mapping):
        unknown = set(materials) - set(FAMILIES)
        if unknown:
            raise WeaveError(f"materials: unknown families {sorted(unknown, key=str)}; use matrix, weft, warp")
        return YarnMaterials(**materials)
    raise WeaveError(f"materials must be None, a YarnMaterials or a dict of matrix/weft/warp to materials, "
                     f"got {show(materials)}")
