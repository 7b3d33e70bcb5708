"""Checks of constructor arguments: each returns the value in its canonical form (floats, tuples)
or raises :class:`~xrayraster.core.errors.GeometryError` naming the argument."""

from __future__ import annotations

import math

import numpy as np

from .errors import GeometryError


def finite(name: str, value: float, *, positive: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise GeometryError(f"{name} must be finite, got {x}")
    if positive and x <= 0:
        raise GeometryError(f"{name} must be > 0, got {x}")
    return x


def pair(name: str, value, *, positive: bool) -> tuple[float, float]:
    if np.ndim(value) == 0:
        value = (value, value)
    if len(value) != 2:
        raise GeometryError(f"{name} must be a number or a (row, col) pair, got {value!r}")
    return tuple(finite(f"{name}[{i}]", v, positive=positive) for i, v in enumerate(value))


def positive_ints(name: str, value, ndim: int) -> tuple[int, ...]:
    if np.ndim(value) == 0:
        value = (value,) * ndim
    if len(value) != ndim:
        raise GeometryError(f"{name} must have {ndim} entries, got {value!r}")
    out = []
    for i, n in enumerate(value):
        if not np.isfinite(n) or int(n) != n or n < 1:
            raise GeometryError(f"{name}[{i}] must be a positive integer, got {n!r}")
        out.append(int(n))
    return tuple(out)


def set_field(obj, name: str, value) -> None:
    """Store a checked value on a frozen dataclass (from its ``__post_init__``)."""
    object.__setattr__(obj, name, value)
