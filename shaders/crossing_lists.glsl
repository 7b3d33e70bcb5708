// Shared by the resolve passes: read one pixel's crossing list (recorded by crossing.glsl in
// RESOLVE mode), sort it along the ray, and sweep it with the ownership rule. The lists stay in
// place; the host empties them when the last resolve pass of a view is done.
//
// llvmpipe ends every loop of a shader invocation once all its loops together have run 65535
// steps (Mesa's LP_MAX_TGSI_LOOP_ITERATIONS), silently: a pixel whose ray crosses a few hundred
// surfaces then came out wrong when the sort took n² steps. The sort takes n log2 n, and a pass
// reports each pixel whose last loop did not run to its end (truncated) through
// count_truncated; the host refuses the view's result then (xrayraster/gl/crossings.py).

layout(local_size_x = 8, local_size_y = 8) in;
layout(std430, binding = BINDING_HEADS) readonly buffer Heads { uint heads[]; };
layout(std430, binding = BINDING_NODES) readonly buffer Nodes { uvec4 nodes[]; };  // t bits, object*2 + exit, next, -
layout(std430, binding = BINDING_COUNTERS) buffer Counters { uint overflow_pixels; uint max_depth; uint truncated_pixels; };

const uint END = 0xFFFFFFFFu;
float ts[MAX_CROSSINGS];
uint metas[MAX_CROSSINGS];
float listed_ts[MAX_CROSSINGS];  // in list order, before sorting
uint listed_metas[MAX_CROSSINGS];
uint active_rank[MAX_CROSSINGS];
int active_count[MAX_CROSSINGS];
int n_active = 0;

// One merge pass: the runs of `width` in SRC (n entries) merged pairwise into DST, the left
// run's entry first on equal t. A macro: GLSL copies arrays passed to functions. The reads are
// clamped because a SIMD driver may evaluate both sides of || and && for every lane.
#define MERGE_PASS(SRC_T, SRC_M, DST_T, DST_M) \
    for (int k = 0, i = 0, j = 0, mid = 0, end = 0; k < n; k++) { \
        if (k == end) { i = k; mid = min(k + width, n); j = mid; end = min(k + 2 * width, n); } \
        bool left = j >= end || (i < mid && SRC_T[min(i, n - 1)] <= SRC_T[min(j, n - 1)]); \
        int from = left ? i : j; \
        DST_T[k] = SRC_T[from]; \
        DST_M[k] = SRC_M[from]; \
        if (left) i++; else j++; \
    }

// Counts a pixel whose resolve pass was cut short: `complete` is false when its last loop did not
// run to its end (module comment).
void count_truncated(bool complete) {
    if (!complete) atomicAdd(truncated_pixels, 1u);
}

// The list of `pixel` into ts/metas, sorted by t; returns how many crossings it holds, or -1
// after counting an overflow when it holds more than MAX_CROSSINGS (the host then reruns the
// pass with room for max_depth).
int load_sorted(int pixel) {
    uint node = heads[pixel];
    int n = 0;
    int depth = 0;
    while (node != END) {
        uvec4 e = nodes[node];
        if (n < MAX_CROSSINGS) {
            listed_ts[n] = uintBitsToFloat(e.x);
            listed_metas[n] = e.y;
            n++;
        }
        node = e.z;
        depth++;
    }
    if (depth > MAX_CROSSINGS) {
        atomicAdd(overflow_pixels, 1u);
        atomicMax(max_depth, uint(depth));
        return -1;
    }
    // A stable bottom-up merge sort (ties stay in list order), passes alternating between the
    // listed and the sorted arrays: ceil(log2 n) passes of n steps each.
    bool in_listed = true;
    for (int width = 1; width < n; width *= 2) {
        if (in_listed) MERGE_PASS(listed_ts, listed_metas, ts, metas)
        else MERGE_PASS(ts, metas, listed_ts, listed_metas)
        in_listed = !in_listed;
    }
    if (in_listed) {
        for (int k = 0; k < n; k++) {
            ts[k] = listed_ts[k];
            metas[k] = listed_metas[k];
        }
    }
    return n;
}

// Crossing i enters (+1) or leaves (-1) its object; given the owner before it, returns the rank
// of the object that owns the space after it: the highest-ranked (priority, then insertion order)
// object the ray is inside, or -1 for none. The active list holds only the objects the ray is
// inside (an object whose count returns to 0 leaves it), so it stays as short as the nesting is
// deep however many objects the ray crosses: keeping every object once met made each crossing
// cost O(objects met). Only the owner's own exit needs the list searched for the next owner.
int sweep(int i, int owner) {
    uint rank = metas[i] >> 1;  // object index = rank order
    int step = (metas[i] & 1u) == 1u ? -1 : 1;  // exit leaves, entry enters
    int j = 0;
    while (j < n_active && active_rank[j] != rank) j++;
    if (j == n_active) { active_rank[j] = rank; active_count[j] = 0; n_active++; }
    int count = active_count[j] + step;
    active_count[j] = count;
    if (count == 0) {
        n_active--;
        active_rank[j] = active_rank[n_active];
        active_count[j] = active_count[n_active];
    }
    if (count > 0) return max(owner, int(rank));
    if (int(rank) != owner) return owner;
    owner = -1;
    for (int q = 0; q < n_active; q++)
        if (active_count[q] > 0 && int(active_rank[q]) > owner) owner = int(active_rank[q]);
    return owner;
}
