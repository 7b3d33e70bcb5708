#version 430 core
// Crossing pass 1: one invocation per triangle. A triangle whose pixel box holds at most
// MAX_SMALL_PIXELS pixel centres is tested exactly against each of those pixels' rays here:
// for the small triangles of dense meshes this beats the rasteriser, whose cost is per
// primitive. Larger triangles are appended to a list for the rasterised pass 2, as a
// glDrawArraysIndirect command (6 vertices each: see pathlength_large.vert).
#include "ray.glsl"
#include "scene.glsl"
#include "crossing.glsl"
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
    for (int y = first.y; y <= last.y; ++y) {
        for (int x = first.x; x <= last.x; ++x) {
            float t;
            int side = hit_triangle(pixel_ray(vec2(x, y) + 0.5), tri.a, tri.b, tri.c, t);
            if (side != 0) record_crossing(ivec2(x, y), tri.object, side, t);
        }
    }
}
