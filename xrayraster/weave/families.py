"""Weave families: how a unit cell's yarns interlace, and which fields say so.

The 3D families are laid out on the same cell (:class:`~xrayraster.weave.UnitCell`): straight weft
layers along x, straight warp stuffers along y in the gaps between them, and binders whose path is
a gap per weft column (gap ``g`` lies between weft layers ``g − 1`` and ``g``; 0 below the bottom
layer, ``n = weft_layers`` above the top one). A family is the rule for the binders' paths and its
own defaults, with the names TexGen's users know. Where the binders run over the outer layers (all
but layer to layer), ``margin_z`` defaults to the room they take there: the warp height.

* ``layer_to_layer`` (the default): each binder links two adjacent weft layers, over the upper for
  the first half of the columns and under the lower for the second, the positions staggered
  (docs/weave.md); ``binders``, ``binder_position`` and ``binder_path`` may be given instead.
* ``orthogonal``: straight stuffers in every gap (``stuffers`` defaults to ``n − 1``) held by one
  through-thickness binder (z-yarn) per position, over the top layer (gap ``n``) for the first half
  of the columns and under the bottom layer (gap 0) for the rest; ``binder_path`` may give another
  sequence of 0s and ``n``s.
* ``through_thickness_angle_interlock``: one binder per position climbing one gap every
  ``binder_step`` columns from under the bottom layer to over the top one and back down, every
  position in phase: a zig-zag of period ``2 · n · binder_step`` columns (``weft_per_layer`` defaults
  to one period and must be a whole number of them).
* ``offset_angle_interlock``: the same binders, position ``p`` shifted by ``p · binder_offset``
  columns along the warp.

The 2D families weave a ply: a warp per row of a ``pattern`` (:mod:`~xrayraster.weave.patterns`),
running along y over the wefts where its row has a 1 and under them where it has a 0, and a weft per
column running along x the other way round, both undulating about the ply's mid-plane; ``plies``
such plies are stacked in the cell's thickness, ply ``k`` shifted in x and y by ``k · ply_shift_mm``
(the nesting of a laminate). ``plain``, ``twill`` (``floats``) and ``satin`` (``harness``) give the
named patterns; ``pattern`` gives any other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import WeaveError
from .patterns import Pattern, plain_pattern, satin_pattern, twill_pattern

__all__ = ["FAMILIES", "FAMILY_NAMES", "Family"]

#: The defaults of the fields a family leaves to itself (docs/weave.md).
WEFT_LAYERS, WARP_POSITIONS, PLIES, FLOATS, HARNESS = 5, 4, 4, (2, 2), 5

#: Fields only some families take (every family takes the cell's other fields).
STACK_FIELDS = ("weft_layers", "stuffers", "warp_ratio", "binder_ratio")  # the 3D families'
PLY_FIELDS = ("pattern", "plies", "ply_shift_mm")  # the 2D families'
FAMILY_FIELDS = (*STACK_FIELDS, "binders", "binder_position", "binder_path", "binder_step", "binder_offset",
                 *PLY_FIELDS, "floats", "harness")


#: An orthogonal binder's nodes over a weft column, in units of the weft's half-width from the
#: column's centre (as :data:`~xrayraster.weave.sample.PLATEAU`, which the other families use): flat
#: over most of the weft, so it drops nearly upright between two columns, as a z-yarn does. Against
#: TexGen's binder over the same cell (tests/references/test_texgen_peer.py), whose path wraps the
#: weft's corner and drops between the wefts, the centre lines lie 0.036 mm apart (RMS; 0.103 at the
#: turns' corners) for a 0.571 mm binder, where the default plateau (±0.5) left 0.114 (0.284).
ORTHOGONAL_PLATEAU = (-0.85, -0.75, 0.75, 0.85)


@dataclass(frozen=True)
class Family:
    """A family's rule: the family-specific fields it ``takes`` (of :data:`FAMILY_FIELDS`), and
    its binders' nodes over a weft column (``plateau``; None: the sample's default; a 2D family's
    yarns have one node a crossing)."""

    name: str
    takes: tuple[str, ...]
    plateau: tuple[float, ...] | None = None

    @property
    def plies(self) -> bool:
        """Whether the family weaves 2D plies (else a 3D stack of weft layers and binders)."""
        return "plies" in self.takes

    @property
    def default_weft_share(self) -> float:
        """The weft's share of the yarns' thickness: 0.6 in a 3D stack, 0.5 in a ply."""
        return 0.5 if self.plies else 0.6

    def pattern(self, pattern: Pattern | None, floats: tuple[int, int] | None, harness: int | None) -> Pattern:
        """A 2D family's pattern: ``pattern`` when given, else its own (:mod:`~xrayraster.weave.patterns`)."""
        if pattern is not None:
            return pattern
        if self.name == "twill":
            return twill_pattern(*(floats or FLOATS))
        if self.name == "satin":
            return satin_pattern(harness or HARNESS)
        return plain_pattern()

    def default_stuffers(self, weft_layers: int) -> int:
        return weft_layers - 1 if self.name == "orthogonal" else 0

    def default_margin_z(self, thickness: float, weft_share: float, weft_layers: int) -> float:
        """mm: 0.4 layer to layer; for binders that run over the outer layers, the margin that just
        holds them: ``m`` equal to the warp height ``(1 − weft_share) · (thickness − 2m) / (n − 1)``;
        over and under ``n`` plies, a tenth of a ply: ``m = (thickness − 2m) / (10 n)``."""
        if self.plies:
            return thickness / (10 * weft_layers + 2)
        if self.name == "layer_to_layer":
            return 0.4
        rest = 1.0 - weft_share
        return rest * thickness / (weft_layers - 1 + 2 * rest)

    def period(self, weft_layers: int, step: int) -> int:
        """The columns after which a binder's path repeats (0: any number of columns)."""
        return 2 * weft_layers * step if self.name.endswith("angle_interlock") else 0

    def default_weft_per_layer(self, weft_layers: int, step: int) -> int:
        return self.period(weft_layers, step) or 4

    def binder_count(self, warp_positions: int, weft_layers: int) -> int:
        """Binders a cell has when ``binders`` is not given: one per position, or, layer to
        layer, one per position and pair of adjacent weft layers; a 2D family's warps, which
        interlace as binders do: one per position and ply."""
        if self.plies:
            return warp_positions * weft_layers
        return warp_positions * (weft_layers - 1) if self.name == "layer_to_layer" else warp_positions

    def path(self, i: int, n: int, w: int, p: int, step: int, offset: int) -> tuple[int, ...]:
        """Binder ``i``'s gap at each of the ``w`` weft columns (``n`` weft layers, ``p`` positions)."""
        if self.name == "layer_to_layer":
            k = (i // p) % (n - 1)  # links weft layers k and k + 1
            shift = (i % p) * w // p  # positions staggered along the warp
            half = (w + 1) // 2
            return tuple(k + 2 if (j - shift) % w < half else k for j in range(w))
        if self.name == "orthogonal":
            half = (w + 1) // 2
            return tuple(n if j < half else 0 for j in range(w))
        shift = (i % p) * offset if self.name == "offset_angle_interlock" else 0
        period = self.period(n, step)
        return tuple(_zigzag(((j - shift) % period) // step, n) for j in range(w))

    def node_heights(self, path, columns, offsets, spacing: float, gap_z) -> np.ndarray:
        """``(len(columns), len(offsets))`` z (mm) of a binder's nodes at ``offsets`` (mm) from the
        centres of weft ``columns`` (``spacing`` mm apart; indices over all cells) for its ``path``
        (gaps, ``gap_z(gap)`` their heights): flat at each column's gap, except where an angle
        interlock climbs or falls through a column (its gaps before and after one below and one
        above, or the reverse): there its nodes lie on the line from the end of its last turn's
        plateau to the start of its next one, so it runs flat over the wefts it turns on and straight
        between them."""
        w = len(path)
        heights = np.repeat(np.array([gap_z(path[j % w]) for j in columns])[:, None], len(offsets), axis=1)
        if not self.name.endswith("angle_interlock"):
            return heights

        def climbs(j):  # through column j, one gap a column
            before, here, after = (path[(j + d) % w] for d in (-1, 0, 1))
            return (before - here) * (here - after) > 0 and abs(before - after) == 2

        for k, j in enumerate(columns):
            if not climbs(j):
                continue
            start, end = j - 1, j + 1
            while climbs(start):
                start -= 1
            while climbs(end):
                end += 1
            y0, y1 = (start + 0.5) * spacing + offsets[-1], (end + 0.5) * spacing + offsets[0]  # plateau edges
            z0, z1 = gap_z(path[start % w]), gap_z(path[end % w])
            heights[k] = z0 + ((j + 0.5) * spacing + offsets - y0) * (z1 - z0) / (y1 - y0)
        return heights

    def check_path(self, i: int, path: tuple[int, ...], n: int) -> None:
        """Refuse a given path the family cannot weave (an orthogonal binder only runs over the top
        or under the bottom)."""
        if self.name == "orthogonal":
            for j, g in enumerate(path):
                if g not in (0, n):
                    raise WeaveError(f"binder_path[{i}][{j}] = {g}: an orthogonal binder runs over the top layer "
                                     f"(gap {n}) or under the bottom one (gap 0); use family = \"layer_to_layer\" "
                                     "for binders between layers")


def _zigzag(k: int, n: int) -> int:
    """Gap of a through-thickness binder ``k`` steps into its period: 0, 1, …, n, n − 1, …, 1."""
    return k if k <= n else 2 * n - k


FAMILIES = {family.name: family for family in (
    Family("layer_to_layer", (*STACK_FIELDS, "binders", "binder_position", "binder_path")),
    Family("orthogonal", (*STACK_FIELDS, "binder_path"), ORTHOGONAL_PLATEAU),
    Family("through_thickness_angle_interlock", (*STACK_FIELDS, "binder_step")),
    Family("offset_angle_interlock", (*STACK_FIELDS, "binder_step", "binder_offset")),
    Family("plain", PLY_FIELDS, (0.0,)),
    Family("twill", (*PLY_FIELDS, "floats"), (0.0,)),
    Family("satin", (*PLY_FIELDS, "harness"), (0.0,)),
)}
FAMILY_NAMES = tuple(FAMILIES)
