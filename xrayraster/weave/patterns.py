"""2D weave patterns: which yarn lies on top at each crossing of a ply's warps and wefts.

A pattern is a matrix of 0s and 1s, a row per warp yarn of the cell (warp ``i`` at
``x = (i + 0.5) · warp_spacing``) and a column per weft yarn (weft ``j`` at
``y = (j + 0.5) · weft_spacing``): 1 where warp ``i`` runs over weft ``j``, 0 where it runs under.
The named weaves, as a weaver drafts them:

* plain: over one, under one, the next warp the other way round (2 × 2);
* twill ``floats = [over, under]``: each warp over ``over`` wefts and under ``under``, the next
  warp's run one weft further on (a diagonal line; 2/2 by default, ``(over + under)`` square);
* satin ``harness = n``: each warp over ``n − 1`` wefts and under one, the next warp's crossing
  ``move`` wefts further on, ``move`` the smallest number from 2 that shares no factor with ``n``
  and is not ``n − 1`` (5-harness: move 2; 8-harness: 3), so no two crossings touch (``n`` square).
"""

from __future__ import annotations

import math

from ..core.errors import WeaveError
from ..core.validate import show

__all__ = ["checked_pattern", "level_changes", "plain_pattern", "satin_move", "satin_pattern", "twill_pattern"]

Pattern = tuple[tuple[int, ...], ...]


def plain_pattern() -> Pattern:
    return ((1, 0), (0, 1))


def twill_pattern(over: int, under: int) -> Pattern:
    n = over + under
    return tuple(tuple(int((j - i) % n < over) for j in range(n)) for i in range(n))


def satin_move(harness: int) -> int:
    """The smallest move from 2 that makes a satin of ``harness`` (>= 5) wefts: coprime with it, not ``harness − 1``."""
    return next(m for m in range(2, harness - 1) if math.gcd(m, harness) == 1)


def satin_pattern(harness: int) -> Pattern:
    move = satin_move(harness)
    return tuple(tuple(int(j != (i * move) % harness) for j in range(harness)) for i in range(harness))


def checked_pattern(pattern) -> Pattern:
    """``pattern`` (a list of rows of 0s and 1s, a row per warp) as a tuple of tuples, else a WeaveError
    naming the row and column at fault."""
    if isinstance(pattern, (str, bytes)) or not hasattr(pattern, "__len__") or len(pattern) < 1:
        raise WeaveError(f"pattern must be a list of rows of 0s and 1s, a row per warp yarn, got {show(pattern)}")
    rows = []
    for i, row in enumerate(pattern):
        if isinstance(row, (str, bytes)) or not hasattr(row, "__len__") or len(row) < 1:
            raise WeaveError(f"pattern[{i}] must be a row of 0s and 1s, one per weft yarn, got {show(row)}")
        if len(row) != len(pattern[0]):
            raise WeaveError(f"pattern[{i}] has {len(row)} crossings, pattern[0] {len(pattern[0])}: every warp "
                             "crosses the same wefts; give every row one 0 or 1 per weft yarn")
        for j, over in enumerate(row):
            if isinstance(over, bool) or over not in (0, 1):
                raise WeaveError(f"pattern[{i}][{j}] must be 1 (the warp over the weft) or 0 (under), got {show(over)}")
        rows.append(tuple(int(over) for over in row))
    return tuple(rows)


def level_changes(pattern) -> float:
    """The share of a pattern's crossing-to-crossing steps, along its warps and its wefts, where the
    yarn changes level (over to under or back): 1 for a plain weave, 0.5 for a 2/2 twill, 0.4 for
    a 5-harness satin. Its yarns bend there, so their meshes are denser (:mod:`~xrayraster.weave.size`)."""
    rows = [tuple(row) for row in pattern]
    columns = list(zip(*rows))
    steps = [a != b for line in (*rows, *columns) for a, b in zip(line, line[1:] + line[:1])]
    return sum(steps) / len(steps)
