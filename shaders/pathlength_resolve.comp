#version 430 core
// Overlap pass, step 2: per pixel, sort the crossings along the ray and sweep them. Between
// two crossings the space belongs to the highest-ranked object the ray is inside (rank order
// = priority, then insertion order), and that object's material gets the length.

#include "crossing_lists.glsl"
#include "objects.glsl"
#include "fixed_point.glsl"

layout(std430, binding = BINDING_OUTPUT) writeonly buffer Lengths { float lengths[]; };  // (channel, row, col)

uniform ivec2 u_size;  // (cols, rows)

uint acc[NUM_CHANNELS];

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    int pixel = px.y * u_size.x + px.x;
    int n = load_sorted(pixel);
    if (n <= 0) return;  // no crossing: the lengths stay as the host cleared them (most pixels of a view)
    for (int c = 0; c < NUM_CHANNELS; c++) acc[c] = 0u;
    // Each span adds its end minus its start in fixed point (fixed_point.glsl, as the sum passes),
    // each crossing's t rounded once, not a float32 running sum.
    int owner = -1;
    uint previous = 0u;
    int i = 0;
    for (; i < n; i++) {
        uint units = fixed_units(ts[i]);
        if (owner >= 0) acc[object_info(uint(owner)).x] += units - previous;
        previous = units;
        owner = sweep(i, owner);
    }
    count_truncated(i == n);
    int npix = u_size.x * u_size.y;
    for (int c = 0; c < NUM_CHANNELS; c++) lengths[c * npix + pixel] = float(int(acc[c])) / u_fixed_scale;
}
