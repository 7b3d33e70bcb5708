// Where a ray-surface crossing goes. Two variants, chosen by the RESOLVE define:
//  * sum (default): the signed distance goes into the pixel's 32-bit fixed-point accumulator of
//    the triangle's channel (fixed_point.glsl: exact, order-independent sums, so the total is
//    deterministic), and, for an object nested in another (Scene.nesting), is taken off its
//    container's channel (here, with u_containers; else the host takes whole channels off). An
//    overlap term (scene/overlap_terms.py) whose sign is -1 counts the other way round in both.
//  * RESOLVE: the crossing is appended to the pixel's linked list for pathlength_resolve.comp.

#ifdef RESOLVE
// The node pool is cut into 2^NODE_STRIPE_BITS stripes of u_stripe_capacity nodes, and a pixel's
// crossings go to the stripe its index hashes to (Knuth's multiplicative hash: neighbouring pixels
// land in unrelated stripes, so every stripe gets a fair share of the sample). One pool counter
// taken by every crossing of a view serialised a GPU's threads on one address: on an H100 the
// overlap pass ran 10x slower than the sum pass (measured, BENCHMARKS.md); a counter per stripe
// spreads the atomics as the sum pass's accumulators are spread.
layout(std430, binding = BINDING_HEADS) buffer Heads { uint heads[]; };                 // per pixel, 0xFFFFFFFF = empty
layout(std430, binding = BINDING_NODES) writeonly buffer Nodes { uvec4 nodes[]; };      // t bits, object*2 + exit, next, -
layout(std430, binding = BINDING_STRIPES) buffer Stripes { uint stripe_used[]; };       // nodes taken in each stripe
uniform uint u_stripe_capacity;

void record_crossing(ivec2 px, Triangle tri, int side, float t) {
    uint object = tri.object;
    uint pixel = uint(px.y) * uint(u_size.x) + uint(px.x);
    uint stripe = (pixel * 2654435761u) >> (32 - NODE_STRIPE_BITS);
    uint k = atomicAdd(stripe_used[stripe], 1u);
    if (k < u_stripe_capacity) {
        uint slot = stripe * u_stripe_capacity + k;
        uint next = atomicExchange(heads[pixel], slot);
        nodes[slot] = uvec4(floatBitsToUint(t), 2u * object + uint(side > 0), next, 0u);
    }
}
#else
#include "fixed_point.glsl"
layout(std430, binding = BINDING_ACCUMULATORS) buffer Accumulators { uint acc[]; };            // (channel, row, col)
uniform bool u_containers;  // some object's container channel is in the object table (column z)

void record_crossing(ivec2 px, Triangle tri, int side, float t) {
    uint units = fixed_units(t);
    uint value = (side > 0) != tri.negative ? units : 0u - units;  // exits add t, entries subtract it
    uint pixel = uint(px.y) * uint(u_size.x) + uint(px.x);
    uint npix = uint(u_size.x) * uint(u_size.y);
    atomicAdd(acc[tri.channel * npix + pixel], value);
    if (u_containers) {
        uint container = object_info(tri.object).z;  // container channel + 1, 0: none
        if (container != 0u) atomicAdd(acc[(container - 1u) * npix + pixel], 0u - value);
    }
}
#endif
