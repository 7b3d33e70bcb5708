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

#include "crossing_lists.glsl"
#include "objects.glsl"

layout(std430, binding = BINDING_OUTPUT) writeonly buffer Labels { uint words[]; };      // (slice / LABELS_PER_WORD, row, col)

uniform ivec2 u_size;   // voxel columns (nx, ny)
uniform float u_t0;     // the slab's first voxel centre: mm along +z from the rays' origin plane
uniform float u_dt;     // voxel size along z, mm
uniform int u_slices;   // slices in the slab, a multiple of LABELS_PER_WORD

const int BITS = 32 / LABELS_PER_WORD;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    int column = px.y * u_size.x + px.x;
    int n = load_sorted(column);
    if (n < 0) return;
    int owner = -1;
    int i = 0;
    int plane = u_size.x * u_size.y;
    uint word = 0u;
    int s = 0;
    for (; s < u_slices; s++) {
        float t = u_t0 + float(s) * u_dt;
        for (; i < n && ts[i] < t; i++) owner = sweep(i, owner);
        uint label = owner < 0 ? 0u : object_info(uint(owner)).w;
        int lane = s % LABELS_PER_WORD;
        word |= label << (BITS * lane);
        if (lane == LABELS_PER_WORD - 1) {
            words[(s / LABELS_PER_WORD) * plane + column] = word;
            word = 0u;
        }
    }
    count_truncated(s == u_slices);
}
