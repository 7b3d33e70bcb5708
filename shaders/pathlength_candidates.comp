#version 430 core
// Crossing pass 1b: one invocation per entry of pass 1 (a triangle and up to two pixels), the
// exact test of each pixel's ray against the triangle.
#include "ray.glsl"
#include "scene.glsl"
#include "crossing.glsl"
#include "candidates.glsl"

layout(local_size_x = 64) in;

void main() {
    uint index = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x + gl_LocalInvocationIndex;
    if (index >= min(candidate_count, u_candidate_capacity)) return;
    uvec4 entry = candidates[index];
    Triangle tri = fetch_triangle(entry.x);
    for (int k = 1; k <= 2; ++k) {
        if (entry[k] == NO_PIXEL) break;
        ivec2 px = ivec2(entry[k] & 0xFFFFu, entry[k] >> 16);
        float t;
        int side = hit_triangle(pixel_ray(vec2(px) + 0.5), tri.a, tri.b, tri.c, t);
        if (side != 0) record_crossing(px, tri, side, t);
    }
}
