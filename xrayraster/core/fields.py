"""Checks of one field of a dict read from a file (TOML, JSON, metadata).

Each takes the value, the field's name and ``where`` (the file and table, e.g.
``scene.toml [[objects]] #2 (ball)``), returns the checked value, and raises
:class:`~xrayraster.core.errors.ConfigError` with a message that names all three and the fix.
"""

from __future__ import annotations

import math
import numbers

from .errors import ConfigError, GeometryError
from .validate import show


def only(table: dict, allowed: set, where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}")


def required(table: dict, key: str, where: str):
    if key not in table:
        raise ConfigError(f"{where}: missing '{key}'")
    return table[key]


def number(value, field: str, where: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):  # numpy scalars too
        raise ConfigError(f"{where}: {field} must be a number, got {show(value)}")
    try:
        finite = math.isfinite(value)
    except OverflowError:  # an integer beyond float's range (TOML and JSON integers have no bound)
        finite = False
    if not finite:
        raise ConfigError(f"{where}: {field} must be finite, got {show(value)}")
    if positive and value <= 0:
        raise ConfigError(f"{where}: {field} must be > 0, got {show(value)}")
    if nonnegative and value < 0:
        raise ConfigError(f"{where}: {field} must be >= 0, got {show(value)}")
    return float(value)


def string(value, field: str, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{where}: {field} must be a non-empty string, got {show(value)}")
    return value


def boolean(value, field: str, where: str) -> bool:
    """A TOML or JSON boolean: not 1 or 0, which equal True and False, nor a string."""
    if not isinstance(value, bool):
        raise ConfigError(f"{where}: {field} must be true or false, got {show(value)}")
    return value


def choice(value, field: str, where: str, choices: tuple[str, ...]) -> str:
    """One of the strings ``choices`` (a tuple of :mod:`~xrayraster.core.choices`)."""
    if not isinstance(value, str) or value not in choices:
        raise ConfigError(f"{where}: {field} must be one of {', '.join(choices)}, got {show(value)}")
    return value


def table(value, field: str, where: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: {field} must be a table ([{field}]), got {show(value)}")
    return value


def integer(value, field: str, where: str, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo or (hi is not None and value > hi):
        bounds = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise ConfigError(f"{where}: {field} must be an integer {bounds}, got {show(value)}")
    return value


def vector(value, field: str, where: str, length: int | None, form: str, *, element=number, **limits) -> tuple:
    """An array of exactly ``length`` values (any non-empty array if None), each checked by ``element``."""
    if not isinstance(value, list) or not value or (length is not None and len(value) != length):
        raise ConfigError(f"{where}: {field} must be {form}, got {show(value)}")
    return tuple(element(x, f"{field}[{i}]", where, **limits) for i, x in enumerate(value))


def one_or_pair(value, field: str, where: str, form: str, *, element=number, **limits):
    """One value (meaning both) or a ``[row, col]`` array of two."""
    if isinstance(value, list):
        return vector(value, field, where, 2, form, element=element, **limits)
    return element(value, field, where, **limits)


def mapping(d, where: str) -> dict:
    """``d`` if it is a dict (a TOML table, a JSON object)."""
    if not isinstance(d, dict):
        raise ConfigError(f"{where} must be a table (a JSON object), got {type(d).__name__}")
    return d


def one_or_three(value, field: str, where: str, form: str, element, **limits):
    if isinstance(value, list):
        return vector(value, field, where, 3, f"[z, y, x] {form}", element=element, **limits)
    return element(value, field, where, **limits)


def construct(cls, where: str, **kwargs):
    """``cls(**kwargs)``, its GeometryError (a relation between fields) reported at ``where``."""
    try:
        return cls(**kwargs)
    except GeometryError as exc:
        raise ConfigError(f"{where}: {exc}") from None
