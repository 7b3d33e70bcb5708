#version 430 core
// Crossing pass 2, fragment stage: the exact test of this pixel's ray against the triangle.
#include "ray.glsl"
#include "scene.glsl"
#include "crossing.glsl"

flat in uint v_triangle;

void main() {
    Triangle tri = fetch_triangle(v_triangle);
    float t;
    int side = hit_triangle(pixel_ray(gl_FragCoord.xy), tri.a, tri.b, tri.c, t);
    if (side != 0) record_crossing(ivec2(gl_FragCoord.xy), tri, side, t);
}
