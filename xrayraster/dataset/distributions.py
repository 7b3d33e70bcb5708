"""The distributions of a dataset file's ``[vary]`` table (docs/dataset.md), each drawn from a numpy Generator.

A value of ``[vary]`` is a distribution table (one of the kinds below, with its modifiers) or a
plain value, which fixes the key (:class:`Fixed`):

- ``{ uniform = [a, b] }``: a float uniform in [a, b), a < b;
- ``{ loguniform = [a, b] }``: a float whose log is uniform, 0 < a < b (scales such as mAs);
- ``{ normal = [mean, sigma], clip = [lo, hi] }``: a Gaussian, sigma > 0; with ``clip`` the
  truncated Gaussian (the Gaussian redrawn until inside [lo, hi]: its shape kept, no mass piled
  at the ends), drawn in one step by the inverse CDF, so no bound on retries is needed;
- ``{ integer = [a, b] }``: an integer uniform in [a, b], both ends included, a < b;
- ``{ choice = [v1, v2, ...], weights = [w1, w2, ...] }``: one of the values (any TOML value:
  numbers, strings, arrays, tables), with the given weights (default equal);
- ``{ around = r, clip = [lo, hi] }``: ±r (a share, 0 < r < 1) of the base scan's own value of the
  key, uniform: ``{ uniform = [v·(1 − r), v·(1 + r)] }``, the form it is read as (``dataset_file``
  resolves it against the base; around a fitted scan file, docs/fit.md); with ``clip`` that range
  cut to [lo, hi] (a fraction whose +r would pass 1, say).

Each distribution's ``to_dict()`` is the table it was read from, so
``distribution_from(d.to_dict(), ...) == d``; the draws are plain Python values (float, int, or a
deep copy of a choice), ready for JSON and TOML.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from statistics import NormalDist

from ..core import fields
from ..core.errors import ConfigError
from ..core.validate import show

__all__ = ["Choice", "Distribution", "Fixed", "Integer", "LogUniform", "Normal", "Uniform", "distribution_from",
           "is_distribution"]

KINDS = ("uniform", "loguniform", "normal", "integer", "choice")
AROUND = "around"  # a share of the base's own value: read as a uniform (resolved_around)
MODIFIERS = {"normal": ("clip",), "choice": ("weights",)}
#: The least share of a normal's mass its clip interval must hold. Below it the interval lies in
#: the far tail, where the inverse CDF loses its precision and the draw is no longer a Gaussian's.
MIN_CLIP_MASS = 1e-6


@dataclass(frozen=True)
class Uniform:
    low: float
    high: float

    def sample(self, rng) -> float:
        return float(rng.uniform(self.low, self.high))

    def to_dict(self) -> dict:
        return {"uniform": [self.low, self.high]}


@dataclass(frozen=True)
class LogUniform:
    low: float
    high: float

    def sample(self, rng) -> float:
        return float(math.exp(rng.uniform(math.log(self.low), math.log(self.high))))

    def to_dict(self) -> dict:
        return {"loguniform": [self.low, self.high]}


@dataclass(frozen=True)
class Normal:
    mean: float
    sigma: float
    clip: tuple[float, float] | None = None

    def sample(self, rng) -> float:
        if self.clip is None:
            return float(rng.normal(self.mean, self.sigma))
        lo, hi = self.clip
        gauss = NormalDist(self.mean, self.sigma)
        # u uniform over the clip interval's share of the CDF: the truncated Gaussian exactly.
        x = gauss.inv_cdf(float(rng.uniform(gauss.cdf(lo), gauss.cdf(hi))))
        return min(max(x, lo), hi)  # the inverse CDF's last-bit rounding never leaves the interval

    def to_dict(self) -> dict:
        return {"normal": [self.mean, self.sigma]} | ({"clip": list(self.clip)} if self.clip else {})


@dataclass(frozen=True)
class Integer:
    low: int
    high: int

    def sample(self, rng) -> int:
        return int(rng.integers(self.low, self.high, endpoint=True))

    def to_dict(self) -> dict:
        return {"integer": [self.low, self.high]}


@dataclass(frozen=True)
class Choice:
    values: tuple
    weights: tuple[float, ...] | None = None

    def sample(self, rng):
        p = None
        if self.weights is not None:
            total = sum(self.weights)
            p = [w / total for w in self.weights]
        return copy.deepcopy(self.values[int(rng.choice(len(self.values), p=p))])

    def to_dict(self) -> dict:
        return {"choice": copy.deepcopy(list(self.values))} | (
            {"weights": list(self.weights)} if self.weights is not None else {})


@dataclass(frozen=True)
class Fixed:
    """A plain value in ``[vary]``: the key is set to it in every sample (no draw)."""

    value: object

    def sample(self, rng):
        return copy.deepcopy(self.value)

    def to_dict(self):
        return copy.deepcopy(self.value)


Distribution = Uniform | LogUniform | Normal | Integer | Choice | Fixed


def is_distribution(value) -> bool:
    """True for a table holding a distribution's key (a kind or a modifier); any other table in
    ``[vary]`` is a level of nesting (``[vary.source]``)."""
    return isinstance(value, dict) and any(k in value for k in (*KINDS, AROUND, "clip", "weights"))


def resolved_around(value, key: str, base_value, where: str):
    """``value`` with ``{ around = r }`` turned into the uniform ±r of ``base_value`` (the base scan's
    value of ``key``); any other value as it is."""
    if not (isinstance(value, dict) and AROUND in value):
        return value
    field = f"'{key}' around"
    if not set(value) <= {AROUND, "clip"}:
        raise ConfigError(f"{where}: {field} takes only clip besides (got {', '.join(sorted(value))}); write "
                          "{ around = 0.1 } or { around = 0.1, clip = [0.0, 1.0] }")
    share = fields.number(value[AROUND], field, where, positive=True)
    if share >= 1:
        raise ConfigError(f"{where}: {field} = {show(share)} is a share of the base's value below 1 (0.1: ±10 %)")
    if isinstance(base_value, bool) or not isinstance(base_value, (int, float)) or not base_value:
        raise ConfigError(f"{where}: {field} needs a non-zero number for '{key}' in the base scan, which gives "
                          f"{show(base_value) if base_value is not None else 'none'}; give {{ uniform = [a, b] }} instead")
    low, high = sorted((base_value * (1 - share), base_value * (1 + share)))
    if "clip" in value:
        lo, hi = _pair(value["clip"], f"{field} clip", where, form="[low, high]")
        _increasing(lo, hi, f"{field} clip", where, "[low, high]")
        low, high = max(low, lo), min(high, hi)
        if not low < high:
            raise ConfigError(f"{where}: {field} clip = {show(value['clip'])} leaves nothing of "
                              f"[{show(base_value * (1 - share))}, {show(base_value * (1 + share))}]; widen the clip")
    return {"uniform": [float(low), float(high)]}


def distribution_from(value, key: str, where: str) -> Distribution:
    """The distribution that ``value`` (a ``[vary]`` entry) describes; ``key`` is its dotted scan-file
    key, ``where`` the file and table, both named in every error."""
    if not is_distribution(value):
        return Fixed(copy.deepcopy(value))
    field = f"'{key}'"
    kinds = [k for k in KINDS if k in value]
    if len(kinds) != 1:
        given = f"got {' and '.join(kinds)}" if kinds else "got only " + ", ".join(sorted(value))
        raise ConfigError(f"{where}: {field} must give exactly one of {', '.join(KINDS)} ({given})")
    kind = kinds[0]
    allowed = {kind, *MODIFIERS.get(kind, ())}
    stray = sorted(set(value) - allowed)
    if stray:
        raise ConfigError(f"{where}: {field}: unknown key(s) {', '.join(stray)} in a {kind} distribution; "
                          f"allowed: {', '.join(sorted(allowed))}")
    return _READERS[kind](value, f"{field} {kind}", where)


def _pair(value, field: str, where: str, form: str = "[low, high]", element=fields.number, **limits) -> tuple:
    return fields.vector(value, field, where, 2, form, element=element, **limits)


def _increasing(a, b, field: str, where: str, form: str) -> None:
    if not a < b:
        raise ConfigError(f"{where}: {field} = [{show(a)}, {show(b)}] is an empty range; give {form} with "
                          f"the first below the second (for one value, write the value itself)")


def _uniform(d: dict, field: str, where: str) -> Uniform:
    low, high = _pair(d["uniform"], field, where)
    _increasing(low, high, field, where, "[low, high]")
    return Uniform(low, high)


def _loguniform(d: dict, field: str, where: str) -> LogUniform:
    low, high = _pair(d["loguniform"], field, where)
    if low <= 0:
        raise ConfigError(f"{where}: {field} = [{show(low)}, {show(high)}]: both ends must be > 0 (its log is uniform)")
    _increasing(low, high, field, where, "[low, high]")
    return LogUniform(low, high)


def _normal(d: dict, field: str, where: str) -> Normal:
    mean, sigma = _pair(d["normal"], field, where, form="[mean, sigma]")
    if sigma <= 0:
        raise ConfigError(f"{where}: {field} = [{show(mean)}, {show(sigma)}]: sigma must be > 0 "
                          "(for one value, write the value itself)")
    if "clip" not in d:
        return Normal(mean, sigma)
    clip_field = field.replace(" normal", " clip")
    lo, hi = _pair(d["clip"], clip_field, where, form="[low, high]")
    _increasing(lo, hi, clip_field, where, "[low, high]")
    gauss = NormalDist(mean, sigma)
    mass = gauss.cdf(hi) - gauss.cdf(lo)
    if mass < MIN_CLIP_MASS:
        raise ConfigError(f"{where}: {clip_field} = [{show(lo)}, {show(hi)}] holds {mass:.2g} of normal = "
                          f"[{show(mean)}, {show(sigma)}]: its draws are all impossible; move the clip interval "
                          "towards the mean or widen sigma")
    return Normal(mean, sigma, (lo, hi))


def _integer(d: dict, field: str, where: str) -> Integer:
    low, high = _pair(d["integer"], field, where, "[low, high] integers", fields.integer, lo=-2 ** 63)
    _increasing(low, high, field, where, "[low, high] (both included)")
    return Integer(low, high)


def _choice(d: dict, field: str, where: str) -> Choice:
    values = d["choice"]
    if not isinstance(values, list) or not values:
        raise ConfigError(f"{where}: {field} must be a non-empty array of values, got {show(values)}")
    if "weights" not in d:
        return Choice(tuple(copy.deepcopy(values)))
    weights_field = field.replace(" choice", " weights")
    weights = d["weights"]
    if not isinstance(weights, list) or len(weights) != len(values):
        raise ConfigError(f"{where}: {weights_field} must be an array of {len(values)} numbers, one per choice, "
                          f"got {show(weights)}")
    weights = tuple(fields.number(w, f"{weights_field}[{i}]", where, nonnegative=True) for i, w in enumerate(weights))
    if not any(weights):
        raise ConfigError(f"{where}: {weights_field} are all 0: no value could be drawn; give one a weight > 0")
    return Choice(tuple(copy.deepcopy(values)), weights)


_READERS = {"uniform": _uniform, "loguniform": _loguniform, "normal": _normal, "integer": _integer,
            "choice": _choice}
