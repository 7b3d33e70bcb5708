"""The ``--views`` option: which views of a scan a command renders."""

from __future__ import annotations

from ..core.errors import ConfigError


def parse_views(text: str, num_views: int) -> list[int]:
    """View indices from ``--views``: comma-separated integers, or ``all``."""
    if text == "all":
        return list(range(num_views))
    try:
        views = [int(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(f"--views must be comma-separated integers or 'all', got {text!r}") from None
    bad = [v for v in views if not 0 <= v < num_views]
    if bad:
        raise ConfigError(f"--views {bad} out of range: the scene has {num_views} views (0..{num_views - 1})")
    return views
