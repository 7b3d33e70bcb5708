// Crossing pass 1's candidates for pass 1b: entries of a triangle and up to two pixels of its
// box (pairs halve pass 1's loop over the box, and pass 1b's lanes still do useful tests: a
// box of an odd number of pixels leaves one test of its last entry idle). The buffer starts with
// the entries pass 1 reserved (which may exceed the capacity: the host then grows the buffer and
// runs the view again) and the work groups of pass 1b's indirect dispatch (candidate_groups.comp).
// A pixel is packed as column | row << 16 (GL's size limits keep both far below 65536).
const uint NO_PIXEL = 0xFFFFFFFFu;

layout(std430, binding = BINDING_CANDIDATES) buffer Candidates {
    uint candidate_count;   // entries
    uint candidate_groups[3];
    uvec4 candidates[];     // triangle index, pixel, pixel or NO_PIXEL, -
};
uniform uint u_candidate_capacity;  // entries the buffer holds
