"""Photon starvation: the share of the pixels a sample covers that detected no photon, and what to
say about it.

A starved pixel's signal is at or below the dark level (no photon detected, or a transmission
that is 0 in float32): its −log is infinite, so it is clamped to half a mean photon and its line
integral is a guess. A few are harmless; many make a reconstruction that is noise, biased low
(negative where the sample is). The share is taken over the pixels the sample covers, the rays
with a non-zero path length through the scene (sample and mount), counted per view from the path
lengths the radiograph is made from (``Radiograph.covered``, ``starved_covered``); air around the
sample does not dilute it. Above :data:`WARN_SHARE` a :class:`StarvationWarning` says so; above
:data:`REFUSE_SHARE` a scan refuses (:class:`StarvationError`) unless allowed (docs/scan.md).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

from ..core.errors import StarvationError, StarvationWarning

WARN_SHARE = 0.01  # 1 %: streaks and bias from the clamped pixels become visible
REFUSE_SHARE = 0.5  # over half the sample's rays are guesses: the volume is noise
FIX = ("raise [source] mas, use a thinner or lighter [source] filter, or a lower magnification or larger "
       "pixels (more photons a pixel)")


def starved_share(starved_covered: Sequence[int], covered: Sequence[int]) -> float:
    """The starved share of the pixels the sample covers, over all views given (0 when it covers none)."""
    total = sum(covered)
    return sum(starved_covered) / total if total else 0.0


def describe(share: float, where: str) -> str:
    """One line: the share, what it does to the result, and :data:`FIX`."""
    return (f"{where}: {100 * share:.1f} % of the pixels the sample covers are photon-starved (no photon "
            f"detected: clamped before −log), so the result is biased and noisy; {FIX}")


def warn_if_starved(share: float, where: str) -> None:
    """A :class:`StarvationWarning` when ``share`` is over :data:`WARN_SHARE`."""
    if share > WARN_SHARE:
        warnings.warn(describe(share, where), StarvationWarning, stacklevel=3)


def refuse_if_starved(share: float, where: str, views: int) -> None:
    """A :class:`StarvationError` when ``share`` (of the first ``views`` views) is over :data:`REFUSE_SHARE`."""
    if share > REFUSE_SHARE:
        raise StarvationError(f"{describe(share, where)} (in the first {views} views; over "
                              f"{100 * REFUSE_SHARE:.0f} % is refused); or scan anyway with --allow-starved "
                              "(xr.scan(..., allow_starved=True))")
