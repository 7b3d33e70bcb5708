"""xrayraster: X-ray CT simulation from triangle meshes (see README.md and DESIGN.md)."""

from .geometry import ConeBeamGeometry, GeometryError, ParallelBeamGeometry, VectorGeometry, VolumeGeometry, full_circle
from .glcontext import GLContext, GLContextError
from .mesh import Mesh, MeshError, load_mesh
from .render import RenderError, Renderer
from .scene import Scene, SceneError, SceneObject
from .transform import Transform

__version__ = "0.1.0"

__all__ = [
    "ConeBeamGeometry",
    "GLContext",
    "GLContextError",
    "GeometryError",
    "Mesh",
    "MeshError",
    "ParallelBeamGeometry",
    "RenderError",
    "Renderer",
    "Scene",
    "SceneError",
    "SceneObject",
    "Transform",
    "VectorGeometry",
    "VolumeGeometry",
    "full_circle",
    "load_mesh",
]
