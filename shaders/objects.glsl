// The scene's per-object table, by rank (uploaded each view): channel, drawn in this view,
// container channel + 1 (0: none), label. A texture, not a storage buffer: llvmpipe reads texels
// several times faster than SSBO elements (measured: xrayraster/gl/bindings.py).
layout(binding = TEXTURE_OBJECTS) uniform usampler2D u_objects;

uvec4 object_info(uint rank) {
    return texelFetch(u_objects, ivec2(rank % uint(TEXTURE_WIDTH), rank / uint(TEXTURE_WIDTH)), 0);
}
