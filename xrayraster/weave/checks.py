"""The checks of a weave's fields: a finite number within bounds, an integer from a least, each
refused with a :class:`~xrayraster.core.errors.WeaveError` that names the field and the fix; and
the setting of a checked value on a frozen dataclass."""

from __future__ import annotations

import numbers

from ..core.errors import WeaveError
from ..core.validate import show


def set_field(obj, name: str, value) -> None:
    """Set ``name`` on a frozen dataclass ``obj`` (its checked value, in ``__post_init__`` or a check)."""
    object.__setattr__(obj, name, value)


def checked_float(name: str, value, *, lo: float | None = None, hi: float | None = None,
            lo_open: bool = True, hi_open: bool = False, fix: str = "") -> float:
    """A finite float within bounds, else a WeaveError naming ``name`` and ``fix``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or value != value or abs(value) == float("inf"):
        raise WeaveError(f"{name} must be a finite number, got {show(value)}")
    x = float(value)
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise WeaveError(f"{name} must be {'>' if lo_open else '>='} {show(float(lo))}, got {show(x)}{fix}")
    if hi is not None and (x > hi or (hi_open and x == hi)):
        raise WeaveError(f"{name} must be {'<' if hi_open else '<='} {show(float(hi))}, got {show(x)}{fix}")
    return x


def checked_int(name: str, value, lo: int, fix: str = "") -> int:
    """An integer >= ``lo``, else a WeaveError naming ``name`` and ``fix``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
        raise WeaveError(f"{name} must be an integer >= {lo}, got {show(value)}{fix}")
    return int(value)
