#version 430 core
// Crossing pass 1: one invocation per triangle. It projects the triangle and lists the pixel
// centres its box holds, two to an entry (candidates.glsl), for pass 1b
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
    // The box's pixels row by row, two to an entry, in one flat loop (cheaper than two nested).
    uint count = uint(n.x * n.y);
    uint entries = (count + 1u) / 2u;
    uint base = atomicAdd(candidate_count, entries);
    uint room = base < u_candidate_capacity ? min(entries, u_candidate_capacity - base) : 0u;
    ivec2 px = first;
    for (uint k = 0u; k < room; ++k) {
        uint a = uint(px.x) | (uint(px.y) << 16);
        if (++px.x > last.x) px = ivec2(first.x, px.y + 1);
        uint b = 2u * k + 1u < count ? uint(px.x) | (uint(px.y) << 16) : NO_PIXEL;
        if (++px.x > last.x) px = ivec2(first.x, px.y + 1);
        candidates[base + k] = uvec4(index, a, b, 0u);
    }
}
