"""Woven-composite geometry: unit cells, yarn paths and their meshes (needs no OpenGL)."""
