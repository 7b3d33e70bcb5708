"""A yarn's cross-section (``weft_section``, ``warp_section`` of a weave; docs/weave.md)."""

from __future__ import annotations

from dataclasses import dataclass

from ..core import fields
from ..core.choices import check_choice
from ..core.errors import ConfigError, WeaveError
from ..core.validate import show
from .checks import checked_float, set_field

SECTION_SHAPES = ("ellipse", "lenticular", "power_ellipse", "rounded_rectangle")
_SHAPE_PARAMETER = {"power_ellipse": "exponent", "rounded_rectangle": "corner"}


@dataclass(frozen=True)
class Section:
    """A yarn cross-section: its shape and the one number some shapes take.

    ``ellipse`` and ``lenticular`` (two circular arcs meeting at the yarn's edges) take none.
    ``power_ellipse`` takes ``exponent`` n > 0, the superellipse ``|x/a|^n + |z/b|^n = 1`` with
    a, b half the width and height (n = 2 the ellipse, n > 2 squarer; not TexGen's power ellipse),
    as :func:`xrayraster.weave.sweep.power_ellipse` draws it. ``rounded_rectangle`` takes
    ``corner`` in (0, 1]: the corner radius as a fraction of half the smaller side (1 a stadium),
    as :func:`xrayraster.weave.sweep.rounded_rectangle` draws it.
    """

    shape: str = "ellipse"
    exponent: float | None = None
    corner: float | None = None

    def check(self, field: str) -> None:
        """Validate, naming ``field`` (e.g. ``weft_section``) in the message."""
        check_choice(self.shape, SECTION_SHAPES, f"{field}.shape", WeaveError)
        wanted = _SHAPE_PARAMETER.get(self.shape)
        for name in ("exponent", "corner"):
            if name != wanted and getattr(self, name) is not None:
                takes = f"takes only '{wanted}'" if wanted else "takes no parameter"
                raise WeaveError(f"{field}.{name}: shape {self.shape!r} {takes}; remove {name}")
        if self.shape == "power_ellipse":
            if self.exponent is None:
                raise WeaveError(f"{field}.exponent: a power_ellipse needs its exponent n > 0 "
                                 "(|x/a|^n + |z/b|^n = 1; 2 is the ellipse, > 2 squarer)")
            set_field(self, "exponent", checked_float(f"{field}.exponent", self.exponent, lo=0.0,
                                           fix=" (|x/a|^n + |z/b|^n = 1; 2 is the ellipse, > 2 squarer)"))
        if self.shape == "rounded_rectangle":
            if self.corner is None:
                raise WeaveError(f"{field}.corner: a rounded_rectangle needs its corner radius fraction in (0, 1]")
            set_field(self, "corner", checked_float(f"{field}.corner", self.corner, lo=0.0, hi=1.0,
                                         fix=" (the corner radius over half the smaller side; 1 a stadium)"))

    def to_dict(self) -> dict:
        out = {"shape": self.shape}
        for name in ("exponent", "corner"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        return out

    @classmethod
    def from_dict(cls, d, field: str, where: str) -> "Section":
        if isinstance(d, str):  # a bare shape name
            d = {"shape": d}
        if not isinstance(d, dict):
            raise ConfigError(f"{where}: {field} must be a table like {{ shape = \"ellipse\" }}, got {show(d)}")
        fields.only(d, {"shape", "exponent", "corner"}, f"{where} {field}")
        kwargs = {"shape": fields.string(fields.required(d, "shape", f"{where} {field}"), f"{field}.shape", where)}
        for name in ("exponent", "corner"):
            if name in d:
                kwargs[name] = fields.number(d[name], f"{field}.{name}", where)
        return cls(**kwargs)
