"""xrayraster: X-ray CT simulation from triangle meshes (see README.md and DESIGN.md)."""

from .detector import Detector
from .reconstruction import ReconstructionError, Volume, fdk
from .geometry import ConeBeamGeometry, GeometryError, ParallelBeamGeometry, VectorGeometry, VolumeGeometry, full_circle
from .glcontext import GLContext, GLContextError
from .materials import Material, MaterialError
from .mesh import Mesh, MeshError, load_mesh
from .opencl import CLContext, OpenCLError
from .physics import PhysicsError
from .radiograph import Radiograph
from .render import RenderError, Renderer
from .scene import Scene, SceneError, SceneObject
from .spectrum import Spectrum, SpectrumError
from .transform import Transform
from .label_volume import LabelVolume, VoxelizeError, voxelize

__version__ = "0.1.0"

__all__ = [
    "CLContext",
    "ConeBeamGeometry",
    "Detector",
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
    "Radiograph",
    "ReconstructionError",
    "RenderError",
    "Renderer",
    "Scene",
    "SceneError",
    "SceneObject",
    "Spectrum",
    "SpectrumError",
    "Transform",
    "VectorGeometry",
    "Volume",
    "VoxelizeError",
    "VolumeGeometry",
    "fdk",
    "full_circle",
    "load_mesh",
    "voxelize",
]
