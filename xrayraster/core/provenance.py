"""What made an output: the package version, for reports and metadata."""

from __future__ import annotations

from importlib import metadata


def package_version() -> str:
    """xrayraster's installed version, or ``"unknown"`` when running from a checkout that is not installed."""
    try:
        return metadata.version("xrayraster")
    except metadata.PackageNotFoundError:
        return "unknown"
