"""xrayraster: X-ray CT simulation from triangle meshes (see README.md; the layers are in docs/architecture.md).

The public API is what this module exports; the stage subpackages below it may reorganise.

Units: lengths in mm everywhere (geometry, meshes, path lengths, voxel sizes). Attenuation is
mm⁻¹ inside, where it meets path lengths in mm (:meth:`Material.attenuation_per_mm`, also
``Material.attenuation``; a line integral ∫μ dl is then dimensionless), and cm⁻¹ in
reconstructed volumes, as CT tools report it (``Volume.data`` with ``Volume.unit == "1/cm"``;
1 mm⁻¹ = 10 cm⁻¹). Mass attenuation μ/ρ is cm²/g and density g/cm³, as the tables give them.
"""

# xr.weave.UnitCell, xr.weave.Sample: woven samples (needs no OpenGL)
from . import weave
from .core.errors import (
    CompareError,
    ConfigError,
    GeometryError,
    GLContextError,
    MaterialError,
    MeshError,
    OpenCLError,
    PhysicsError,
    ReconstructionError,
    RenderError,
    SceneError,
    SpectrumError,
    StarvationError,
    StarvationWarning,
    VoxelizeError,
    WeaveError,
    XrayrasterError,
    XrayrasterWarning,
)
from .core.geometry import (
    ConeBeamGeometry,
    ParallelBeamGeometry,
    VectorGeometry,
    full_circle,
)
from .core.projections import Projections
from .core.transform import Transform
from .core.volume import VolumeGeometry
from .gl.context import GLContext
from .gl.voxelize import LabelVolume, voxelize
from .physics.detector import Detector
from .physics.radiograph import Radiograph
from .physics.realism import Realism
from .physics.spectrum import Spectrum
from .pipeline import Comparison, ScanResult, compare, scan
from .recon.fdk import FDKStream, Volume, fdk
from .recon.opencl import CLContext
from .scene.materials import Material
from .scene.mesh import Mesh, load_mesh
from .scene.scene import Scene, SceneObject
from .simulate.renderer import Renderer

__version__ = "0.1.0"

__all__ = [
    "CLContext",
    "CompareError",
    "Comparison",
    "ConeBeamGeometry",
    "ConfigError",
    "Detector",
    "FDKStream",
    "GLContext",
    "GLContextError",
    "GeometryError",
    "LabelVolume",
    "Material",
    "MaterialError",
    "Mesh",
    "MeshError",
    "OpenCLError",
    "ParallelBeamGeometry",
    "PhysicsError",
    "Projections",
    "Radiograph",
    "Realism",
    "ReconstructionError",
    "RenderError",
    "Renderer",
    "ScanResult",
    "Scene",
    "SceneError",
    "SceneObject",
    "Spectrum",
    "SpectrumError",
    "StarvationError",
    "StarvationWarning",
    "Transform",
    "VectorGeometry",
    "Volume",
    "VoxelizeError",
    "VolumeGeometry",
    "WeaveError",
    "XrayrasterError",
    "XrayrasterWarning",
    "compare",
    "fdk",
    "full_circle",
    "load_mesh",
    "scan",
    "voxelize",
    "weave",
]
