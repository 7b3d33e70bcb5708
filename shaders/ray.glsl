// Shared by the crossing stages: the ray direction of a pixel, and an exact, watertight ray-triangle test
// in projected space with a tie rule so that a ray through a shared edge or vertex is counted by
// exactly one triangle of a surface. All positions are float32 offsets from the scene
// reference point (xrayraster/gl/rays.py).

uniform vec3 u_origin_num[3];   // ray origin Q = (N0 + c'N1 + r'N2) / (m . (1, c', r'))
uniform vec3 u_origin_den;
uniform vec3 u_direction[3];    // ray direction along D0 + c'D1 + r'D2
uniform vec2 u_half_detector;   // (cols, rows) / 2: window coordinate -> centred pixel offset
uniform float u_facing;         // +1: (detector u, v, ray direction) is right-handed; -1: left-handed

struct Ray { vec3 org; vec3 dir; };

// Offset (c', r') of a window position from the detector centre: exact for pixel centres
// (half-integers in float32).
vec2 pixel_offset(vec2 window) {
    return window - u_half_detector;
}

// The ray through the point at offset p (pixel_offset) on the detector: its origin near the
// scene (on the plane through the reference point facing the source) and unit direction.
Ray pixel_ray(vec2 p) {
    vec3 num = u_origin_num[0] + p.x * u_origin_num[1] + p.y * u_origin_num[2];
    float den = u_origin_den.x + p.x * u_origin_den.y + p.y * u_origin_den.z;
    vec3 d = u_direction[0] + p.x * u_direction[1] + p.y * u_direction[2];
    return Ray(num / den, normalize(d));
}

// An edge of zero edge-function value belongs to the triangle for which the edge, oriented by
// the triangle's facing, points "up" (or right when horizontal). The two triangles sharing an
// edge see it reversed, so exactly one owns it; at a silhouette both do or neither does, and
// their entry and exit cancel.
bool owns_edge(float value, vec2 edge) {
    return value > 0.0 || (value == 0.0 && (edge.y > 0.0 || (edge.y == 0.0 && edge.x > 0.0)));
}

// Does the ray of the pixel at offset q cross the triangle whose corners project to p (to_pixel)?
// 0: miss. +1: the ray leaves the solid through it, -1: it enters.
//
// Exact and watertight in projected (pixel) space (Woop, Benthin & Wald, JCGT 2013, after their
// shear, which a projection through the source already is): a ray crosses a triangle exactly
// when its pixel centre lies in the triangle's projection, the edge functions are 2-D cross
// products of corners relative to q, and a shared edge's corners are the same float32 values
// in both its triangles (one projection per corner, by the same code: to_pixel), so its two
// evaluations are exactly opposite: a ray through an edge or vertex is counted by one triangle.
int cross_projected(vec2 p[3], vec2 q) {
    // 'precise' forbids fused multiply-adds, which would break that exact opposition.
    precise vec2 a2 = p[0] - q;
    precise vec2 b2 = p[1] - q;
    precise vec2 c2 = p[2] - q;
    precise float U = c2.x * b2.y - c2.y * b2.x;  // edge B->C
    precise float V = a2.x * c2.y - a2.y * c2.x;  // edge C->A
    precise float W = b2.x * a2.y - b2.y * a2.x;  // edge A->B

    float s;
    if (U >= 0.0 && V >= 0.0 && W >= 0.0) s = 1.0;
    else if (U <= 0.0 && V <= 0.0 && W <= 0.0) s = -1.0;
    else return 0;
    float det = U + V + W;
    if (det == 0.0) return 0;  // edge-on or degenerate: no length
    if (!owns_edge(s * U, s * (c2 - b2)) || !owns_edge(s * V, s * (a2 - c2)) || !owns_edge(s * W, s * (b2 - a2)))
        return 0;
    // s > 0: the ray meets the outward (counter-clockwise) side, an entry, in a right-handed
    // (column, row, depth) frame; u_facing is -1 where the detector's is left-handed.
    return s * u_facing > 0.0 ? -1 : 1;
}

// Distance (mm) from the ray's origin to where it crosses the plane of triangle ABC (the ray is
// known to cross the triangle). Measured in 3-D from an origin beside the scene, not from the
// triangle's projection: a ray at a grazing angle to a face then places the crossing to float32
// rounding of positions near the scene, as two coincident faces of different meshes need. Kept
// within the triangle's own depth range along the ray, so a sliver whose normal float32 cannot
// resolve still gives a crossing on the triangle.
float crossing_distance(Ray ray, vec3 A, vec3 B, vec3 C) {
    vec3 a = A - ray.org;
    vec3 n = cross(B - A, C - A);
    float ta = dot(a, ray.dir), tb = dot(B - ray.org, ray.dir), tc = dot(C - ray.org, ray.dir);
    float lo = min(ta, min(tb, tc)), hi = max(ta, max(tb, tc));
    float den = dot(n, ray.dir);
    return den != 0.0 ? clamp(dot(n, a) / den, lo, hi) : 0.5 * (lo + hi);
}
