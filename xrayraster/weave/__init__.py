"""Woven-composite geometry: unit cells, yarn paths and their meshes (needs no OpenGL)."""

from .materials import FibreBundle, Tracer, YarnMaterials
from .distort import Distortion
from .sample import Sample
from .spec import Section, UnitCell
from .textomos import TextomosImport, read_textomos

__all__ = [
    "Distortion", "FibreBundle", "Sample", "Section", "TextomosImport", "Tracer", "UnitCell", "YarnMaterials",
    "read_textomos",
]
