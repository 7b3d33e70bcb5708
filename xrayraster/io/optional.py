"""Optional libraries, imported when first needed so the core install stays lean."""

from __future__ import annotations

import importlib

from ..core.errors import ConfigError


def optional_module(name: str, extra: str, needed_for: str):
    """Import ``name``, or refuse (:class:`~xrayraster.core.errors.ConfigError`) naming the extra
    that installs it."""
    try:
        return importlib.import_module(name)
    except ImportError:
        raise ConfigError(f"{needed_for} needs {name}, which is not installed: "
                          f'pip install "xrayraster[{extra}]"') from None
