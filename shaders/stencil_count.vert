#version 430 core
// Stencil voxelization, counting pass (xrayraster/label_stencil.py): triangles seen along +z,
// window pixel (i, j) centred on voxel column (i, j), clipped to the half-space above the
// slice plane. Front faces (outward normal up: the upward ray from the voxel centre exits
// there) increment the stencil, back faces decrement it: a non-zero count is inside.

in vec3 in_position;         // mm, relative to u_ref
uniform vec2 u_first_centre; // (x, y) of voxel column (0, 0), relative to u_ref
uniform vec2 u_voxel;        // (x, y) voxel size, mm
uniform vec2 u_columns;      // (nx, ny)
uniform float u_slice_z;     // the slice's voxel-centre z, relative to u_ref

out float gl_ClipDistance[1];

void main() {
    vec2 window = (in_position.xy - u_first_centre) / u_voxel + 0.5;
    gl_Position = vec4(2.0 * window / u_columns - 1.0, 0.0, 1.0);
    gl_ClipDistance[0] = in_position.z - u_slice_z;
}
