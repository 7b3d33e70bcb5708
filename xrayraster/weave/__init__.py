"""Woven-composite geometry: unit cells, yarn paths and their meshes (needs no OpenGL)."""

from .distort import Distortion
from .materials import FibreBundle, Tracer, YarnMaterials
from .resolve import Interpenetration, Resolved, interpenetration, resolve_boolean
from .sample import Sample
from .spec import Section, UnitCell
from .textomos import TextomosImport, read_textomos

__all__ = [
    "Distortion", "FibreBundle", "Interpenetration", "Resolved", "Sample", "Section", "TextomosImport", "Tracer",
    "UnitCell", "YarnMaterials", "interpenetration", "read_textomos", "resolve_boolean",
]
