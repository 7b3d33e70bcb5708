"""Checks of constructor arguments: each returns the value in its canonical form (floats, tuples)
or raises :class:`~xrayraster.core.errors.GeometryError` naming the argument."""

from __future__ import annotations

import math

import numpy as np

from .errors import GeometryError


def show(value) -> str:
    """A value as a message shows it: plain numbers (``nan``, ``0.5``, never ``np.float32(0.5)`` or
    ``-0.0``), strings quoted, lists, tuples and dicts element by element; anything else its repr."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool) or value is None:
        return repr(value)
    if isinstance(value, float):
        return "0.0" if value == 0 else repr(float(value))
    if isinstance(value, int):
        text = repr(int(value))
        return text if len(text) <= 20 else f"{text[:3]}...({len(text)} digits)"  # a TOML integer has no bound
    if isinstance(value, list):
        return "[" + ", ".join(show(v) for v in value) + "]"
    if isinstance(value, tuple):
        return "(" + ", ".join(show(v) for v in value) + ("," if len(value) == 1 else "") + ")"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{show(k)}: {show(v)}" for k, v in value.items()) + "}"
    return repr(value)


def finite(name: str, value: float, *, positive: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"{name} must be a number, got {show(value)}") from None
    if not math.isfinite(x):
        raise GeometryError(f"{name} must be finite, got {show(x)}")
    if positive and x <= 0:
        raise GeometryError(f"{name} must be > 0, got {show(x)}")
    return x


def pair(name: str, value, *, positive: bool) -> tuple[float, float]:
    if np.ndim(value) == 0:
        value = (value, value)
    if len(value) != 2:
        raise GeometryError(f"{name} must be a number or a (row, col) pair, got {show(value)}")
    return tuple(finite(f"{name}[{i}]", v, positive=positive) for i, v in enumerate(value))


def positive_ints(name: str, value, ndim: int) -> tuple[int, ...]:
    if np.ndim(value) == 0:
        value = (value,) * ndim
    if len(value) != ndim:
        raise GeometryError(f"{name} must have {ndim} entries, got {show(value)}")
    out = []
    for i, n in enumerate(value):
        if not np.isfinite(n) or int(n) != n or n < 1:
            raise GeometryError(f"{name}[{i}] must be a positive integer, got {show(n)}")
        out.append(int(n))
    return tuple(out)


def set_field(obj, name: str, value) -> None:
    """Store a checked value on a frozen dataclass (from its ``__post_init__``)."""
    object.__setattr__(obj, name, value)
