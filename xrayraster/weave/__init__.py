"""Woven-composite geometry: unit cells, yarn paths and their meshes (needs no OpenGL)."""

from .sample import Sample
from .spec import Section, UnitCell
from .textomos import TextomosImport, read_textomos

__all__ = ["Sample", "Section", "TextomosImport", "UnitCell", "read_textomos"]
