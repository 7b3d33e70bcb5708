#version 430 core
// Stencil voxelization, counting pass: only the stencil is written (colour writes are masked).
void main() {}
