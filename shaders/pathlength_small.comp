#version 430 core
// Crossing pass 1: one invocation per triangle. It projects the triangle and lists the pixel
// centres of its box within the margin of it, two to an entry (candidates.glsl), for pass 1b
// (pathlength_candidates.comp), which tests them exactly. Testing them here, in a loop whose trip
// count differs from lane to lane, kept most SIMD lanes idle: on llvmpipe the split is 1.4-1.5x
// faster (BENCHMARKS.md). A triangle whose box holds more than MAX_SMALL_PIXELS pixel centres is
// appended instead to a list for the rasterised pass 2, as a glDrawArraysIndirect command
// (6 vertices each: see pathlength_large.vert): for large triangles the rasteriser's per-pixel
// cost beats a loop.
#include "scene.glsl"
#include "candidates.glsl"
#include "grow.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = BINDING_LARGE) buffer Large { uint draw_count; uint draw_instances; uint draw_first; uint draw_base; uint large[]; };
layout(std430, binding = BINDING_LARGE_CORNERS) writeonly buffer LargeCorners { vec2 large_corners[]; };

uniform uint u_num_triangles;

void main() {
    // 2-D dispatch: one dimension holds at most 65535 groups (4 M triangles) on many drivers.
    uint index = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x + gl_LocalInvocationIndex;
    if (index >= u_num_triangles) return;
    Triangle tri = fetch_triangle(index);
    if (object_info(tri.object).y == 0u) return;  // behind the source in this view
    vec2 p[3] = vec2[3](to_window(tri.a), to_window(tri.b), to_window(tri.c));
    vec2 lo = min(p[0], min(p[1], p[2]));
    vec2 hi = max(p[0], max(p[1], p[2]));
    float m = margin(lo, hi);
    ivec2 first, last;
    pixel_range(lo - m, hi + m, first, last);
    if (any(greaterThan(first, last))) return;
    ivec2 n = last - first + 1;
    if (n.x * n.y > MAX_SMALL_PIXELS) {
        uint slot = atomicAdd(draw_count, 6u) / 6u;
        large[slot] = index;
        vec2 corners[6];
        grown_primitives(p, m, corners);
        for (int k = 0; k < 6; ++k) large_corners[6u * slot + uint(k)] = corners[k];
        return;
    }
    // Only the box's pixel centres within the margin of the projected triangle become candidates:
    // a superset of those the exact test can accept (the same margin that grows pass 2's
    // triangles), about 0.4 of the box on a woven sample. Counted row by row first, so the
    // entries are reserved at once and written two to an entry.
    RowSpans spans = row_spans(p, m);
    uint count = 0u;
    for (int y = first.y; y <= last.y; ++y) {
        ivec2 span = row_span(spans, float(y) + 0.5, ivec2(first.x, last.x));
        count += uint(max(span.y - span.x + 1, 0));
    }
    if (count == 0u) return;
    uint entries = (count + 1u) / 2u;
    uint base = atomicAdd(candidate_count, entries);
    uint room = base < u_candidate_capacity ? min(entries, u_candidate_capacity - base) : 0u;
    uint written = 0u;
    uint pending = NO_PIXEL;
    for (int y = first.y; y <= last.y && written < room; ++y) {
        ivec2 span = row_span(spans, float(y) + 0.5, ivec2(first.x, last.x));
        for (int x = span.x; x <= span.y && written < room; ++x) {
            uint pixel = uint(x) | (uint(y) << 16);
            if (pending == NO_PIXEL) { pending = pixel; continue; }
            candidates[base + written++] = uvec4(index, pending, pixel, 0u);
            pending = NO_PIXEL;
        }
    }
    if (pending != NO_PIXEL && written < room) candidates[base + written] = uvec4(index, pending, NO_PIXEL, 0u);
}
