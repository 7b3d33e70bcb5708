"""Dataset builds (docs/dataset.md): dataset files and their deterministic draws of scan files
(``dataset_file``, ``distributions``), the plan of a build (``plan``), the build on a process pool
or Dask (``build``: ``xr.build``), and the builds' on-disk layouts (``layouts``: one module each,
``tiff_layout``, ``nnunet_layout``, ``hdf5_layout``, and ``layout_shared``; with ``manifest``,
``nifti`` and the shared ``names``; docs/dataset_layouts.md).

The layer between ``pipeline``, whose scans a build runs, and ``xr.ml``, which reads builds. The
names below are imported on first use (core/lazy.py), so a reader of builds imports ``layouts``
without loading the renderer that ``build`` needs. The function ``build`` is ``xr.build``: here
``build`` is its module.
"""

from ..core.lazy import lazy_names

_HOMES = {
    ".build": ("BuildReport",),
    ".dataset_file": ("DatasetFile", "Draw", "differences", "draw", "fingerprint", "load_dataset_file"),
    ".plan": ("format_plan", "plan_rows"),
}
__getattr__, __dir__ = lazy_names(globals(), _HOMES)
__all__ = sorted(name for names in _HOMES.values() for name in names)
