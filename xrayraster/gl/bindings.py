"""Shader-storage binding slots and texture units: written once here, handed to every GLSL stage
as defines.

``shader_source`` prepends ``#define BINDING_<NAME> <slot>`` for each entry, the shaders declare
``layout(std430, binding = BINDING_HEADS)``, and Python binds with
``buffer.bind_to_storage_buffer(BINDINGS["heads"])``: a slot number appears nowhere else.

Slots 0-7 only (OpenGL 4.3 guarantees 8). Two buffers share a slot because no pass uses both:
``accumulators`` (the single-pass sum) and ``heads`` (the per-pixel lists of the overlap passes)
are chosen by the ``RESOLVE`` define of ``shaders/crossing.glsl``.

What the shaders only read in bulk, the triangles and the object table, lives in textures
(``TEXTURES``: ``layout(binding = TEXTURE_TRIANGLES) uniform sampler2D``), rows of
``TEXTURE_WIDTH`` texels read with ``texelFetch``: on llvmpipe a texel costs a sixth of a
storage-buffer element (measured: 3 vec4 per triangle of 3.3 M, 26 ms against 161 ms).
"""

from __future__ import annotations

BINDINGS = {
    "candidates": 0,  # crossing pass 1's (triangle, pixel) candidates for pass 1b, and their count
    "output": 1,  # what a resolve pass writes: path lengths, or packed labels
    "stripes": 2,  # nodes taken in each stripe of the node pool
    "large": 3,  # indirect draw command + the triangles the rasteriser draws
    "accumulators": 4,  # fixed-point sums (channel, row, col); sum passes only
    "heads": 4,  # per-pixel list heads; overlap passes only
    "nodes": 5,  # crossing-list nodes
    "counters": 6,  # a resolve pass's overflowing pixels, deepest list and pixels cut short
    "large_corners": 7,  # window-space corners of the large triangles
}


TEXTURES = {
    "triangles": 0,  # the scene's triangle soup, three RGBA32F texels a triangle (read by every crossing pass)
    "objects": 1,  # RGBA32UI per object by rank: channel, drawn, container channel + 1, label
}
TEXTURE_WIDTH = 4096  # texels per row: a power of two, and within every driver's limit (OpenGL 4.3: 16384)


def binding_defines() -> dict[str, int]:
    """``{"BINDING_OUTPUT": 1, ..., "TEXTURE_TRIANGLES": 0, ..., "TEXTURE_WIDTH": 4096}`` for the GLSL preprocessor."""
    return {**{f"BINDING_{name.upper()}": slot for name, slot in BINDINGS.items()},
            **{f"TEXTURE_{name.upper()}": unit for name, unit in TEXTURES.items()}, "TEXTURE_WIDTH": TEXTURE_WIDTH}
