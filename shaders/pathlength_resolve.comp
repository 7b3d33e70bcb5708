#version 430 core
// Overlap pass, step 2: per pixel, sort the crossings along the ray and sweep them. Between
// two crossings the space belongs to the highest-ranked object the ray is inside (rank order
// = priority, then insertion order), and that object's material gets the length.

layout(local_size_x = 8, local_size_y = 8) in;
layout(std430, binding = 2) readonly buffer Objects { uvec4 objects[]; };  // channel, active, (container channel + 1), -
layout(std430, binding = 4) buffer Heads { uint heads[]; };
layout(std430, binding = 5) readonly buffer Nodes { uvec4 nodes[]; };      // t bits, object*2 + exit, next, -
layout(std430, binding = 6) buffer Counters { uint node_count; uint overflow_pixels; uint max_depth; };
layout(std430, binding = 7) writeonly buffer Lengths { float lengths[]; };  // (channel, row, col)

uniform ivec2 u_size;  // (cols, rows)

const uint END = 0xFFFFFFFFu;
float ts[MAX_CROSSINGS];
uint metas[MAX_CROSSINGS];
uint active_rank[MAX_CROSSINGS];
int active_count[MAX_CROSSINGS];
float acc[NUM_CHANNELS];

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    int pixel = px.y * u_size.x + px.x;
    uint node = heads[pixel];
    heads[pixel] = END;  // leave the list empty for the next view
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
    if (depth > MAX_CROSSINGS) {
        atomicAdd(overflow_pixels, 1u);
        atomicMax(max_depth, uint(depth));
    }
    for (int c = 0; c < NUM_CHANNELS; c++) acc[c] = 0.0;
    int n_active = 0;
    int owner = -1;  // index into active_* of the current owner
    for (int i = 0; i < n; i++) {
        if (owner >= 0 && i > 0) acc[objects[active_rank[owner]].x] += ts[i] - ts[i - 1];
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
    int npix = u_size.x * u_size.y;
    for (int c = 0; c < NUM_CHANNELS; c++) lengths[c * npix + pixel] = acc[c];
}
