// Shared by the crossing passes: what the rasteriser draws for a large triangle (six corners,
// two primitives). It contains the projected triangle grown by a margin, so every pixel centre
// the real triangle covers gets a fragment whatever the rasteriser's sub-pixel snapping; the
// fragment stage's exact test then decides the hit.
//  * Triangles without sharp corners: the triangle with each edge pushed out by the margin
//    (the second primitive is left empty).
//  * Needles and slivers (a corner under ~7 degrees): pushing the edges would throw that corner
//    far out along a direction float32 cannot resolve, so a rectangle aligned with the longest
//    edge is drawn instead; it is tight for such triangles.

// Unit normal of edge p -> q pointing away from a triangle of orientation `winding` (+1: ccw).
vec2 outward(vec2 p, vec2 q, float winding) {
    vec2 e = q - p;
    return winding * normalize(vec2(e.y, -e.x));
}

vec2 pushed_corner(vec2 p[3], int corner, float margin, float winding) {
    // Where pushed edges (i-1 -> i) and (i -> i+1) meet: p_i + margin (n1 + n2) / (1 + n1.n2),
    // written as p_i + 2 margin s / |s|^2 with s = n1 + n2 (|s| = 2 sin(angle / 2)).
    vec2 s = outward(p[(corner + 2) % 3], p[corner], winding) + outward(p[corner], p[(corner + 1) % 3], winding);
    return p[corner] + (2.0 * margin / dot(s, s)) * s;
}

bool has_sharp_corner(vec2 p[3], float winding) {
    for (int i = 0; i < 3; ++i) {
        vec2 s = outward(p[(i + 2) % 3], p[i], winding) + outward(p[i], p[(i + 1) % 3], winding);
        if (dot(s, s) < 1.0 / 64.0) return true;  // |s| < 1/8: angle < 7.2 degrees
    }
    return false;
}

vec2 edge_aligned_rectangle_corner(vec2 p[3], int corner, float margin) {
    vec2 e01 = p[1] - p[0], e12 = p[2] - p[1], e20 = p[0] - p[2];
    float l01 = dot(e01, e01), l12 = dot(e12, e12), l20 = dot(e20, e20);
    vec2 origin = l01 >= l12 && l01 >= l20 ? p[0] : (l12 >= l20 ? p[1] : p[2]);
    vec2 edge = l01 >= l12 && l01 >= l20 ? e01 : (l12 >= l20 ? e12 : e20);
    float len = length(edge);
    vec2 e = len > 0.0 ? edge / len : vec2(1.0, 0.0);
    vec2 n = vec2(-e.y, e.x);
    vec2 lo = vec2(1e38), hi = vec2(-1e38);
    for (int k = 0; k < 3; ++k) {
        vec2 uv = vec2(dot(p[k] - origin, e), dot(p[k] - origin, n));
        lo = min(lo, uv);
        hi = max(hi, uv);
    }
    lo -= margin;
    hi += margin;
    // Two primitives (0, 1, 2) and (0, 2, 3) over the rectangle's corners.
    int k = corner < 3 ? corner : (corner == 3 ? 0 : corner - 2);
    vec2 uv = vec2(k == 1 || k == 2 ? hi.x : lo.x, k >= 2 ? hi.y : lo.y);
    return origin + uv.x * e + uv.y * n;
}

// The six window-space corners drawn for a triangle whose projected corners are p.
void grown_primitives(vec2 p[3], float margin, out vec2 corners[6]) {
    float area2 = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[1].y - p[0].y) * (p[2].x - p[0].x);
    float winding = sign(area2);
    bool pushed = winding != 0.0 && !has_sharp_corner(p, winding);
    for (int k = 0; k < 6; ++k)
        corners[k] = pushed ? pushed_corner(p, k < 3 ? k : 0, margin, winding)  // 3..5: an empty primitive
                            : edge_aligned_rectangle_corner(p, k, margin);
}

// Pass 1's candidate pixels: the projected triangle with each edge pushed out by `margin` px, row
// by row. A pixel centre outside it is farther than the margin from the triangle, so no exact
// test can accept it (pass 2 grows its triangles by the same margin). Edge i is the half-plane
// a·x + c ≥ 0; on the row through y it bounds x from below (a.x > 0) or above (a.x < 0) at
// slope·y + offset, or, parallel to the rows (a.x = 0), holds for the whole row or for none.
// A triangle thinner than the margin, whose orientation rounding may flip, lies within the
// margin of either orientation's half-planes, and a degenerate edge (a = 0, c = 0) imposes
// nothing: the region stays a superset for slivers and needles.
struct RowSpans { vec3 slope; vec3 offset; bvec3 lower; bvec3 upper; vec3 flat_a; vec3 flat_c; };

RowSpans row_spans(vec2 p[3], float margin) {
    vec2 d0 = p[1] - p[0], d2 = p[0] - p[2];
    float winding = d0.x * d2.y - d0.y * d2.x > 0.0 ? -1.0 : 1.0;  // cross(p1 - p0, p2 - p0) < 0: clockwise
    RowSpans s;
    for (int i = 0; i < 3; ++i) {
        vec2 d = p[(i + 1) % 3] - p[i];
        vec2 a = winding * vec2(-d.y, d.x);  // inward normal, |a| = |d|
        float c = margin * length(d) - dot(a, p[i]);
        float across = a.x == 0.0 ? 0.0 : -1.0 / a.x;
        s.slope[i] = a.y * across;
        s.offset[i] = c * across;
        s.lower[i] = a.x > 0.0;
        s.upper[i] = a.x < 0.0;
        s.flat_a[i] = a.x == 0.0 ? a.y : 0.0;
        s.flat_c[i] = a.x == 0.0 ? c : 0.0;
    }
    return s;
}

// The columns [x, y] of `columns` (none when x > y) whose pixel centres on the row through
// `y_centre` lie inside all three half-planes.
ivec2 row_span(RowSpans s, float y_centre, ivec2 columns) {
    vec3 bound = s.slope * y_centre + s.offset;
    // mix by a bvec selects; a float weight may be computed x + w (y - x), which at 3e38 loses the
    // bound whole (an NVIDIA H200 lost or misplaced crossings so at 256² and 512²).
    vec3 low = mix(vec3(-3.0e38), bound, s.lower), high = mix(vec3(3.0e38), bound, s.upper);
    if (any(lessThan(s.flat_a * y_centre + s.flat_c, vec3(0.0)))) return ivec2(1, 0);
    float lo = max(float(columns.x) + 0.5, max(low.x, max(low.y, low.z)));
    float hi = min(float(columns.y) + 0.5, min(high.x, min(high.y, high.z)));
    return ivec2(ceil(lo - 0.5), floor(hi - 0.5));
}
