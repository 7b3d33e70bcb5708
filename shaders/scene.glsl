// Shared by the crossing stages: the scene's triangles (uploaded once, positions relative to
// the scene reference point) and the pixel box a triangle's projection can cover.

#include "objects.glsl"

// Three texels per triangle, its corners (xyz mm; the corners' w hold, as bits, the object number,
// its channel, and 1 for an overlap term of sign -1), row by row TEXTURE_WIDTH texels wide: a
// triangle soup, read in order, costs less than indexed vertices gathered at random, and texels
// less than storage-buffer elements (objects.glsl). What a crossing records is then in the
// triangle: the object table is read only where a container channel is subtracted per crossing.
layout(binding = TEXTURE_TRIANGLES) uniform sampler2D u_triangles;

uniform mat3x4 u_world_to_pixel;  // transposed 3x4: h = P (x - ref, 1); c' = h.x/h.z, r' = h.y/h.z
uniform ivec2 u_size;             // detector (cols, rows)
uniform float u_snap_margin;      // px: eight times the rasteriser's largest vertex snap

struct Triangle { vec3 a; vec3 b; vec3 c; uint object; uint channel; bool negative; };

// Objects are numbered by rank (priority, then insertion), so `object` also orders ownership.
vec4 corner(uint texel) {
    return texelFetch(u_triangles, ivec2(texel % uint(TEXTURE_WIDTH), texel / uint(TEXTURE_WIDTH)), 0);
}

Triangle fetch_triangle(uint index) {
    vec4 a = corner(3u * index), b = corner(3u * index + 1u), c = corner(3u * index + 2u);
    return Triangle(a.xyz, b.xyz, c.xyz, floatBitsToUint(a.w), floatBitsToUint(b.w), floatBitsToUint(c.w) != 0u);
}

vec2 to_window(vec3 x) {
    vec3 h = vec4(x, 1.0) * u_world_to_pixel;
    return h.xy / h.z + vec2(u_size) * 0.5;
}

// Margin (px) by which a projected triangle with window box [lo, hi] is grown: the
// rasteriser's sub-pixel snapping plus float32 rounding of the projection, with room to spare.
float margin(vec2 lo, vec2 hi) {
    return u_snap_margin + 1e-6 * max(max(abs(lo.x), abs(lo.y)), max(abs(hi.x), abs(hi.y)));
}

// First and last pixel (column, row) whose centre lies in the box, clipped to the detector.
void pixel_range(vec2 lo, vec2 hi, out ivec2 first, out ivec2 last) {
    first = max(ivec2(ceil(lo - 0.5)), ivec2(0));
    last = min(ivec2(floor(hi - 0.5)), u_size - 1);
}
