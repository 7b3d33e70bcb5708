"""Shared fixtures. Capabilities (a GL driver, the OSMesa fallback, an OpenCL device) are probed
once; a missing one skips with the reason, unless XRAYRASTER_REQUIRE_GL=1 /
XRAYRASTER_REQUIRE_OSMESA=1 / XRAYRASTER_REQUIRE_OPENCL=1 / XRAYRASTER_REQUIRE_BROWSER=1 /
XRAYRASTER_REQUIRE_TORCH=1 (set by .ci/run), which turn that skip into a failure. Tests that take the
``torch`` fixture are marked ``needs_torch``: .ci/run runs the README's plain ``pytest`` first, in an
environment without the ml extra, and then ``pytest -m needs_torch`` once the extra is installed."""

from __future__ import annotations

import importlib
import os

import pytest


def _require(capability: str, reason: str) -> None:
    if os.environ.get(f"XRAYRASTER_REQUIRE_{capability}") == "1":
        pytest.fail(f"{capability} is required here (XRAYRASTER_REQUIRE_{capability}=1) but unavailable: {reason}")
    pytest.skip(reason)


def _context(capability: str, make, error):
    """Yield ``make()``, released afterwards; skip (or fail, see _require) when it raises ``error``."""
    try:
        ctx = make()
    except error as exc:
        _require(capability, str(exc))
    yield ctx
    ctx.release()


@pytest.fixture(scope="session")
def gl():
    from xrayraster import GLContext, GLContextError

    yield from _context("GL", GLContext, GLContextError)


@pytest.fixture(scope="session")
def osmesa():
    """A context on the OSMesa fallback backend (libosmesa6)."""
    from xrayraster import GLContext, GLContextError

    yield from _context("OSMESA", lambda: GLContext("osmesa"), GLContextError)


@pytest.fixture(scope="session")
def cl():
    """An OpenCL context on the default device (PoCL on a CPU machine)."""
    from xrayraster.recon.opencl import CLContext, OpenCLError

    yield from _context("OPENCL", CLContext, OpenCLError)


@pytest.fixture(scope="session")
def browser():
    """Debian's Chromium, headless, driven by Selenium (the preview's page tests)."""
    from references.browser import CHROMEDRIVER, CHROMIUM, headless_chromium

    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not os.path.exists(p)]
    if missing:
        _require("BROWSER", f"no {' or '.join(missing)}: apt-get install chromium chromium-driver")
    try:
        from selenium.common.exceptions import WebDriverException
    except ImportError as exc:
        _require("BROWSER", f"selenium is not importable ({exc}): pip install selenium")
    try:
        driver = headless_chromium()
    except WebDriverException as exc:
        _require("BROWSER", f"Chromium did not start: {str(exc).splitlines()[0]}")
    yield driver
    driver.quit()


def pytest_collection_modifyitems(items):
    for item in items:
        if "torch" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.needs_torch)


@pytest.fixture(scope="session")
def torch():
    """PyTorch, with the rest of the ml extra (MONAI, scikit-learn, scikit-image): xrayraster.ml's
    torch path and the training experiment."""
    try:
        import torch

        for name in ("monai", "sklearn", "skimage"):
            importlib.import_module(name)
    except ImportError as exc:
        _require("TORCH", f"{exc.name} is not installed: pip install 'torch==2.13.0+cpu' '.[ml]'")
    torch.manual_seed(0)
    return torch


@pytest.fixture
def render(gl):
    """render(geometry, scene, view=0, **options) -> (materials, rows, cols) on the shared context."""
    from xrayraster import Renderer

    def _render(geometry, scene, view=0, **options):
        with Renderer(geometry, context=gl, **options) as r:
            out = r.path_lengths(scene, view)
            _render.method = r.last_method
            return out

    return _render
