"""Radiographs: the GL path lengths of a view composed with the physics (spectrum, materials,
detector, noise). GL knows nothing of photons and the physics nothing of GL; this is where they meet."""

from __future__ import annotations

import numpy as np

from ..core.errors import RenderError
from ..gl.pathlengths import PathLengthRenderer
from ..physics.beer_lambert import pixel_photon_factor, thread_count
from ..physics.detector import Detector
from ..physics.radiograph import Radiograph, radiograph
from ..scene.scene import Scene


class Renderer(PathLengthRenderer):
    """Path lengths (:class:`~xrayraster.gl.pathlengths.PathLengthRenderer`, whose options it
    takes) and radiographs for a scan geometry. ``threads``: how many threads the spectral sum of
    :meth:`project` uses (default every core); a process pool or Dask worker running several
    renderers at once gives each its share, so they do not oversubscribe the cores.
    """

    def __init__(self, geometry, *, threads: int | None = None, **options):
        self.threads = thread_count(threads)  # checked before a GL context is made
        super().__init__(geometry, **options)

    def project(self, scene: Scene, spectrum, view: int = 0, *, detector: Detector | None = None,
                output: str = "lineint", noise: bool = False, seed: int | None = None) -> Radiograph:
        """The radiograph of one view (:class:`~xrayraster.physics.radiograph.Radiograph`).

        Scene materials must be :class:`~xrayraster.Material` objects. ``output``: ``"raw"``
        (detector signal), ``"transmission"`` or ``"lineint"`` (−ln of it). With ``noise``,
        quantum and electronic noise are drawn from a generator seeded by ``(seed, view)``:
        the same seed gives the same bytes, and every view its own independent stream.
        """
        if noise and seed is None:
            raise RenderError("noise=True needs a seed (an int), so the noise is reproducible")
        lengths = self.path_lengths(scene, view)
        view %= self.vector_geometry.num_views
        rng = np.random.default_rng([int(seed), view]) if noise else None
        factor = pixel_photon_factor(self.vector_geometry, view)
        return radiograph(lengths, scene.materials, spectrum, detector or Detector(), factor, output=output,
                          noise=noise, rng=rng, threads=self.threads)
