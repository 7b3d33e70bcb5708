"""The unit cell of a weave (layer-to-layer angle interlock by default; 2D plies too): what a user measures on the loom.

Frame (mm): weft yarns run along x and are spaced along y; warp yarns (binders, and optional
straight stuffers) run along y and are spaced along x; z is the thickness, weft layer 0 at the
bottom. The cell spans ``[0, size[0]] × [0, size[1]] × [0, size[2]]`` and tiles in x and y.

A binder's path is its *gap* at each weft column: gap ``g`` is the space between weft layers
``g − 1`` and ``g``, so gap 0 lies below the bottom weft layer and gap ``weft_layers`` above the
top one. Weft column ``j`` sits at ``y = (j + 0.5) · weft_spacing``. The ``family`` sets how the
binders run (:mod:`~xrayraster.weave.families`). Every field, its unit and its default are
documented in docs/weave.md; the dict form (:meth:`UnitCell.to_dict`) uses the same names as the
``[weave]`` table of a TOML file.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields

from ..core import fields
from ..core.choices import check_choice
from ..core.errors import ConfigError, WeaveError
from ..core.validate import show
from .families import FAMILIES, FAMILY_FIELDS, FAMILY_NAMES, PLIES, WARP_POSITIONS, WEFT_LAYERS, Family
from .checks import checked_float, checked_int, set_field
from .patterns import checked_pattern
from .section import Section

__all__ = ["UnitCell"]

@dataclass(frozen=True)
class UnitCell:
    """One repeat of a weave of the ``family`` (:mod:`~xrayraster.weave.families`): a 3D stack of weft
    layers and binders, or 2D plies; lengths in mm (docs/weave.md).

    A 2D family (plain, twill, satin) takes ``pattern`` (else its own, from ``floats`` or
    ``harness``), ``plies`` (4) and ``ply_shift_mm`` ((0, 0)); it sets ``warp_positions`` and
    ``weft_per_layer`` from the pattern, ``weft_layers`` to the plies (a weft layer each), no
    stuffers or binders, ``weft_share`` 0.5 and ``margin_z`` a tenth of a ply. The rest below is
    the 3D families'.

    Fields left as None take the family's values. Layer to layer (the default), ``binders``,
    ``binder_position`` and ``binder_path`` are generated: one binder per adjacent weft-layer pair
    in every warp position (``warp_positions · (weft_layers − 1)`` binders), binder ``b`` in position
    ``b % warp_positions`` linking weft layers ``k`` and ``k + 1`` with
    ``k = (b // warp_positions) % (weft_layers − 1)``: over layer ``k + 1`` (gap ``k + 2``) for the
    first half of the columns, under layer ``k`` (gap ``k``) for the second, the binders of one
    position in phase and each position shifted by ``weft_per_layer / warp_positions`` columns.
    ``weft_per_layer`` is 4 but for the angle interlocks (one period of their binders), ``stuffers``
    0 but for the orthogonal weave (``weft_layers − 1``), ``margin_z`` 0.4 mm layer to layer and
    the binders' height in the other families. The warp columns across the cell are groups
    of ``binder_ratio`` binder positions followed, where there are stuffers, by ``warp_ratio``
    stuffer columns; ``binder_step`` and ``binder_offset`` belong to the angle interlocks.
    """

    weft_per_layer: int | None = None
    weft_layers: int | None = None
    warp_positions: int | None = None
    binders: int | None = None
    binder_position: tuple[int, ...] | None = None
    binder_path: tuple[tuple[int, ...], ...] | None = None
    stuffers: int | None = None
    warp_spacing: float = 2.5
    weft_spacing: float = 2.5
    warp_width_fraction: float = 0.8
    weft_width_fraction: float = 0.9
    weft_share: float | None = None
    thickness: float = 4.0
    weft_section: Section = Section("power_ellipse", exponent=3.0)
    warp_section: Section = Section("lenticular")
    margin_xy: float = 0.0
    margin_z: float | None = None
    family: str = "layer_to_layer"
    warp_ratio: int | None = None
    binder_ratio: int | None = None
    binder_step: int | None = None
    binder_offset: int | None = None
    pattern: tuple[tuple[int, ...], ...] | None = None
    floats: tuple[int, int] | None = None
    harness: int | None = None
    plies: int | None = None
    ply_shift_mm: tuple[float, float] | None = None

    def __post_init__(self):
        check_choice(self.family, FAMILY_NAMES, "family", WeaveError)
        family = FAMILIES[self.family]
        for name in FAMILY_FIELDS:
            if name not in family.takes and getattr(self, name) is not None:
                takers = [f for f, rule in FAMILIES.items() if name in rule.takes]
                raise WeaveError(f"{name}: family {self.family!r} takes no {name} (it belongs to "
                                 f"{', '.join(map(repr, takers))}); remove it or change family")
        if family.plies:
            self._lay_plies(family)
        else:
            self._lay_stack(family)
        for name in ("warp_spacing", "weft_spacing", "thickness"):
            set_field(self, name, checked_float(name, getattr(self, name), lo=0.0, fix=" mm"))
        for name in ("warp_width_fraction", "weft_width_fraction"):
            set_field(self, name, checked_float(name, getattr(self, name), lo=0.0, hi=1.0,
                                     fix=" (a yarn wider than its spacing overlaps its neighbour; "
                                         "lower the fraction or widen the spacing)"))
        share = family.default_weft_share if self.weft_share is None else self.weft_share
        set_field(self, "weft_share", checked_float("weft_share", share, lo=0.0, hi=1.0, hi_open=True,
                                         fix=" (the weft's share of the yarn stack thickness)"))
        if self.margin_z is None:
            set_field(self, "margin_z", family.default_margin_z(self.thickness, self.weft_share, self.weft_layers))
        for name in ("margin_xy", "margin_z"):
            set_field(self, name, checked_float(name, getattr(self, name), lo=0.0, lo_open=False, fix=" mm"))
        for name in ("weft_section", "warp_section"):
            section = getattr(self, name)
            if isinstance(section, str):
                section = Section(section)
            if not isinstance(section, Section):
                raise WeaveError(f"{name} must be a Section (or a shape name), got {show(section)}")
            section.check(name)
            set_field(self, name, section)
        if self.thickness <= 2 * self.margin_z:
            raise WeaveError(f"thickness ({show(self.thickness)} mm) must exceed 2 · margin_z "
                             f"({show(2 * self.margin_z)} mm): no room is left for the yarns; "
                             "raise thickness or lower margin_z")
        if not family.plies:
            self._lay_binders(family)

    def _lay_plies(self, family: Family) -> None:
        """A 2D family's fields: the pattern (its rows the warps, its columns the wefts), the plies
        (a weft layer each) and their shift; the 3D fields set as a ply has them (no stuffers, no binders)."""
        if self.floats is not None:
            floats = self.floats
            if isinstance(floats, (str, bytes)) or not hasattr(floats, "__len__") or len(floats) != 2:
                raise WeaveError(f"floats must be [over, under], the wefts a twill's warp runs over then under, "
                                 f"got {show(floats)}")
            set_field(self, "floats", (checked_int("floats[0] (over)", floats[0], 1), checked_int("floats[1] (under)", floats[1], 1)))
        if self.harness is not None:
            set_field(self, "harness", checked_int("harness", self.harness, 5, " (a satin needs at least 5 wefts in its repeat)"))
        given = [name for name in ("floats", "harness") if getattr(self, name) is not None]
        if self.pattern is not None and given:
            raise WeaveError(f"give pattern or {given[0]}, not both: a pattern sets every crossing itself")
        pattern = family.pattern(None if self.pattern is None else checked_pattern(self.pattern), self.floats,
                                 self.harness)
        set_field(self, "pattern", pattern)
        for name, count, what in (("warp_positions", len(pattern), "rows"), ("weft_per_layer", len(pattern[0]),
                                                                            "columns")):
            if getattr(self, name) is not None and getattr(self, name) != count:
                raise WeaveError(f"{name} ({show(getattr(self, name))}) must equal the pattern's {what} ({count}): "
                                 f"a {self.family} cell has a warp per row and a weft per column; leave {name} out")
            set_field(self, name, count)
        plies = checked_int("plies", PLIES if self.plies is None else self.plies, 1, " (plies stacked in the cell)")
        set_field(self, "plies", plies)
        shift = (0.0, 0.0) if self.ply_shift_mm is None else self.ply_shift_mm
        if isinstance(shift, (str, bytes)) or not hasattr(shift, "__len__") or len(shift) != 2:
            raise WeaveError(f"ply_shift_mm must be [x, y], each ply's shift from the one below (mm), got {show(shift)}")
        set_field(self, "ply_shift_mm", (checked_float("ply_shift_mm[0]", shift[0]), checked_float("ply_shift_mm[1]", shift[1])))
        for name, value in (("weft_layers", plies), ("stuffers", 0), ("warp_ratio", 1), ("binder_ratio", 1)):
            set_field(self, name, value)
        set_field(self, "binder_position", ())
        set_field(self, "binder_path", ())

    def _lay_stack(self, family: Family) -> None:
        """A 3D family's weft layers, columns and warp positions, with its own defaults."""
        n = checked_int("weft_layers", WEFT_LAYERS if self.weft_layers is None else self.weft_layers, 2,
                 " (a 3D weave holds at least two weft layers)")
        set_field(self, "weft_layers", n)
        step = offset = None
        if "binder_step" in family.takes:
            step = checked_int("binder_step", 1 if self.binder_step is None else self.binder_step, 1,
                        " (weft columns a binder takes to climb one gap)")
            set_field(self, "binder_step", step)
        if "binder_offset" in family.takes:
            offset = checked_int("binder_offset", 1 if self.binder_offset is None else self.binder_offset, 0,
                          " (weft columns between the paths of neighbouring binder positions)")
            set_field(self, "binder_offset", offset)
        w = self.weft_per_layer
        w = family.default_weft_per_layer(n, step or 1) if w is None else w
        w = checked_int("weft_per_layer", w, 1, " (weft yarns per layer in the cell)")
        set_field(self, "weft_per_layer", w)
        period = family.period(n, step or 1)
        if period and w % period:
            raise WeaveError(f"weft_per_layer ({w}) must be a multiple of the binders' period, 2 · weft_layers · "
                             f"binder_step = {period} columns, so the cell repeats; use {period} or "
                             f"{2 * period}")
        p = checked_int("warp_positions", WARP_POSITIONS if self.warp_positions is None else self.warp_positions, 1,
                 " (warp positions across the cell)")
        set_field(self, "warp_positions", p)
        set_field(self, "warp_ratio", checked_int("warp_ratio", 1 if self.warp_ratio is None else self.warp_ratio, 1,
                                      " (stuffer columns after each group of binder positions)"))
        br = checked_int("binder_ratio", 1 if self.binder_ratio is None else self.binder_ratio, 1,
                  " (binder positions in each group)")
        set_field(self, "binder_ratio", br)
        if p % br:
            raise WeaveError(f"warp_positions ({p}) must be a multiple of binder_ratio ({br}): the warp columns "
                             "repeat in groups of binder_ratio binder positions")
        stuffers = family.default_stuffers(n) if self.stuffers is None else self.stuffers
        stuffers = checked_int("stuffers", stuffers, 0)
        set_field(self, "stuffers", stuffers)
        if stuffers > n - 1:
            raise WeaveError(f"stuffers must be <= weft_layers - 1 = {n - 1} (one per gap between weft layers), "
                             f"got {stuffers}")

    def _lay_binders(self, family: Family) -> None:
        """A 3D family's binders: their count, positions and paths (generated or checked), and room for them."""
        n, w, p = self.weft_layers, self.weft_per_layer, self.warp_positions
        step, offset = self.binder_step, self.binder_offset
        b = self.binders
        b = family.binder_count(p, n) if b is None else checked_int("binders", b, 1, " (binder warp yarns per cell)")
        set_field(self, "binders", b)
        set_field(self, "binder_position", self._positions(b, p))
        set_field(self, "binder_path", self._paths(b, n, w, p, step or 1, offset or 0))
        self._check_room(n)

    def _positions(self, b: int, p: int) -> tuple[int, ...]:
        if self.binder_position is None:
            return tuple(i % p for i in range(b))
        pos = self.binder_position
        if isinstance(pos, (str, bytes)) or not hasattr(pos, "__len__") or len(pos) != b:
            raise WeaveError(f"binder_position must list one warp position per binder ({b}), got {show(pos)}")
        out = []
        for i, x in enumerate(pos):
            x = checked_int(f"binder_position[{i}]", x, 0)
            if x >= p:
                raise WeaveError(f"binder_position[{i}] must be in 0..{p - 1} (warp_positions - 1), got {x}; "
                                 "raise warp_positions or move the binder")
            out.append(x)
        return tuple(out)

    def _paths(self, b: int, n: int, w: int, p: int, step: int, offset: int) -> tuple[tuple[int, ...], ...]:
        family = FAMILIES[self.family]
        if self.binder_path is None:
            return tuple(family.path(i, n, w, p, step, offset) for i in range(b))
        paths = self.binder_path
        if isinstance(paths, (str, bytes)) or not hasattr(paths, "__len__") or len(paths) != b:
            raise WeaveError(f"binder_path must hold one path per binder ({b}), got "
                             f"{len(paths) if hasattr(paths, '__len__') else show(paths)}; give binders = the "
                             "number of paths or one path per binder")
        out = []
        for i, path in enumerate(paths):
            if isinstance(path, (str, bytes)) or not hasattr(path, "__len__") or len(path) != w:
                raise WeaveError(f"binder_path[{i}] must give one gap per weft column ({w} = weft_per_layer), "
                                 f"got {show(path)}")
            gaps = []
            for j, g in enumerate(path):
                g = checked_int(f"binder_path[{i}][{j}]", g, 0, f" (gaps run 0..{n} = weft_layers)")
                if g > n:
                    raise WeaveError(f"binder_path[{i}][{j}] = {g} leaves the weft stack: gaps run 0 (below weft "
                                     f"layer 0) to {n} (above the top layer, weft_layers = {n})")
                gaps.append(g)
            family.check_path(i, tuple(gaps), n)
            out.append(tuple(gaps))
        return tuple(out)

    def _check_room(self, n: int) -> None:
        """Binders of one position never share a gap in one column; surface loops fit in margin_z."""
        for j in range(self.weft_per_layer):
            seen = {}
            for i, (pos, path) in enumerate(zip(self.binder_position, self.binder_path)):
                other = seen.setdefault((pos, path[j]), i)
                if other != i:
                    raise WeaveError(f"binder_path: binders {other} and {i} share warp position {pos} and gap "
                                     f"{path[j]} at weft column {j}; give one of them another gap or position")
        surface = any(g in (0, n) for path in self.binder_path for g in path)
        if surface and self.margin_z < self.warp_height - 1e-12:
            h = self.warp_height
            raise WeaveError(f"margin_z ({show(self.margin_z)} mm) is thinner than the binders ({h:.4g} mm "
                             f"high) that binder_path loops over the outer weft layers (gap 0 or {n}): the "
                             f"thickness is too small for the yarns; raise margin_z to >= {h:.4g} mm (and "
                             "thickness with it) or lower weft_share")

    # Derived values (mm) for the mesher.

    @property
    def warp_groups(self) -> int:
        """Groups of ``binder_ratio`` binder positions across the cell."""
        return self.warp_positions // self.binder_ratio

    @property
    def warp_columns(self) -> int:
        """Warp columns across x: binder positions, and ``warp_ratio`` stuffer columns after each group
        of them when stuffers > 0."""
        return self.warp_positions + (self.warp_groups * self.warp_ratio if self.stuffers else 0)

    @property
    def size(self) -> tuple[float, float, float]:
        """Cell size (x, y, z) in mm; x and y are the periods, z the thickness with its margins."""
        return (self.warp_columns * self.warp_spacing, self.weft_per_layer * self.weft_spacing, self.thickness)

    @property
    def stack_thickness(self) -> float:
        """The weft layers and the binder gaps between them: thickness − 2 · margin_z (mm)."""
        return self.thickness - 2 * self.margin_z

    @property
    def weft_width(self) -> float:
        return self.weft_width_fraction * self.weft_spacing

    @property
    def warp_width(self) -> float:
        return self.warp_width_fraction * self.warp_spacing

    @property
    def weft_height(self) -> float:
        """weft_share of the stack, over the weft layers."""
        return self.weft_share * self.stack_thickness / self.weft_layers

    @property
    def warp_height(self) -> float:
        """The rest of the stack, over the weft_layers − 1 gaps between weft layers (in plies: over the plies)."""
        gaps = self.weft_layers if FAMILIES[self.family].plies else self.weft_layers - 1
        return (1.0 - self.weft_share) * self.stack_thickness / gaps

    @property
    def ply_pitch(self) -> float:
        """A ply's thickness (mm): the stack over the plies (2D families)."""
        return self.stack_thickness / self.weft_layers

    def ply_z(self, ply: int) -> float:
        """z of ply ``ply``'s mid-plane (mm), the bottom ply 0 (2D families)."""
        return self.margin_z + (ply + 0.5) * self.ply_pitch

    @property
    def weft_layer_z(self) -> tuple[float, ...]:
        """z of each weft layer's centre, bottom to top (mm)."""
        pitch = self.weft_height + self.warp_height
        return tuple(self.margin_z + self.weft_height / 2 + i * pitch for i in range(self.weft_layers))

    def gap_z(self, gap: int) -> float:
        """z of a warp yarn's centre in ``gap`` (0 below the bottom weft layer .. weft_layers above the top)."""
        if isinstance(gap, bool) or not isinstance(gap, numbers.Integral) or not 0 <= gap <= self.weft_layers:
            raise WeaveError(f"gap must be an integer in 0..{self.weft_layers}, got {show(gap)}")
        return self.margin_z + gap * (self.weft_height + self.warp_height) - self.warp_height / 2

    @property
    def weft_y(self) -> tuple[float, ...]:
        """y of each weft column's centre (mm)."""
        return tuple((j + 0.5) * self.weft_spacing for j in range(self.weft_per_layer))

    @property
    def _group_columns(self) -> int:
        """Warp columns a group of binder positions and its stuffer columns take."""
        return self.binder_ratio + (self.warp_ratio if self.stuffers else 0)

    @property
    def binder_x(self) -> tuple[float, ...]:
        """x of each binder's centre (mm)."""
        br, group = self.binder_ratio, self._group_columns
        return tuple((group * (p // br) + p % br + 0.5) * self.warp_spacing for p in self.binder_position)

    @property
    def stuffer_x(self) -> tuple[float, ...]:
        """x of each stuffer column's centre (mm), after each group of binder positions; empty without stuffers."""
        if not self.stuffers:
            return ()
        br, group = self.binder_ratio, self._group_columns
        return tuple((group * g + br + c + 0.5) * self.warp_spacing
                     for g in range(self.warp_groups) for c in range(self.warp_ratio))

    @property
    def stuffer_gaps(self) -> tuple[int, ...]:
        """The gaps the stuffers of every stuffer column lie in: 1..stuffers."""
        return tuple(range(1, self.stuffers + 1))

    # Dict form: the [weave] table.

    def to_dict(self) -> dict:
        """The dict form, TOML and JSON ready; generated fields are written out as generated, and
        the fields the family does not take left out."""
        out = {}
        takes = FAMILIES[self.family].takes
        for f in dataclass_fields(self):
            value = getattr(self, f.name)
            if value is None or (f.name in FAMILY_FIELDS and f.name not in takes):
                continue
            if f.name == "pattern" and (self.floats is not None or self.harness is not None):
                continue  # generated from them, as they are given
            if isinstance(value, Section):
                value = value.to_dict()
            elif f.name in ("binder_path", "pattern"):
                value = [list(row) for row in value]
            elif isinstance(value, tuple):
                value = list(value)
            out[f.name] = value
        return out

    @classmethod
    def from_dict(cls, d: dict, where: str = "[weave]") -> "UnitCell":
        """A unit cell from its dict form; errors name ``where`` and the field. Missing keys take defaults."""
        return cls.from_arguments(cls.arguments_from_dict(d, where), where)

    @classmethod
    def from_arguments(cls, kwargs: dict, where: str = "[weave]") -> "UnitCell":
        """``UnitCell(**kwargs)`` (from :meth:`arguments_from_dict`), its errors ConfigErrors naming ``where``."""
        try:
            return cls(**kwargs)
        except WeaveError as exc:
            raise ConfigError(f"{where}: {exc}") from None

    @staticmethod
    def arguments_from_dict(d: dict, where: str = "[weave]") -> dict:
        """The keyword arguments of the unit cell of a dict form, each value's type and range checked,
        before the cell is built (building generates every binder's path: a size to check first)."""
        d = fields.mapping(d, where)
        fields.only(d, _KEYS, where)
        kwargs = {}
        if "family" in d:
            kwargs["family"] = fields.string(d["family"], "family", where)
            check_choice(kwargs["family"], FAMILY_NAMES, f"{where} family", ConfigError)
        for key in ("weft_per_layer", "weft_layers", "warp_positions", "binders", "warp_ratio", "binder_ratio",
                    "binder_step", "harness", "plies"):
            if key in d:
                kwargs[key] = fields.integer(d[key], key, where, 1)
        for key in ("stuffers", "binder_offset"):
            if key in d:
                kwargs[key] = fields.integer(d[key], key, where, 0)
        for key in ("warp_spacing", "weft_spacing", "thickness"):
            if key in d:
                kwargs[key] = fields.number(d[key], key, where, positive=True)
        for key in ("warp_width_fraction", "weft_width_fraction", "weft_share", "margin_xy", "margin_z"):
            if key in d:
                kwargs[key] = fields.number(d[key], key, where)
        if "binder_position" in d:
            kwargs["binder_position"] = fields.vector(d["binder_position"], "binder_position", where, None,
                                                      "a list of warp positions, one a binder",
                                                      element=fields.integer, lo=0)
        if "binder_path" in d:
            kwargs["binder_path"] = _rows(d["binder_path"], "binder_path", where,
                                          "a list of paths (lists of gaps), one a binder", "a list of gaps, one a weft column")
        for key in ("weft_section", "warp_section"):
            if key in d:
                kwargs[key] = Section.from_dict(d[key], key, where)
        if "floats" in d:
            kwargs["floats"] = fields.vector(d["floats"], "floats", where, 2, "[over, under], two counts of wefts",
                                             element=fields.integer, lo=1)
        if "ply_shift_mm" in d:
            kwargs["ply_shift_mm"] = fields.vector(d["ply_shift_mm"], "ply_shift_mm", where, 2, "[x, y] in mm")
        if "pattern" in d:
            kwargs["pattern"] = _rows(d["pattern"], "pattern", where, "a list of rows of 0s and 1s (1: the warp over "
                                      "the weft), a row per warp yarn", "a row of 0s and 1s, one a weft yarn")
        return kwargs


def _rows(rows, field: str, where: str, form: str, row_form: str) -> tuple[tuple[int, ...], ...]:
    """A non-empty list of lists of integers >= 0 (binder paths, a pattern), each row checked and named."""
    if not isinstance(rows, list) or not rows:
        raise ConfigError(f"{where}: {field} must be {form}, got {show(rows)}")
    return tuple(fields.vector(r, f"{field}[{i}]", where, None, row_form, element=fields.integer, lo=0)
                 for i, r in enumerate(rows))


_KEYS = {f.name for f in dataclass_fields(UnitCell)}
