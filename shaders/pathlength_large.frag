#version 430 core
// Crossing pass 2, fragment stage: the exact test of this pixel's ray against the triangle, with
// the corners' projections pass 1 stored for it.
#include "ray.glsl"
#include "scene.glsl"
#include "crossing.glsl"

layout(std430, binding = BINDING_LARGE) readonly buffer Large { uvec4 draw_command; uint large[]; };
layout(std430, binding = BINDING_LARGE_POINTS) readonly buffer LargePoints { vec2 large_points[]; };

flat in uint v_slot;

void main() {
    Triangle tri = fetch_triangle(large[v_slot]);
    vec2 p[3] = vec2[3](large_points[3u * v_slot], large_points[3u * v_slot + 1u], large_points[3u * v_slot + 2u]);
    vec2 q = pixel_offset(gl_FragCoord.xy);
    int side = cross_projected(p, q);
    if (side != 0) record_crossing(ivec2(gl_FragCoord.xy), tri.object, side, crossing_distance(pixel_ray(q), tri.a, tri.b, tri.c));
}
