#version 430 core
// Overlap pass, step 2: per pixel, sort the crossings along the ray and sweep them. Between
// two crossings the space belongs to the highest-ranked object the ray is inside (rank order
// = priority, then insertion order), and that object's material gets the length.

#include "crossing_lists.glsl"
#include "objects.glsl"

layout(std430, binding = BINDING_OUTPUT) writeonly buffer Lengths { float lengths[]; };  // (channel, row, col)

uniform ivec2 u_size;  // (cols, rows)
uniform float u_fixed_scale;  // fixed-point units per mm, as the sum passes use (crossing.glsl)

uint acc[NUM_CHANNELS];

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    int pixel = px.y * u_size.x + px.x;
    int n = load_sorted(pixel);
    if (n < 0) return;
    for (int c = 0; c < NUM_CHANNELS; c++) acc[c] = 0u;
    // Each span adds its end minus its start in fixed point, each crossing's t rounded once: the
    // integer sums are exact (modulo 2^32: only the length must fit), so a channel's length has the
    // error of its crossings' t alone (as the sum passes), not that of a float32 running sum.
    int owner = -1;
    uint previous = 0u;
    for (int i = 0; i < n; i++) {
        float a = round(abs(ts[i]) * u_fixed_scale);  // |t| mod 2^32, exact, as crossing.glsl takes it
        uint magnitude = uint(a - 4294967296.0 * floor(a * (1.0 / 4294967296.0)));
        uint units = ts[i] >= 0.0 ? magnitude : 0u - magnitude;
        if (owner >= 0) acc[object_info(uint(owner)).x] += units - previous;
        previous = units;
        owner = sweep(i);
    }
    int npix = u_size.x * u_size.y;
    for (int c = 0; c < NUM_CHANNELS; c++) lengths[c * npix + pixel] = float(int(acc[c])) / u_fixed_scale;
}
