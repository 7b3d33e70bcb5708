#version 430 core
// Stencil voxelization, label pass: where the stencil test passes (the object's count is not
// zero), the object's label; objects are drawn in rank order, so the highest priority wins.
uniform uint u_label;
out uint out_label;
void main() { out_label = u_label; }
