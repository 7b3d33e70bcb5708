#version 430 core
// Between crossing passes 1 and 1b: the work groups of 64 that pass 1b needs for the candidates
// (entries) pass 1 listed, as a 2-D indirect dispatch (one dimension holds at most u_max_groups).
#include "candidates.glsl"

layout(local_size_x = 1) in;

uniform uint u_max_groups;

void main() {
    uint groups = (min(candidate_count, u_candidate_capacity) + 63u) / 64u;
    uint wide = min(groups, u_max_groups);
    candidate_groups[0] = wide;
    candidate_groups[1] = wide == 0u ? 0u : (groups + wide - 1u) / wide;
    candidate_groups[2] = 1u;
}
