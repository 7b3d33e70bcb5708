// Shared by the path-length fragment stages: the ray of the pixel under a fragment, and an
// exact, watertight ray-triangle test (Woop, Benthin & Wald, JCGT 2013) with a tie rule so that
// a ray through a shared edge or vertex is counted by exactly one triangle of a surface.
// All positions are float32 offsets from the scene reference point (xrayraster/gl/rays.py).

uniform vec3 u_origin_num[3];   // ray origin Q = (N0 + c'N1 + r'N2) / (m . (1, c', r'))
uniform vec3 u_origin_den;
uniform vec3 u_direction[3];    // ray direction along D0 + c'D1 + r'D2
uniform vec2 u_half_detector;   // (cols, rows) / 2: window coordinate -> centred pixel offset

struct Ray { vec3 org; vec3 dir; };

Ray pixel_ray(vec2 frag_coord) {
    vec2 p = frag_coord - u_half_detector;  // exact: half-integers in float32
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

// 0: miss. +1: the ray leaves the solid through this triangle, -1: it enters. t: distance (mm)
// from the ray origin along the unit direction.
int hit_triangle(Ray ray, vec3 A, vec3 B, vec3 C, out float t) {
    vec3 ad = abs(ray.dir);
    int kz = ad.x > ad.y ? (ad.x > ad.z ? 0 : 2) : (ad.y > ad.z ? 1 : 2);
    int kx = kz == 2 ? 0 : kz + 1;
    int ky = kx == 2 ? 0 : kx + 1;
    if (ray.dir[kz] < 0.0) { int tmp = kx; kx = ky; ky = tmp; }
    float sx = ray.dir[kx] / ray.dir[kz];
    float sy = ray.dir[ky] / ray.dir[kz];
    float sz = 1.0 / ray.dir[kz];

    // 'precise' forbids fused multiply-adds, so a shared edge evaluates to exactly opposite
    // values in its two triangles: the property watertightness rests on.
    precise vec3 a = A - ray.org;
    precise vec3 b = B - ray.org;
    precise vec3 c = C - ray.org;
    precise vec2 a2 = vec2(a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
    precise vec2 b2 = vec2(b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
    precise vec2 c2 = vec2(c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
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
    t = (U * a[kz] + V * b[kz] + W * c[kz]) * sz / det;
    return s > 0.0 ? -1 : 1;  // s > 0: the ray meets the outward (counter-clockwise) side: entry
}
