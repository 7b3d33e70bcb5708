"""FDK cone-beam reconstruction (and parallel-beam FBP by the same path) in OpenCL.

    vol = xr.fdk(line_integrals, geometry, xr.VolumeGeometry(shape=(256,) * 3, voxel_size=0.05))
    vol.data      # float32 (z, y, x), cm⁻¹ (the CT convention; docs/reconstruction.md)
    vol.geometry  # the VolumeGeometry: voxel (k, j, i) is where xr.voxelize puts label (k, j, i)

:func:`fdk` takes a whole stack; :class:`~xrayraster.recon.fdk_stream.FDKStream`, which it wraps,
takes the views in batches and holds the kernels and the memory plan.
"""

from __future__ import annotations

from ..core.choices import RECONSTRUCTION_INPUTS
from ..core.errors import ReconstructionError
from ..core.projections import Projections
from ..core.volume import VolumeGeometry
from .fdk_stream import FDKStream, check_shape
from .opencl import CLContext
from .truncation import DEFAULT_WIDTH
from .volume import Volume

__all__ = ["FDKStream", "ReconstructionError", "Volume", "fdk"]


def fdk(projections, geometry=None, volume: VolumeGeometry | None = None, *, filter: str = "ram-lak",
        cutoff: float = 1.0, scan: str = "auto", displaced="auto", object_radius_mm: float | None = None,
        truncation="auto",
        truncation_width: float = DEFAULT_WIDTH, input: str | None = None, context: CLContext | None = None,
        device: str | None = None, memory_limit: int | None = None) -> Volume:
    """Reconstruct ``volume`` from ``projections`` (views, rows, cols) taken with ``geometry``.

    * ``projections``: an array with its ``geometry``, or a
      :class:`~xrayraster.core.projections.Projections`, which carries its geometry and what it
      holds (``fdk(p, volume=grid)``; a ``geometry`` or ``input`` given as well must agree).
    * ``input``: ``"lineint"`` (the default for arrays: −ln of the transmission, dimensionless:
      ∫μ dl with μ in mm⁻¹) or ``"transmission"`` (I/I₀, logged here; every value must be > 0).
    * ``filter``: ``ram-lak``, ``shepp-logan``, ``cosine``, ``hamming`` or ``hann``; ``cutoff``
      as a fraction of the Nyquist frequency (:mod:`xrayraster.recon.ramp_filter`).
    * ``scan``: ``auto``, ``full`` or ``short`` (Parker weights), see :mod:`xrayraster.recon.fdk_weights`.
    * ``displaced``: full scans only: ``auto`` (chosen from the detector's coverage of the axis and
      the object's reach, and logged), ``True`` (Wang's displaced-detector weights) or ``False``
      (every line weighted ½). ``object_radius_mm``: the radius about the rotation axis outside which
      nothing attenuates (default: the grid's farthest corner), see :mod:`xrayraster.recon.fdk_weights`;
      given, it also bounds the truncation correction's extrapolation.
    * ``truncation``: rows cut off where the object still attenuates (an object wider than the
      field of view) are extrapolated past the detector's edges before filtering: ``auto`` (the
      row ends with signal at the edge), ``True`` (every row end) or ``False``: a fitted arc where
      the row visibly rounds off, else the row's mirror, out to how far an object of
      ``object_radius_mm`` reaches past the edge, or without it ``truncation_width`` × the
      detector width on each side (:mod:`xrayraster.recon.truncation`).
      The share of row ends corrected is in the result's provenance.
    * ``context``: a :class:`~xrayraster.recon.opencl.CLContext` to reuse (kernels stay compiled),
      else one is made on ``device`` (or ``XRAYRASTER_CL_DEVICE``, or the fastest device).
    * ``memory_limit``: bytes of device memory to plan with (default 80 % of the device's).

    Returns a :class:`Volume` in cm⁻¹. Views that arrive one batch at a time (a simulation that
    renders them) go through :class:`FDKStream` instead, which this wraps.
    """
    projections, geometry, input = _unpack(projections, geometry, input)
    check_shape(projections, geometry)
    with FDKStream(geometry, volume, filter=filter, cutoff=cutoff, scan=scan, displaced=displaced,
                   object_radius_mm=object_radius_mm, truncation=truncation, truncation_width=truncation_width,
                   context=context, device=device, memory_limit=memory_limit) as stream:
        stream.add(0, projections, input)
        out = stream.result()
    return Volume(out.data, volume, provenance={**out.provenance, "input": input})


def _unpack(projections, geometry, input):
    """(array, geometry, input) from an array and its geometry, or from a Projections."""
    if not isinstance(projections, Projections):
        if geometry is None:
            raise ReconstructionError("give the scan geometry of the projections (or pass an xr.Projections)")
        return projections, geometry, input or "lineint"
    if geometry is not None and geometry != projections.geometry:
        raise ReconstructionError("the geometry given differs from the one the Projections carry; pass one of them")
    if projections.quantity not in RECONSTRUCTION_INPUTS:
        raise ReconstructionError(f"these projections hold {projections.quantity!r}; reconstruct line integrals or "
                                  "transmissions (a radiograph rendered with output='lineint' or 'transmission')")
    if input is not None and input != projections.quantity:
        raise ReconstructionError(f"input={input!r} but the Projections hold {projections.quantity!r}; drop input")
    return projections.data, projections.geometry, projections.quantity
