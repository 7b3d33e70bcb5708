#version 430 core
// Overlap pass, step 1: append every exact ray-surface crossing to a per-pixel linked list.
#include "ray.glsl"

layout(binding = 0, r32ui) uniform coherent uimage2D u_heads;
layout(std430, binding = 2) buffer Nodes { uvec4 nodes[]; };  // (t bits, rank*2 + exit, next, -)
layout(std430, binding = 3) buffer Counter { uint node_count; };

uniform uint u_capacity;
uniform uint u_rank;

flat in vec3 v_a;
flat in vec3 v_b;
flat in vec3 v_c;

void main() {
    float t;
    int side = hit_triangle(pixel_ray(gl_FragCoord.xy), v_a, v_b, v_c, t);
    if (side != 0) {
        uint slot = atomicAdd(node_count, 1u);
        if (slot < u_capacity) {
            uint next = imageAtomicExchange(u_heads, ivec2(gl_FragCoord.xy), slot);
            nodes[slot] = uvec4(floatBitsToUint(t), 2u * u_rank + uint(side > 0), next, 0u);
        }
    }
    discard;
}
