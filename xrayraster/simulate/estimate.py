"""The time and memory of rendering many views, before any is rendered (:class:`RenderJob`).

A view costs a fixed part (the passes' set-up and read-back), a part per detector pixel (ray set-up,
the crossing lists, the spectral sum with noise) and a part per triangle (the crossing passes). The
rates were fitted to two scans on the development machine (2 slow cores, llvmpipe), right to an
order of magnitude: ``examples/scan_small.toml`` (90 views of 24 × 64 pixels, 5,340 triangles:
7.9 ms a view) and the full twin (801 views of 512 × 512 pixels, 700 k triangles, by priority,
noise on: 0.18 s a view, docs/twin.md), with the path lengths' benchmark (1.1 M triangles at 256²:
~0.05 s a view, BENCHMARKS.md) for the triangles' share.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.estimate import Estimate, Part

SECONDS_PER_VIEW = 8e-3
SECONDS_PER_PIXEL = 6e-7
SECONDS_PER_TRIANGLE = 3e-8
#: A stacked view's float32 values are held twice while the stack is made (the views and the stack).
STACK_COPIES = 2


def seconds_per_view(pixels: int, triangles: int) -> float:
    """About how long one view of ``pixels`` detector pixels (rays) through ``triangles`` takes."""
    return SECONDS_PER_VIEW + SECONDS_PER_PIXEL * pixels + SECONDS_PER_TRIANGLE * triangles


@dataclass(frozen=True)
class RenderJob:
    """Rendering ``views`` views of ``detector_shape`` (rows, cols) pixels through ``triangles``
    into one stack of ``channels`` float32 images a view (the materials' path lengths, or 1 for
    radiographs), each pixel cast ``supersampling``² rays: a :class:`~xrayraster.core.estimate.Planned` job."""

    views: int
    detector_shape: tuple[int, int]
    triangles: int
    channels: int = 1
    supersampling: int = 1

    def estimate(self) -> Estimate:
        views, channels, (rows, cols) = self.views, self.channels, self.detector_shape
        stack = Part("float32 stack, held twice while stacked", STACK_COPIES * views * channels * rows * cols * 4,
                     f"views = {views} of {rows}×{cols} pixels{f' × {channels} materials' if channels > 1 else ''}",
                     "render fewer views at once (--views, or views= in the Python API) or use fewer detector pixels")
        seconds = views * seconds_per_view(rows * cols * self.supersampling**2, self.triangles)
        return Estimate(f"rendering of {views} views", seconds, (stack,))
