#version 430 core
// Single additive pass (scenes without overlaps): each exit adds t, each entry subtracts t,
// so a pixel accumulates the total length inside its material's closed surfaces.
#include "ray.glsl"

flat in vec3 v_a;
flat in vec3 v_b;
flat in vec3 v_c;
out float out_length;

void main() {
    float t;
    int side = hit_triangle(pixel_ray(gl_FragCoord.xy), v_a, v_b, v_c, t);
    if (side == 0) discard;
    out_length = float(side) * t;
}
