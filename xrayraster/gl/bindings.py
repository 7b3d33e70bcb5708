"""Shader-storage binding slots: written once here, handed to every GLSL stage as defines.

``shader_source`` prepends ``#define BINDING_<NAME> <slot>`` for each entry, the shaders declare
``layout(std430, binding = BINDING_HEADS)``, and Python binds with
``buffer.bind_to_storage_buffer(BINDINGS["heads"])``: a slot number appears nowhere else.

Slots 0-7 only (OpenGL 4.3 guarantees 8). Two pairs share a slot because no pass uses both:
``accumulators`` (the single-pass sum) and ``heads`` (the per-pixel lists of the overlap passes)
are chosen by the ``RESOLVE`` define of ``shaders/crossing.glsl``.
"""

from __future__ import annotations

BINDINGS = {
    "triangles": 0,  # the scene's triangle soup (read by every crossing pass)
    "output": 1,  # what a resolve pass writes: path lengths, or packed labels
    "objects": 2,  # per object by rank: channel, drawn, container channel + 1, label
    "large": 3,  # indirect draw command + the triangles the rasteriser draws
    "accumulators": 4,  # fixed-point sums (channel, row, col); sum passes only
    "heads": 4,  # per-pixel list heads; overlap passes only
    "nodes": 5,  # crossing-list nodes
    "counters": 6,  # node count, overflowing pixels, deepest list
    "large_corners": 7,  # window-space corners of the large triangles
}


def binding_defines() -> dict[str, int]:
    """``{"BINDING_TRIANGLES": 0, ...}`` for the GLSL preprocessor."""
    return {f"BINDING_{name.upper()}": slot for name, slot in BINDINGS.items()}
