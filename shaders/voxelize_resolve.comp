#version 430 core
// Label pass (xrayraster/gl/voxelize.py): one invocation per voxel column. The column's crossings,
// recorded by the path-length passes in RESOLVE mode for a parallel "view" looking along +z
// whose pixels are the voxel columns, are sorted and swept upward together with the slab's
// voxel centres. Below a voxel centre, every crossing changes its object's winding count (entry
// +1, exit -1): the centre is inside the objects whose count is positive, and gets the label of
// the highest-ranked of them (priority, then insertion order: the renderer's ownership rule,
// with the same exact crossings), or 0.
//
// Labels are packed: LABELS_PER_WORD slices of one column share a 32-bit word (4 uint8 labels
// or 2 uint16), so a slab needs a quarter (half) of the memory and read-back of one word each.

layout(local_size_x = 8, local_size_y = 8) in;
layout(std430, binding = 2) readonly buffer Objects { uvec4 objects[]; };  // -, -, -, label (by rank)
layout(std430, binding = 4) readonly buffer Heads { uint heads[]; };
layout(std430, binding = 5) readonly buffer Nodes { uvec4 nodes[]; };      // t bits, object*2 + exit, next, -
layout(std430, binding = 6) buffer Counters { uint node_count; uint overflow_pixels; uint max_depth; };
layout(std430, binding = 7) writeonly buffer Labels { uint words[]; };     // (slice / LABELS_PER_WORD, row, col)

uniform ivec2 u_size;   // voxel columns (nx, ny)
uniform float u_t0;     // the slab's first voxel centre: mm along +z from the rays' origin plane
uniform float u_dt;     // voxel size along z, mm
uniform int u_slices;   // slices in the slab, a multiple of LABELS_PER_WORD

const uint END = 0xFFFFFFFFu;
const int BITS = 32 / LABELS_PER_WORD;
float ts[MAX_CROSSINGS];
uint metas[MAX_CROSSINGS];
uint active_rank[MAX_CROSSINGS];
int active_count[MAX_CROSSINGS];

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    int column = px.y * u_size.x + px.x;
    uint node = heads[column];  // the lists stay for the next slab; the host empties them at the end
    int n = 0;
    int depth = 0;
    while (node != END) {
        if (n < MAX_CROSSINGS) {
            uvec4 e = nodes[node];
            float t = uintBitsToFloat(e.x);
            int k = n;  // insertion sort by t
            while (k > 0 && ts[k - 1] > t) { ts[k] = ts[k - 1]; metas[k] = metas[k - 1]; k--; }
            ts[k] = t;
            metas[k] = e.y;
            n++;
            node = e.z;
        } else {
            node = nodes[node].z;
        }
        depth++;
    }
    if (depth > MAX_CROSSINGS) {  // the host recompiles with room for max_depth and runs the slab again
        atomicAdd(overflow_pixels, 1u);
        atomicMax(max_depth, uint(depth));
        return;
    }
    int n_active = 0;
    int owner = -1;  // index into active_* of the current owner
    int i = 0;
    int plane = u_size.x * u_size.y;
    uint word = 0u;
    for (int s = 0; s < u_slices; s++) {
        float t = u_t0 + float(s) * u_dt;
        for (; i < n && ts[i] < t; i++) {
            uint rank = metas[i] >> 1;  // object index = rank order
            int step = (metas[i] & 1u) == 1u ? -1 : 1;  // exit leaves, entry enters
            int j = 0;
            while (j < n_active && active_rank[j] != rank) j++;
            if (j == n_active) { active_rank[j] = rank; active_count[j] = 0; n_active++; }
            active_count[j] += step;
            owner = -1;
            for (int q = 0; q < n_active; q++)
                if (active_count[q] > 0 && (owner < 0 || active_rank[q] > active_rank[owner])) owner = q;
        }
        uint label = owner < 0 ? 0u : objects[active_rank[owner]].w;
        int lane = s % LABELS_PER_WORD;
        word |= label << (BITS * lane);
        if (lane == LABELS_PER_WORD - 1) {
            words[(s / LABELS_PER_WORD) * plane + column] = word;
            word = 0u;
        }
    }
}
