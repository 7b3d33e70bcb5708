"""Every error xrayraster raises on purpose, under one base class.

A caller (the command line, a dataset builder, a web preview) catches :class:`XrayrasterError`
to tell a bad request, whose message names the field, file or object and the fix, from a bug.
Each stage raises its own subclass. Value errors also derive from ``ValueError`` and the
missing-driver errors from ``RuntimeError``, as they did before this base class existed.
"""

from __future__ import annotations


class XrayrasterError(Exception):
    """A request xrayraster cannot meet; the message says what is wrong and the fix."""


class GeometryError(XrayrasterError, ValueError):
    """A geometry field is invalid; the message names the field and the fix."""


class ConfigError(XrayrasterError, ValueError):
    """A scene, scan or metadata file (or dict) is invalid; the message names the file, the field and the fix."""


class MeshError(XrayrasterError, ValueError):
    """A mesh cannot be used: not closed, not finite, unreadable; the message names the object."""


class SceneError(XrayrasterError, ValueError):
    """A scene is empty or its objects cannot be placed; the message names the object."""


class MaterialError(XrayrasterError, ValueError):
    """A material's composition or density is invalid, or has no cross sections."""


class SpectrumError(XrayrasterError, ValueError):
    """A source spectrum cannot be made or read; the message names the field or file line."""


class PhysicsError(XrayrasterError, ValueError):
    """A physics request cannot be met; the message names the field and the fix."""


class StarvationError(PhysicsError):
    """Over half the pixels the sample covers detected no photon: the scan would be noise (physics/starvation.py)."""


class RenderError(XrayrasterError, ValueError):
    """A render request cannot be met; the message names the problem and the fix."""


class VoxelizeError(XrayrasterError, ValueError):
    """A voxelization request cannot be met; the message says the fix."""


class ReconstructionError(XrayrasterError, ValueError):
    """Projections, geometry and volume do not make a reconstruction; the message says the fix."""


class WeaveError(XrayrasterError, ValueError):
    """A woven unit cell or sample cannot be made; the message names the field and the fix."""


class CompareError(XrayrasterError, ValueError):
    """Two volumes (or a mask) cannot be compared, or a metric's library is missing; the message says the fix."""


class GLContextError(XrayrasterError, RuntimeError):
    """No usable OpenGL context; the message says what to install."""


class OpenCLError(XrayrasterError, RuntimeError):
    """No usable OpenCL device; the message says what to install or choose."""


class XrayrasterWarning(UserWarning):
    """A result xrayraster made but whose quality is in doubt; the message says why and the fix.
    The command line prints each as one line on stderr."""


class StarvationWarning(XrayrasterWarning):
    """Over 1 % of the pixels the sample covers detected no photon (physics/starvation.py)."""
