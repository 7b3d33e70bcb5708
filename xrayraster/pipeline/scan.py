"""``xr.scan``: a scan file's sample → every projection → FDK → labels on the same grid.

The stages run in one process. The projections are rendered in batches that go straight into
the reconstruction (:class:`~xrayraster.FDKStream`), so they are never all in memory: the peak is
the volume plus a batch of views. The result carries the volume (cm⁻¹), the labels and the
metadata that ``scan.json`` stores; :meth:`ScanResult.save` writes them (docs/scan.md).
"""

from __future__ import annotations

import importlib.metadata
import json
import resource
import time
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import ConfigError
from ..core.estimate import plan
from ..core.extra_labels import EXTRA_LABEL_NAMES, write_extra_labels
from ..core.files import atomic_directory, atomic_write_text, check_output_directory
from ..core.pictures import write_slices
from ..core.projections import Projections
from ..core.provenance import package_version
from ..core.tiff import quicklook_path
from ..gl.context import GLContext
from ..gl.pathlengths import interpenetrating_overlap
from ..gl.voxelize import LabelVolume, voxelize
from ..io.scan_file import ScanFile, load_scan_file
from ..physics.detector import Detector
from ..physics.starvation import refuse_if_starved, starved_share, warn_if_starved
from ..recon.fdk import FDKStream, Volume
from ..recon.fdk_weights import footprint_radius
from ..recon.opencl import CLContext
from ..scene.scene import Scene
from ..simulate.renderer import Renderer
from ..weave.centrelines import centreline_table
from ..weave.directions import direction_field
from ..weave.yarn import LABELS as WEAVE_LABELS
from ..weave.yarn import Yarn
from .plan import ScanJob, fdk_batch_views

__all__ = ["ScanResult", "check_scan_output", "scan"]

GENERATOR = "xrayraster scan"
VOLUME_NAME, LABELS_NAME, METADATA_NAME, SLICES_NAME = "volume.tif", "labels.tif", "scan.json", "slices.png"
PROJECTIONS_NAME = "projections.tif"
#: Spacing of the points of the centre lines a scan writes, in voxels of its grid.
CENTRELINE_STEP_VOXELS = 0.5
_LIBRARIES = ("numpy", "moderngl", "pyopencl", "manifold3d", "xraylib", "spekpy")
# Views rendered, checked for starved pixels and filtered per batch (32 MiB of line integrals at
# 512²); the FDK backprojects them in larger passes (plan.fdk_batch_views). docs/scan.md
BATCH_VIEWS = 32
STAGES = ("sample", "projections", "fdk", "labels")
# What the FDK chose, from its provenance: weights, and whether truncated rows were extrapolated.
RECONSTRUCTION_FACTS = ("method", "filter", "scan", "displaced", "truncation", "truncation_width",
                        "truncation_corrected_row_ends")
# Per-view lists of Renderer.project_all's provenance, joined across batches.
_PER_VIEW = ("views", "bins_used", "dropped_signal_share", "starved_pixels", "covered_pixels", "starved_covered_pixels",
             "spr_centre", "spr_covered")


@dataclass(frozen=True)
class ScanResult:
    """``volume`` (:class:`~xrayraster.Volume`, cm⁻¹), ``labels`` (:class:`~xrayraster.LabelVolume`) on
    the same grid, and ``metadata``: every parameter, the seed, library versions, device names,
    per-stage wall times (s) and the peak resident memory (MiB), as ``scan.json`` stores them;
    ``instances``, one id per yarn on the same grid where the scan file asks (``metadata["instances"]``
    names each id's yarn), and ``directions``, each yarn voxel's yarn direction, ``(3, z, y, x)``
    float16 (x, y, z) components (:func:`~xrayraster.weave.directions.direction_field`), and
    ``centrelines``, the yarns' centre lines (:func:`~xrayraster.weave.centrelines.centreline_table`)."""

    volume: Volume
    labels: LabelVolume
    metadata: dict
    projections: Projections | None = None  # kept only when asked (scan(..., keep_projections=True))
    instances: LabelVolume | None = None
    directions: np.ndarray | None = None
    centrelines: dict | None = None

    def save(self, directory, *, overwrite: bool = False) -> Path:
        """Write ``volume.tif`` (float32, cm⁻¹), ``labels.tif``, ``scan.json`` and ``slices.png`` into
        ``directory``, and ``projections.tif`` (line integrals, with their quick-look) when the result
        holds them; ``scan.json`` records the names written. The directory is built beside
        ``directory`` and moved into place whole (:func:`~xrayraster.core.files.atomic_directory`):
        an existing ``directory`` is replaced only if it holds nothing but an earlier scan's files,
        else :class:`~xrayraster.ConfigError`; ``overwrite=True`` then replaces the earlier scan's
        files and keeps every other entry. A link is followed. Returns ``directory``."""
        with atomic_directory(directory, marker=METADATA_NAME, generator=GENERATOR, overwrite=overwrite,
                              names=output_names(self.projections is not None, self.extra_labels)) as tmp:
            self.volume.save(tmp / VOLUME_NAME, quicklook=False)
            if self.projections is not None:
                self.projections.save(tmp / PROJECTIONS_NAME)
            self.labels.save(tmp / LABELS_NAME, quicklook=False)
            write_extra_labels(tmp, instances=self.instances, directions=self.directions, centrelines=self.centrelines)
            write_slices(tmp / SLICES_NAME, self.volume.data, self.labels.data, names=self.metadata.get("labels"),
                         grid=self.volume.geometry)
            atomic_write_text(tmp / METADATA_NAME, json.dumps(self.metadata, indent=2) + "\n")
        return Path(directory)

    @property
    def extra_labels(self) -> tuple[str, ...]:
        """The extra labels the result holds (of :data:`EXTRA_LABEL_NAMES`)."""
        return tuple(name for name in EXTRA_LABEL_NAMES if getattr(self, name) is not None)


def output_names(projections: bool, extra_labels=()) -> tuple[str, ...]:
    """The names a scan writes into its directory (with or without the projections, and the files of
    ``extra_labels``)."""
    kept = (PROJECTIONS_NAME, quicklook_path(Path(PROJECTIONS_NAME)).name) if projections else ()
    extra = tuple(EXTRA_LABEL_NAMES[name] for name in extra_labels)
    return (VOLUME_NAME, LABELS_NAME, METADATA_NAME, SLICES_NAME, *kept, *extra)


def check_scan_output(directory, *, overwrite: bool = False, projections: bool = False, extra_labels=()) -> Path:
    """Refuse, before any work, an output directory that :meth:`ScanResult.save` would refuse
    (``extra_labels``: those the scan file asks for, ``ScanOptions.labels[1:]``)."""
    return check_output_directory(directory, marker=METADATA_NAME, generator=GENERATOR, overwrite=overwrite,
                                  names=output_names(projections, extra_labels))


def scan(scan_file_or_path, *, progress=False, keep_projections: bool = False, allow_starved: bool = False,
         gl: GLContext | None = None, cl: CLContext | None = None, threads: int | None = None) -> ScanResult:
    """Run the scan of a :class:`~xrayraster.pipeline.ScanFile` (or a scan file's path, loaded and
    checked first): sample → ``Renderer.project_all`` (line integrals of the sample and its mount,
    noise and realism as the file says) in batches, each fed to ``xr.FDKStream`` on the file's grid
    → ``xr.voxelize`` of the sample on the same grid. ``progress``: a bar with ETA for the
    projections (True), a callable ``progress(done, total)``, or nothing (False).
    ``keep_projections``: return the projections too (otherwise each batch is freed once filtered).

    Photon starvation (:mod:`~xrayraster.physics.starvation`): after every batch, the share of the
    pixels the sample covers that detected no photon, over the views so far; over half is a
    :class:`~xrayraster.core.errors.StarvationError` at once (after the first batch when the
    exposure is that low) unless ``allow_starved``, and over 1 % at the end a ``StarvationWarning``.
    ``metadata["projections"]["starved_share"]`` records it.

    Before any work, a scan that cannot fit in memory is refused (ConfigError naming the key), and
    with ``progress=True`` the estimate of a long one is printed on stderr (:class:`.plan.ScanJob`).

    ``gl``, ``cl``: contexts to reuse (a dataset worker keeps its own across samples: made once,
    they save their set-up and compiled kernels; each scan makes and closes its own otherwise).
    ``threads``: the spectral sum's thread count (default every core; a worker of a pool its share)."""
    loaded = scan_file_or_path if isinstance(scan_file_or_path, ScanFile) else load_scan_file(scan_file_or_path)
    plan(ScanJob(loaded, BATCH_VIEWS), ConfigError, f"{loaded.path} ", announce=progress is True)
    options = loaded.options
    # Projections and FDK take turns (or, beside a GPU, overlap), so each is a sum and "total" the wall time.
    seconds = dict.fromkeys(STAGES, 0.0)
    started = time.perf_counter()
    with _timed(seconds, "sample"):
        scene = loaded.sample_scene(progress=progress is True)
    scanned = loaded.with_mount(scene)
    # A woven sample's yarns interpenetrate (docs/weave.md): one pass where its overlap terms pay,
    # else the sort without first searching the meshes for overlaps.
    overlap = interpenetrating_overlap(scanned, loaded.geometry) if loaded.weave is not None else "auto"
    with Renderer(loaded.geometry, overlap=overlap, context=gl, threads=threads) as renderer, \
            (nullcontext(cl) if cl is not None else CLContext()) as cl:
        with _timed(seconds, "fdk"):
            # Nothing outside the sample and its mount attenuates: the displaced-detector weights
            # weigh that reach (recon/fdk_weights.py), not the grid's.
            stream = FDKStream(loaded.geometry, loaded.volume, filter=options.filter, truncation=options.truncation,
                               truncation_width=options.truncation_width, context=cl,
                               batch_views=fdk_batch_views(loaded.geometry.detector_shape, BATCH_VIEWS),
                               threads=threads, object_radius_mm=footprint_radius(*scanned.bounds))
        with stream:
            provenances, stacks = _project_into(stream, renderer, scanned, loaded, seconds, progress,
                                                keep_projections, allow_starved)
            with _timed(seconds, "fdk"):
                volume = stream.result()
        with _timed(seconds, "labels"):
            labels, instances, yarns, directions, centrelines = _labels(loaded, scene, renderer.gl)
        devices = {"gl_renderer": renderer.gl.renderer, "opencl_device": str(cl.info)}
    provenance = _joined(provenances)
    starved = starved_share(provenance["starved_covered_pixels"], provenance["covered_pixels"])
    warn_if_starved(starved, str(loaded.path))
    projections = (Projections(np.concatenate(stacks), loaded.geometry, "lineint", "1", provenance)
                   if keep_projections else None)

    metadata = {
        "generator": GENERATOR,
        "xrayraster_version": package_version(),
        "scan_file": str(loaded.path),
        "geometry": loaded.geometry.to_dict(),
        "volume": loaded.volume.to_dict(),
        "source": loaded.spectrum.description,
        "detector": repr(loaded.detector or Detector()),
        "options": options.to_dict(),
        "seed": options.seed,
        "sample": loaded.weave_report or _objects_report(scene),
        "labels": label_names(scene, woven=loaded.weave is not None),
        **({"instances": yarns} if yarns is not None else {}),
        "mesh_resolution": loaded.mesh_resolution,
        "triangles": scene.num_triangles,
        "projections": {"batch_views": BATCH_VIEWS, "fdk_batch_views": stream.batch_views,
                        "bins_used": max(provenance["bins_used"]),
                        "dropped_signal_share": max(provenance["dropped_signal_share"]),
                        "starved_pixels": sum(provenance["starved_pixels"]),
                        "covered_pixels": sum(provenance["covered_pixels"]),
                        "starved_covered_pixels": sum(provenance["starved_covered_pixels"]),
                        "starved_share": starved,
                        "spectral_table": provenance.get("spectral_table"),
                        **_scatter_report(provenance)},
        "reconstruction": {key: volume.provenance[key] for key in RECONSTRUCTION_FACTS},
        "realism": loaded.realism.to_dict(),
        "pose": loaded.pose.to_dict(),
        "mount": [{"name": o.name, "material": repr(o.material)}
                  for o in (loaded.mount.objects if loaded.mount is not None else ())],
        "units": {"volume": volume.unit, "lengths": "mm", "seconds": "s", "peak_rss": "MiB"},
        "libraries": {name: _version(name) for name in _LIBRARIES},
        "devices": devices,
        "seconds": {**{k: round(v, 3) for k, v in seconds.items()}, "total": round(time.perf_counter() - started, 3)},
        # ru_maxrss is in KiB on Linux: the process's peak, which the scan's stages set.
        "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
    }
    return ScanResult(volume, labels, metadata, projections, instances, directions, centrelines)


def _labels(loaded: ScanFile, scene, gl):
    """(classes, instances, their yarns' table, directions, centre lines) of a scan: the class volume,
    and each of the others None unless the scan file asks for it (``[scan] labels``). Instances and
    directions come from the same label pass as the classes: every object labelled by its number,
    each voxel's class and yarn id then looked up (:func:`yarn_instances`), the same owners as a
    pass each (one scene, one set of priorities); it saved a third of the extras' time at 128³."""
    wanted = loaded.options.labels[1:]
    instances = yarns = directions = centrelines = None
    if "instances" in wanted or "directions" in wanted:
        owners, classes, ids, yarns, by_id = yarn_instances(scene, loaded.weave.sample)
        owner = voxelize(owners, loaded.volume, context=gl).data
        labels = LabelVolume(classes.astype(_label_dtype(classes.max()))[owner], loaded.volume)
        instances = LabelVolume(ids.astype(_label_dtype(ids.max()))[owner], loaded.volume)
        if "directions" in wanted:
            directions = direction_field(instances.data, loaded.volume, by_id, loaded.weave_placement())
        if "instances" not in wanted:
            instances = yarns = None
    else:
        labels = voxelize(scene, loaded.volume, context=gl)
    if "centrelines" in wanted:
        step = CENTRELINE_STEP_VOXELS * min(loaded.volume.voxel_size)
        centrelines = centreline_table(loaded.weave.sample, loaded.weave_placement(), step)
    return labels, instances, yarns, directions, centrelines


def _label_dtype(highest: int):
    """The label volume's type for labels up to ``highest``, as :func:`~xrayraster.gl.voxelize.voxelize` picks it."""
    return np.uint8 if highest < 256 else np.uint16


def yarn_instances(scene, sample) -> tuple[Scene, np.ndarray, np.ndarray, dict[str, dict], dict[int, Yarn]]:
    """The woven ``scene``'s objects, each labelled by its number (1, 2, … in the scene's order) with
    its priority: the scene whose label volume gives each voxel's owner. With it, by owner number,
    its class (the object's label) and its yarn id (1, 2, … over the yarns in the scene's order; 0
    for the matrix, voids and background), and each id's yarn, as ``scan.json``'s ``instances``
    lists it: name, family (weft or warp), kind (weft, binder or stuffer; a ply's warp), its index
    among the sample's yarns (:meth:`~xrayraster.weave.Sample.yarns`) and material; and each id's
    :class:`~xrayraster.weave.Yarn`."""
    yarns = {yarn.name: (index, yarn) for index, yarn in enumerate(sample.yarns())}
    owners, table, by_id = Scene(), {}, {}
    classes, ids = [0], [0]
    for number, obj in enumerate(scene.objects, 1):
        owners.add(obj.mesh, obj.material, label=number, priority=obj.priority, name=obj.name)
        classes.append(obj.label)
        ids.append(0)
        if obj.name in yarns:
            index, yarn = yarns[obj.name]
            ids[-1] = label = len(table) + 1
            table[str(label)] = {"name": obj.name, "family": yarn.family, "kind": yarn.kind, "index": index,
                                 "material": obj.material.name}
            by_id[label] = yarn
    return owners, np.array(classes), np.array(ids), table, by_id


def _project_into(stream: FDKStream, renderer: Renderer, scanned, loaded: ScanFile, seconds: dict, progress,
                  keep: bool, allow_starved: bool) -> tuple[list[dict], list[np.ndarray]]:
    """Render the views of ``scanned`` (the sample and its mount) batch by batch into ``stream``, timing the two
    stages apart; noisy views interpolate their spectral sums (``Renderer.project``). A batch that
    leaves the views so far starved over the refusal share stops the scan before its backprojection
    unless ``allow_starved``. Returns the batches' provenance and, if ``keep``, their line integrals
    (else they are dropped at once)."""
    total = loaded.geometry.num_views
    report, bar = _progress(progress, total)
    provenances, stacks = [], []
    starved = covered = 0  # over the views so far, pixels the sample covers

    def add(first: int, data: np.ndarray) -> None:
        with _timed(seconds, "fdk"):
            stream.add(first, data)

    # Beside a GL on a GPU (several physics workers), batch k's FDK (its filtering on the CPU, its
    # backprojection on the OpenCL device) runs on a thread while batch k + 1 renders; beside llvmpipe
    # it runs in turn on this thread, as llvmpipe needs the cores the FDK would take (and with a thread
    # a scan, a dataset worker's resident memory jumped by 55-70 MB now and then over 100 samples).
    overlapped = renderer.physics_workers > 1
    adding = None
    try:
        with ThreadPoolExecutor(1, thread_name_prefix="xrayraster-fdk") if overlapped else _InTurn() as fdk:
            for first in range(0, total, BATCH_VIEWS):
                views = list(range(first, min(first + BATCH_VIEWS, total)))
                with _timed(seconds, "projections"):
                    batch = renderer.project_all(scanned, loaded.spectrum, views, detector=loaded.detector,
                                                 noise=loaded.options.noise, seed=loaded.options.seed,
                                                 realism=loaded.realism, spectral_table=True,
                                                 progress=lambda done, _, first=first: report(first + done, total))
                provenances.append(batch.provenance)
                starved += sum(batch.provenance["starved_covered_pixels"])
                covered += sum(batch.provenance["covered_pixels"])
                if not allow_starved:
                    refuse_if_starved(starved_share([starved], [covered]), str(loaded.path), views[-1] + 1)
                if adding is not None:
                    adding.result()
                adding = fdk.submit(add, first, batch.data)
                if keep:
                    stacks.append(batch.data)
            adding.result()
    finally:
        if bar is not None:
            bar.close()
    return provenances, stacks


class _InTurn:
    """An executor that runs each call at once, on the caller's thread."""

    def submit(self, fn, *args) -> Future:
        future = Future()
        future.set_result(fn(*args))
        return future

    def __enter__(self) -> "_InTurn":
        return self

    def __exit__(self, *exc) -> None:
        return None


def _progress(progress, total: int):
    """(report(done, total), the tqdm bar or None) for ``progress``: True a bar with ETA on stderr,
    a callable itself, False nothing."""
    if progress is True:
        import sys

        from tqdm import tqdm

        bar = tqdm(total=total, desc="projections", unit="view", file=sys.stderr)
        return (lambda done, _: bar.update(done - bar.n)), bar
    if callable(progress):
        return progress, None
    return (lambda done, _: None), None


def _scatter_report(provenance: dict) -> dict:
    """With scatter, its scatter-to-primary ratios over the views: at the detector's centre (mean and
    largest) and over the pixels the sample covers (mean)."""
    if "spr_centre" not in provenance:
        return {}
    centre, covered = provenance["spr_centre"], provenance["spr_covered"]
    return {"scatter_to_primary": {"centre_mean": float(np.mean(centre)), "centre_max": float(np.max(centre)),
                                   "covered_mean": float(np.mean(covered))}}


def _joined(provenances: list[dict]) -> dict:
    """The batches' provenance as one stack's: per-view lists joined, the rest from the first."""
    return {**provenances[0], **{key: [value for p in provenances for value in p[key]] for key in _PER_VIEW
                                 if key in provenances[0]}}


@contextmanager
def _timed(seconds: dict, stage: str):
    start = time.perf_counter()
    yield
    seconds[stage] += time.perf_counter() - start


def _version(name: str) -> str | None:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


def label_names(scene, *, woven: bool) -> dict[str, str]:
    """Each label value of the label volume (as a string, JSON's key type) → its name: 0 "background" (as nnU-Net
    names it, and xr.ml and the dataset layouts; a mount is background too); a
    woven sample's families by name (1 matrix, 2 weft, 3 warp, 4 binder where binders are a class,
    whatever its yarns are called), every class below the highest one named even where no yarn
    has it (a cell whose warps are all binders: its class values stay consecutive, as nnU-Net wants),
    and a tracer with a label of its own by its yarn's name; an object by its name (several objects
    sharing a label: their names joined by "+")."""
    families = {label: family for family, label in WEAVE_LABELS.items()} if woven else {}
    names: dict[int, list[str]] = {}
    for o in scene.objects:
        name = families.get(o.label, o.name)
        if name not in names.setdefault(o.label, []):
            names[o.label].append(name)
    highest = max((label for label in names if label in families), default=0)
    for label in range(1, highest):
        names.setdefault(label, [families[label]])
    return {"0": "background", **{str(label): "+".join(names[label]) for label in sorted(names)}}


def _objects_report(scene) -> dict:
    return {"objects": [{"name": o.name, "label": o.label, "priority": o.priority, "material": repr(o.material)}
                        for o in scene.objects], "box_mm": scene.bounds.tolist()}
