"""Woven-composite geometry: unit cells, yarn paths and their meshes (needs no OpenGL).

The names below are imported on first use (core/lazy.py): importing this package is cheap, so
``import xrayraster`` can make ``xr.weave`` callable without loading trimesh and manifold3d.
"""

from ..core.lazy import lazy_names

_HOMES = {
    ".distort": ("Distortion",),
    ".materials": ("FibreBundle", "Tracer", "YarnMaterials"),
    ".resolve": ("Interpenetration", "Resolved", "interpenetration", "resolve_boolean"),
    ".sample": ("Sample",),
    ".spec": ("Section", "UnitCell"),
    ".textomos": ("TextomosImport", "read_textomos"),
}
__getattr__, __dir__ = lazy_names(globals(), _HOMES)
__all__ = sorted(name for names in _HOMES.values() for name in names)
