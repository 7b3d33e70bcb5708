"""Import a textomos (TexGen-based) layer-to-layer textile section as a :class:`UnitCell`.

The key-by-key mapping is documented in docs/weave.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..core import fields
from ..core.errors import ConfigError, WeaveError
from ..core.validate import show
from .distort import Distortion
from .section import Section
from .spec import UnitCell

__all__ = ["TEXTOMOS_KEYS", "TextomosImport", "read_textomos"]


# textomos (Friemann et al., built on TexGen) layer-to-layer textile keys. Keys that describe the
# cell map to UnitCell fields; the rest are returned as they are (sample-level) or ignored (files).
_TEXTOMOS_CELL = ("unit_cell_weft_length", "unit_cell_warp_length", "unit_cell_thickness", "weft_yarns_per_layer",
                  "warp_yarns_per_layer", "number_of_yarn_layers", "weft_width_to_spacing_ratio",
                  "warp_width_to_spacing_ratio", "weft_to_warp_ratio")
_TEXTOMOS_OPTIONAL = ("weave_type", "weave_pattern", "tiling", "deform", "shift_unit_cell", "textile_resolution",
                      "cut_mesh", "mesh_paths")
TEXTOMOS_KEYS = _TEXTOMOS_CELL + _TEXTOMOS_OPTIONAL


@dataclass(frozen=True)
class TextomosImport:
    """What a textomos textile section describes: the cell, and the sample-level settings.

    ``deform`` is textomos' 12-number vector as given; ``distortion`` is its meaning here
    (:meth:`Distortion.from_textomos`), ready for ``Sample(..., distortion=...)``.
    """

    cell: UnitCell
    tiling: tuple[int, int, int] = (1, 1, 1)
    deform: tuple[float, ...] = ()
    shift_unit_cell: bool = False
    distortion: Distortion = field(default_factory=Distortion)


def read_textomos(d: dict, where: str = "textomos textile") -> TextomosImport:
    """A textomos ``layer2layer`` textile section as a :class:`UnitCell` plus tiling, deform (and its
    :class:`Distortion`), shift.

    Strict: keys outside :data:`TEXTOMOS_KEYS` are refused (pass the textile keys only, e.g.
    ``{k: v for k, v in config.items() if k in TEXTOMOS_KEYS}``).
    """
    d = fields.mapping(d, where)
    fields.only(d, set(TEXTOMOS_KEYS), where)
    kind = d.get("weave_type", "layer2layer")
    if kind != "layer2layer":
        raise ConfigError(f"{where}: weave_type must be 'layer2layer' (the only textomos weave imported), got {show(kind)}")
    v = {k: fields.required(d, k, where) for k in _TEXTOMOS_CELL}
    length_x = fields.number(v["unit_cell_weft_length"], "unit_cell_weft_length", where, positive=True)
    length_y = fields.number(v["unit_cell_warp_length"], "unit_cell_warp_length", where, positive=True)
    stack = fields.number(v["unit_cell_thickness"], "unit_cell_thickness", where, positive=True)
    w = fields.integer(v["weft_yarns_per_layer"], "weft_yarns_per_layer", where, 1)
    p = fields.integer(v["warp_yarns_per_layer"], "warp_yarns_per_layer", where, 1)
    layers = fields.integer(v["number_of_yarn_layers"], "number_of_yarn_layers", where, 1)
    share = fields.number(v["weft_to_warp_ratio"], "weft_to_warp_ratio", where, positive=True)

    # textomos: warp yarns stacked in every position, warp k resting between weft layers k and k+1
    # (gap k + 1); each [warp, weft, ±1] pushes the whole stack of that position one gap up or down
    # at that weft column (TexGen's CTextileWeave3D.PushUp / PushDown).
    shift = [[0] * w for _ in range(p)]
    pattern = d.get("weave_pattern", [])
    if not isinstance(pattern, list):
        raise ConfigError(f"{where}: weave_pattern must be a list of [warp, weft, 1 or -1], got {show(pattern)}")
    for i, row in enumerate(pattern):
        field = f"weave_pattern[{i}]"
        if not isinstance(row, list) or len(row) != 3:
            raise ConfigError(f"{where}: {field} must be [warp, weft, 1 or -1], got {show(row)}")
        warp = fields.integer(row[0], f"{field}[0] (warp)", where, 0, p - 1)
        weft = fields.integer(row[1], f"{field}[1] (weft)", where, 0, w - 1)
        if isinstance(row[2], bool) or row[2] not in (1, -1):
            raise ConfigError(f"{where}: {field}[2] must be 1 (push up) or -1 (push down), got {show(row[2])}")
        shift[warp][weft] += row[2]
    binders = p * layers
    position = tuple(b % p for b in range(binders))
    path = tuple(tuple(b // p + 1 + shift[b % p][j] for j in range(w)) for b in range(binders))
    warp_height = (1.0 - share) * stack / layers if share < 1 else 0.0
    surface = any(g <= 0 or g >= layers + 1 for row in path for g in row)
    margin_z = warp_height if surface else 0.0
    try:
        cell = UnitCell(
            weft_per_layer=w, weft_layers=layers + 1, warp_positions=p, binders=binders,
            binder_position=position, binder_path=path,
            warp_spacing=length_x / p, weft_spacing=length_y / w,
            warp_width_fraction=fields.number(v["warp_width_to_spacing_ratio"], "warp_width_to_spacing_ratio", where),
            weft_width_fraction=fields.number(v["weft_width_to_spacing_ratio"], "weft_width_to_spacing_ratio", where),
            weft_share=share, thickness=stack + 2 * margin_z, margin_z=margin_z,
            weft_section=Section("ellipse"), warp_section=Section("ellipse"),
        )
    except WeaveError as exc:
        raise ConfigError(f"{where}: {exc} (in the imported cell; see docs/weave.md for the mapping)") from None

    tiling = d.get("tiling", [1, 1, 1])
    tiling = fields.vector(tiling, "tiling", where, 3, "[x, y, z] cell repeats", element=fields.integer, lo=1)
    deform = d.get("deform", [])
    if not isinstance(deform, list) or len(deform) not in (0, 12):
        raise ConfigError(f"{where}: deform must be a list of 12 numbers (or empty), got {show(deform)}")
    deform = tuple(fields.number(x, f"deform[{i}]", where, nonnegative=True) for i, x in enumerate(deform))
    try:
        distortion = Distortion.from_textomos(deform)
    except WeaveError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    shift_cells = d.get("shift_unit_cell", False)
    if not isinstance(shift_cells, bool):
        raise ConfigError(f"{where}: shift_unit_cell must be true or false, got {show(shift_cells)}")
    return TextomosImport(cell=cell, tiling=tiling, deform=deform, shift_unit_cell=shift_cells, distortion=distortion)
