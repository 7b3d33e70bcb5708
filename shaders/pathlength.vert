#version 430 core
// Vertex pulling: three invocations per triangle, each reading the whole triangle, so the
// fragment stage can test the pixel's ray against the exact triangle. The rasterised
// primitive is a triangle that contains the triangle's pixel bounding box grown by a small
// margin: every pixel centre the triangle covers gets a fragment whatever the rasteriser's
// sub-pixel snapping, and the exact test in the fragment stage decides the hit.

layout(std430, binding = 0) readonly buffer Vertices { float vertex_xyz[]; };
layout(std430, binding = 1) readonly buffer Faces { uint face_index[]; };

uniform mat3x4 u_world_to_pixel;  // transposed 3x4: h = P (x - ref, 1); c' = h.x/h.z, r' = h.y/h.z
uniform vec2 u_half_detector;

flat out vec3 v_a;
flat out vec3 v_b;
flat out vec3 v_c;

vec3 fetch(uint i) { return vec3(vertex_xyz[3u * i], vertex_xyz[3u * i + 1u], vertex_xyz[3u * i + 2u]); }

vec2 to_window(vec3 x) {
    vec3 h = vec4(x, 1.0) * u_world_to_pixel;
    return h.xy / h.z + u_half_detector;
}

void main() {
    int tri = gl_VertexID / 3;
    int corner = gl_VertexID - 3 * tri;
    v_a = fetch(face_index[3 * tri]);
    v_b = fetch(face_index[3 * tri + 1]);
    v_c = fetch(face_index[3 * tri + 2]);
    vec2 pa = to_window(v_a), pb = to_window(v_b), pc = to_window(v_c);
    vec2 lo = min(pa, min(pb, pc));
    vec2 hi = max(pa, max(pb, pc));
    // Margin: rasteriser snapping (<= 1/256 px) plus float32 rounding of the projection.
    vec2 margin = 1.0 / 64.0 + 1e-6 * max(abs(lo), abs(hi));
    lo -= margin;
    hi += margin;
    // No pixel centre (k + 0.5) inside the box: emit nothing the rasteriser would keep.
    if (any(greaterThan(ceil(lo - 0.5), floor(hi - 0.5)))) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
        return;
    }
    vec2 size = hi - lo;
    vec2 corner_xy = corner == 0 ? lo : (corner == 1 ? vec2(lo.x + 2.0 * size.x, lo.y) : vec2(lo.x, lo.y + 2.0 * size.y));
    gl_Position = vec4(corner_xy / u_half_detector - 1.0, 0.0, 1.0);
}
