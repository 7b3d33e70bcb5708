#version 430 core
// Crossing pass 2, vertex stage: the corners pass 1 computed for each large triangle
// (shaders/grow.glsl), six per triangle. Kept trivial on purpose: software GL runs this stage
// on one thread, the compute pass on all cores.

layout(std430, binding = BINDING_LARGE) readonly buffer Large { uvec4 draw_command; uint large[]; };
layout(std430, binding = BINDING_LARGE_CORNERS) readonly buffer LargeCorners { vec2 large_corners[]; };

uniform ivec2 u_size;  // detector (cols, rows)

flat out uint v_triangle;

void main() {
    v_triangle = large[gl_VertexID / 6];
    gl_Position = vec4(2.0 * large_corners[gl_VertexID] / vec2(u_size) - 1.0, 0.0, 1.0);
}
