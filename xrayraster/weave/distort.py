"""Random distortions of a woven sample, reproducible from one integer seed.

A :class:`Distortion` holds amplitudes only (all 0 by default: the regular weave); a
:class:`~xrayraster.weave.sample.Sample` draws the random values from its ``seed``. Every
amplitude ``a`` scales a uniform draw in ``[-a, a]``:

- **node displacement** ``weft_node_mm`` / ``warp_node_mm`` (x, y, z; mm): each path node moves
  by its own draw (a binder's plateau of nodes over one weft moves as one, so it stays flat);
- **section scale** ``weft_scale`` / ``warp_scale`` (width, height; relative): the section's
  width and height at each node are multiplied by ``1 + draw``, so 0.1 gives factors in [0.9, 1.1];
- **section rotation** ``weft_rotation_deg`` / ``warp_rotation_deg``: the section turns about the
  path's tangent by the draw at each node;
- **layer shift** ``layer_shift_mm`` (x, y): every yarn of one stacked layer of unit cells moves
  in-plane by one draw per layer (stacked cells nest imperfectly; with one layer, a random offset
  of the weave in the box);
- **waviness** ``waviness_mm``: a smooth in-plane displacement across each yarn (y for a weft,
  x for a warp), ``(waviness_mm / 3) · Σ_m sin(2π s / λ_m + φ_m)`` over three terms, ``s`` the
  yarn's axial coordinate in the sample, ``λ_m`` uniform in ``[λ, 2λ]`` (λ =
  ``waviness_wavelength_mm``, the shortest wavelength), ``φ_m`` uniform in ``[0, 2π)``: its
  magnitude never exceeds ``waviness_mm``.

Scale and rotation are carried between nodes by :func:`xrayraster.weave.sweep.smooth_profile`
(C², no overshoot); displacements move the nodes of the yarn's C² spline. A yarn's random numbers
come from a generator seeded by ``(seed, the yarn's name)`` (:func:`yarn_rng`), drawn in a fixed
order whatever the amplitudes, so they do not depend on the other yarns, and changing one
amplitude only rescales its own part. docs/weave.md ("Distortions") has the table and the rules.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields

import numpy as np

from ..core import fields
from ..core.errors import ConfigError, WeaveError
from ..core.validate import show
from .spec import UnitCell

__all__ = ["ALONG_FRACTION", "WAVELENGTH_NODES", "WAVINESS_TERMS", "Distortion", "layer_shift", "yarn_draws",
           "yarn_rng"]

#: Sinusoids in each yarn's waviness.
WAVINESS_TERMS = 3
#: The waviness's shortest wavelength must span this many node spacings, so the spline through
#: the nodes resolves it (a cubic spline through a sinusoid sampled 4 times a wavelength follows it
#: to 2.5 % of its amplitude; 8 times, 0.1 %).
WAVELENGTH_NODES = 4
#: A node may move along its yarn by at most this fraction of the node spacing, so neighbouring
#: nodes keep at least half their spacing (and their order).
ALONG_FRACTION = 0.25

_VECTORS = {"weft_node_mm": 3, "warp_node_mm": 3, "weft_scale": 2, "warp_scale": 2, "layer_shift_mm": 2}


def _amplitude(name: str, value, hi: float | None = None, fix: str = "") -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
        raise WeaveError(f"{name} must be a finite amplitude >= 0, got {show(value)}")
    if hi is not None and value >= hi:
        raise WeaveError(f"{name} must be < {show(hi)}, got {show(value)}{fix}")
    return float(value)


@dataclass(frozen=True)
class Distortion:
    """Amplitudes of the random distortions (module docstring; docs/weave.md); all 0 is the regular weave.

    Node displacements and the layer shift in mm, scales relative (must be < 1), rotations in
    degrees (must be < 90), ``waviness_mm`` in mm with its shortest wavelength
    ``waviness_wavelength_mm`` (mm, > 0).
    """

    weft_node_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    warp_node_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    weft_scale: tuple[float, float] = (0.0, 0.0)
    warp_scale: tuple[float, float] = (0.0, 0.0)
    weft_rotation_deg: float = 0.0
    warp_rotation_deg: float = 0.0
    layer_shift_mm: tuple[float, float] = (0.0, 0.0)
    waviness_mm: float = 0.0
    waviness_wavelength_mm: float = 20.0

    def __post_init__(self):
        for name, length in _VECTORS.items():
            value = getattr(self, name)
            if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != length:
                form = "(x, y, z)" if length == 3 else "(width, height)" if "scale" in name else "(x, y)"
                raise WeaveError(f"{name} must be {length} amplitudes {form}, got {show(value)}")
            hi, fix = (1.0, " (a relative amplitude: 1 would shrink the section to nothing)") if "scale" in name \
                else (None, "")
            object.__setattr__(self, name, tuple(_amplitude(f"{name}[{i}]", x, hi, fix) for i, x in enumerate(value)))
        for name in ("weft_rotation_deg", "warp_rotation_deg"):
            object.__setattr__(self, name, _amplitude(name, getattr(self, name), 90.0,
                                                      " degrees (a flat tow turned that far stands on its edge)"))
        object.__setattr__(self, "waviness_mm", _amplitude("waviness_mm", self.waviness_mm))
        wavelength = _amplitude("waviness_wavelength_mm", self.waviness_wavelength_mm)
        if wavelength == 0:
            raise WeaveError("waviness_wavelength_mm must be > 0 mm (the waviness's shortest wavelength), got 0.0")
        object.__setattr__(self, "waviness_wavelength_mm", wavelength)

    @property
    def is_zero(self) -> bool:
        """True when every amplitude is 0 (the wavelength aside): the sample is the regular weave."""
        return not any(any(getattr(self, name)) for name in _VECTORS) and not (
            self.weft_rotation_deg or self.warp_rotation_deg or self.waviness_mm)

    def varies_section(self, family: str) -> bool:
        """True when ``family`` (``weft`` or ``warp``) has a section scale or rotation amplitude."""
        return any(getattr(self, f"{family}_scale")) or bool(getattr(self, f"{family}_rotation_deg"))

    def check(self, cell: UnitCell, plateau_mm: float = 0.0) -> None:
        """The limits that depend on the cell: along-yarn node displacement, wavelength, layer shift.

        ``plateau_mm`` is the length (along y) of a binder's plateau of nodes over one weft, which
        moves as one: the run between plateaus is the binder's shortest node spacing.
        """
        spacing = (("weft", 0, cell.warp_spacing), ("warp", 1, cell.weft_spacing - plateau_mm))
        for family, axis, step in spacing:
            limit = ALONG_FRACTION * step
            value = getattr(self, f"{family}_node_mm")[axis]
            if value > limit:
                raise WeaveError(
                    f"distortion.{family}_node_mm[{axis}] ({'xy'[axis]}, along the {family}) is {show(value)} mm, above "
                    f"{ALONG_FRACTION} × the node spacing along it ({step:.4g} mm) = {limit:.4g} mm: neighbouring "
                    "nodes could meet or swap; lower it")
        if self.waviness_mm:
            step = max(cell.warp_spacing, cell.weft_spacing)
            if self.waviness_wavelength_mm < WAVELENGTH_NODES * step:
                raise WeaveError(
                    f"distortion.waviness_wavelength_mm ({show(self.waviness_wavelength_mm)} mm) must be >= "
                    f"{WAVELENGTH_NODES} node spacings ({WAVELENGTH_NODES} × {step:.4g} mm = "
                    f"{WAVELENGTH_NODES * step:.4g} mm) so the yarn's spline resolves it; raise it")
        for axis, period in enumerate(cell.size[:2]):
            if self.layer_shift_mm[axis] > period / 2:
                raise WeaveError(
                    f"distortion.layer_shift_mm[{axis}] ({show(self.layer_shift_mm[axis])} mm) must be <= half the "
                    f"cell's period in {'xy'[axis]} ({period / 2:.4g} mm): the weave repeats, so a larger shift "
                    "is a smaller one the other way; lower it")

    # Dict form: the [weave.distortion] table.

    def to_dict(self) -> dict:
        """The dict form (TOML and JSON ready), the field names as keys."""
        return {f.name: list(v) if isinstance(v := getattr(self, f.name), tuple) else v
                for f in dataclass_fields(self)}

    @classmethod
    def from_dict(cls, d: dict, where: str = "[weave.distortion]") -> Distortion:
        """A distortion from its dict form; errors name ``where`` and the field. Missing keys are 0."""
        d = fields.mapping(d, where)
        fields.only(d, {f.name for f in dataclass_fields(cls)}, where)
        kwargs = {}
        for key, value in d.items():
            if key in _VECTORS:
                form = f"a list of {_VECTORS[key]} amplitudes"
                kwargs[key] = fields.vector(value, key, where, _VECTORS[key], form, nonnegative=True)
            else:
                kwargs[key] = fields.number(value, key, where, nonnegative=True)
        try:
            return cls(**kwargs)
        except WeaveError as exc:
            raise ConfigError(f"{where}: {exc}") from None

    @classmethod
    def from_textomos(cls, deform) -> Distortion:
        """textomos' 12-number ``deform`` (weft then warp: section x/y scaling %, rotation °, node x/y/z).

        Empty gives no distortion. textomos multiplies a section by ``1 − U·p/100`` (U uniform in
        [0, 1)), a factor in (1 − p/100, 1]; here the factor is centred on 1 with the same spread,
        so the scale amplitude is ``p / 200`` (textomos' mean shrink of p/200 is not reproduced;
        lower the cell's width fractions for it). Rotation and node displacement are uniform in
        ``[-a, a]`` in both; textomos' node displacement is in the length unit of its cell sizes,
        which the importer reads as mm, so it maps unchanged. textomos allows scalings up to 100 %.
        """
        if isinstance(deform, (str, bytes)) or not hasattr(deform, "__len__") or len(deform) not in (0, 12):
            raise WeaveError(f"deform must be 12 numbers (weft then warp: x/y scaling %, rotation °, node "
                             f"x/y/z displacement) or empty, got {show(deform)}")
        if not len(deform):
            return cls()
        for i, value in enumerate(deform):
            _amplitude(f"deform[{i}]", value)
            if i in (0, 1, 6, 7) and value > 100:
                raise WeaveError(f"deform[{i}] (a section scaling, %) must be <= 100, got {show(value)}")
        kwargs = {}
        for family, base in (("weft", 0), ("warp", 6)):
            kwargs[f"{family}_scale"] = (deform[base] / 200.0, deform[base + 1] / 200.0)
            kwargs[f"{family}_rotation_deg"] = deform[base + 2]
            kwargs[f"{family}_node_mm"] = tuple(deform[base + 3: base + 6])
        return cls(**kwargs)


def yarn_rng(seed: int, name: str) -> np.random.Generator:
    """The generator of one yarn (or layer): seeded by ``seed`` and the bytes of its ``name``."""
    return np.random.default_rng([seed, *name.encode("ascii")])


def layer_shift(distortion: Distortion, seed: int, cz: int) -> np.ndarray:
    """The in-plane shift (x, y; mm) of stacked cell layer ``cz``: uniform in ``±layer_shift_mm``."""
    return yarn_rng(seed, f"layer_shift_c{cz}").uniform(-1.0, 1.0, 2) * np.asarray(distortion.layer_shift_mm)


def yarn_draws(distortion: Distortion, family: str, rng: np.random.Generator, axial: np.ndarray):
    """One yarn's random values at its node groups (``axial``: their axial coordinates, mm).

    Returns ``(displacement (g, 3) mm, scale (g, 2), rotation (g,) degrees)``; the displacement
    includes the waviness, across the yarn in-plane (y for a weft, x for a warp). Draws in a fixed
    order whatever the amplitudes.
    """
    d = distortion
    g = len(axial)
    node = rng.uniform(-1.0, 1.0, (g, 3)) * np.asarray(getattr(d, f"{family}_node_mm"))
    scale = 1.0 + rng.uniform(-1.0, 1.0, (g, 2)) * np.asarray(getattr(d, f"{family}_scale"))
    rotation = rng.uniform(-1.0, 1.0, g) * getattr(d, f"{family}_rotation_deg")
    wavelengths = d.waviness_wavelength_mm * rng.uniform(1.0, 2.0, WAVINESS_TERMS)
    phases = rng.uniform(0.0, 2 * np.pi, WAVINESS_TERMS)
    waves = np.sin(2 * np.pi * np.asarray(axial)[:, None] / wavelengths + phases).sum(axis=1)
    node[:, 0 if family == "warp" else 1] += d.waviness_mm / WAVINESS_TERMS * waves
    return node, scale, rotation
