"""Woven-composite geometry: unit cells, yarn paths and their meshes (needs no OpenGL)."""

from .spec import Section, TextomosImport, UnitCell, read_textomos

__all__ = ["Section", "TextomosImport", "UnitCell", "read_textomos"]
