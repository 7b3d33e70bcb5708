"""xrayraster: X-ray CT simulation from triangle meshes (see README.md; the layers are in docs/architecture.md).

The public API is what this module exports; the stage subpackages below it may reorganise.

Units: lengths in mm everywhere (geometry, meshes, path lengths, voxel sizes). Attenuation is
mm⁻¹ inside, where it meets path lengths in mm (:meth:`Material.attenuation_per_mm`, also
``Material.attenuation``; a line integral ∫μ dl is then dimensionless), and cm⁻¹ in
reconstructed volumes, as CT tools report it (``Volume.data`` with ``Volume.unit == "1/cm"``;
1 mm⁻¹ = 10 cm⁻¹). Mass attenuation μ/ρ is cm²/g and density g/cm³, as the tables give them.
"""

import importlib
import types

from . import ml, preview, weave  # subpackages (ml: lazy names; preview and weave callable: _CallableModule below)
from .core.lazy import lazy_names

__version__ = "0.1.0"

# Where each public name lives; imported on first use (core/lazy.py), so `import xrayraster` and
# the command line start in milliseconds. The stage subpackages below may reorganise.
_HOMES = {
    ".core.errors": (
        "CompareError", "ConfigError", "GLContextError", "GeometryError", "MaterialError", "MeshError", "OpenCLError",
        "PhysicsError", "ReconstructionError", "RenderError", "SceneError", "SpectrumError", "VoxelizeError",
        "StarvationError", "StarvationWarning", "WeaveError", "XrayrasterError", "XrayrasterWarning",
    ),
    ".core.geometry": ("ConeBeamGeometry", "ParallelBeamGeometry", "VectorGeometry", "full_circle"),
    ".core.pictures": ("show",),
    ".core.projections": ("Projections",),
    ".core.transform": ("Transform",),
    ".core.volume": ("VolumeGeometry",),
    ".dataset.build": ("BuildReport", "build"),
    ".gl.context": ("GLContext",),
    ".gl.voxelize": ("LabelVolume", "voxelize"),
    ".physics.detector": ("Detector",),
    ".physics.radiograph": ("Radiograph",),
    ".physics.realism": ("Realism",),
    ".physics.spectrum": ("Spectrum",),
    ".pipeline": ("Comparison", "FitResult", "ScanResult", "WeaveResult", "compare", "fit", "scan"),
    ".recon.fdk": ("FDKStream", "Volume", "fdk"),
    ".recon.opencl": ("CLContext",),
    ".scene.materials": ("Material",),
    ".scene.mesh": ("Mesh", "load_mesh"),
    ".scene.scene": ("Scene", "SceneObject"),
    ".simulate.renderer": ("Renderer",),
}
__getattr__, __dir__ = lazy_names(globals(), _HOMES)
__all__ = ["ml", "preview", "weave"]  # the subpackages, then the names above
__all__ += sorted(name for names in _HOMES.values() for name in names)


class _CallableModule(types.ModuleType):
    """A subpackage that is also its one-call function: ``xr.weave(path)`` makes a sample as
    ``xrayraster weave`` does (beside ``xr.weave.UnitCell``, ``xr.weave.Sample``: docs/weave.md),
    ``xr.preview(path)`` shows a file's live preview in a notebook (docs/preview.md).

    A module cannot be called, so its class is made this subclass. It is done here: a lower layer
    may not import the layers above it that run the call, and this module runs before the
    subpackage whichever is imported first (``import xrayraster.weave`` imports its parent first),
    so ``xr.weave`` and ``xr.preview`` are always callable. The function is imported on the call.
    """

    def __call__(self, *args, **options):
        module, name = _CALLS[self.__name__]
        return getattr(importlib.import_module(module), name)(*args, **options)


_CALLS = {  # the callable subpackage → (module, function) its call runs
    "xrayraster.weave": ("xrayraster.pipeline.woven", "weave"),  # a weave file (path or table) → xr.WeaveResult
    "xrayraster.preview": ("xrayraster.preview.notebook", "preview"),  # a file → the page inline
}
weave.__class__ = preview.__class__ = _CallableModule
