"""Whole jobs beside an earlier commit: the reference twin's scan, two dataset builds and the path
lengths a view of their woven scenes, timed with that commit's code and this checkout's in one run,
alternating, their outputs compared.

    python -m scripts.bench_commits edb156a                  # 3 rounds of the four jobs (~17 min on 2 cores)
    python -m scripts.bench_commits edb156a --jobs twin      # the twin alone
    python -m scripts.bench_commits edb156a --jobs views     # the path lengths a view (~1 min a round)
    python -m scripts.bench_commits edb156a --jobs views --overlap resolve   # both trees' sort
    python -m scripts.bench_commits edb156a --quick          # build128r, one round (~1 min)

The commit is checked out (``git worktree``) into ``out/bench_commits/<commit>``; this checkout is
the other side, with its uncommitted changes. Each job runs in a process of its own in each tree
(working directory and ``PYTHONPATH`` the tree's), the two trees alternating within each round, so
a machine that slows down during the run slows both. Jobs:

* **twin**: ``python -m xrayraster scan examples/twin.toml`` (801 views of 512² onto 512³ voxels),
  the command's wall time: start-up and writing included.
* **build256**: ``scripts/bench_dataset.py``'s 256³ build (360 views of 256², kV, exposure and weave
  seed drawn), 4 samples on 2 workers (``xr.build``): samples an hour over the build, and steadily
  (the samples after each worker's first).
* **build128r**: 8 samples at 128³ (180 views of 128²) that also draw a sub-micron focal spot
  (0.2-1 µm), a detector blur (0-0.35 px) and a tilt (±1.6° about each axis), on 2 workers.
* **views**: the path lengths a view (GL, ``PathLengthRenderer`` with each tree's own choice of
  method) of the woven scenes of those jobs: the builds' samples (twin_small meshed for their
  128³ and 256³ grids, at their 128² and 256² detectors) and the twin at 512², the best of three
  passes over 16 views spread over the scan, after a first view that plans, uploads and compiles
  (``--overlap``: a method forced in both trees instead).

Error: the largest difference between the two trees' volumes (cm⁻¹; sample by sample for the
builds) and whether every label volume is identical; for views, between their path lengths (mm).
Prints the table and writes ``out/bench_commits.json``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve()
# An editable install's finder maps ``xrayraster.shaders`` to this checkout whatever PYTHONPATH
# says: a tree's code would read this checkout's shaders (an older tree's then fails on newer
# ones). Every process of a job, the pool's workers too, first runs this sitecustomize from the
# front of PYTHONPATH, which takes the finder off; a tree's package then reads the tree's shaders/.
SITECUSTOMIZE = """# Written by scripts/bench_commits.py: a tree's own code and shaders, not the editable install's.
import sys
sys.meta_path[:] = [f for f in sys.meta_path if not getattr(f, "__module__", "").startswith("__editable__")]
"""
JOBS = ("twin", "build256", "build128r", "views")
DRAWS = {"source.kvp": {"uniform": [38.0, 42.0]}, "source.mas": {"loguniform": [1.1, 1.4]}}
BUILDS = {  # job: (samples, what is drawn beside kV and exposure)
    "build256": (4, {"geometry.num_views": 360, "geometry.detector_shape": [256, 256], "geometry.pixel_size": 0.2697335,
                     "volume.shape": [256] * 3, "volume.voxel_size": 0.1156}),
    "build128r": (8, {"geometry.num_views": 180, "geometry.detector_shape": [128, 128], "geometry.pixel_size": 0.539467,
                      "volume.shape": [128] * 3, "volume.voxel_size": 0.2312,
                      "source.focal_spot_mm": {"uniform": [0.0002, 0.001]},
                      "detector.blur_sigma_px": {"uniform": [0.0, 0.35]},
                      **{f"pose.tilt_deg.{k}": {"uniform": [-1.6, 1.6]} for k in range(3)}}),
}

# The views job's scenes: (scan file in examples/, its text replaced as the builds' draws set it).
VIEW_SCENES = {
    "128³ sample": ("twin_small.toml", {"[32, 128]": "[128, 128]", "[24, 128, 128]": "[128, 128, 128]"}),
    "256³ sample": ("twin_small.toml", {"[32, 128]": "[256, 256]", "0.539467 ": "0.2697335 ",
                                        "[24, 128, 128]": "[256, 256, 256]", "0.2312 ": "0.1156 "}),
    "twin": ("twin.toml", {}),
}


def views_in_this_process(out: Path, overlap: str = "auto") -> dict:
    """The path lengths a view of :data:`VIEW_SCENES` with the ``xrayraster`` this process imports
    (the tree's), by method ``overlap``: ms a view and the method per scene; the lengths saved in
    ``out`` for the comparison."""
    import numpy as np

    from xrayraster.gl.pathlengths import PathLengthRenderer
    from xrayraster.pipeline import load_scan_file

    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    figures = {}
    for number, (name, (base, edits)) in enumerate(VIEW_SCENES.items()):
        text = (HERE.parents[1] / "examples" / base).read_text()  # this checkout's, for both trees
        for old, new in edits.items():
            assert old in text, f"{base} no longer holds {old!r}"
            text = text.replace(old, new)
        (out / f"scene{number}.toml").write_text(text)
        loaded = load_scan_file(out / f"scene{number}.toml")
        scene = loaded.with_mount(loaded.sample_scene())
        views = np.linspace(0, loaded.geometry.num_views, 16, endpoint=False).astype(int)
        renderer = PathLengthRenderer(loaded.geometry, overlap=overlap)
        try:
            renderer.path_lengths(scene, 0)  # the plan (overlap search, terms), upload and compile
            best = np.inf
            for _ in range(3):
                start = time.perf_counter()
                lengths = np.stack([renderer.path_lengths(scene, int(v)) for v in views])
                best = min(best, (time.perf_counter() - start) / len(views))
            figures[name] = {"ms": 1e3 * best, "method": renderer.last_method}
        finally:
            renderer.release()
        np.save(out / f"scene{number}.npy", lengths)
    return {"wall_s": sum(f["ms"] for f in figures.values()) / 1e3, "scenes": figures}


def build_in_this_process(job: str, out: Path) -> dict:
    """One build with the ``xrayraster`` this process imports (the tree's): wall s and samples an hour."""
    import logging

    import xrayraster as xr

    try:
        from xrayraster.dataset import load_dataset_file
    except ImportError:  # commits before the dataset layer (issue 37)
        from xrayraster.pipeline.dataset_file import load_dataset_file

    count, vary = BUILDS[job]
    base = Path.cwd() / "examples" / "twin_small.toml"
    posed = out.parent / f"{out.name}_base.toml"  # tilts vary pose.tilt_deg's entries: the base names it
    posed.write_text(base.read_text() + "\n[pose]\noffset_mm = [0.0, 0.0, 0.0]\ntilt_deg = [0.0, 0.0, 0.0]\n")
    dataset = load_dataset_file({"base": str(posed), "dataset": {"count": count, "seed": 2026, "name": job},
                                 "vary": {**DRAWS, **vary}}, base_dir=Path.cwd())
    finished = []

    class Finishes(logging.Handler):
        def emit(self, record):
            if str(record.msg).startswith("sample %05d  seed"):
                finished.append(time.perf_counter())

    logger = logging.getLogger("xrayraster")
    logger.addHandler(Finishes())
    logger.setLevel(logging.INFO)
    shutil.rmtree(out, ignore_errors=True)
    start = time.perf_counter()
    report = xr.build(dataset, out, workers=2)
    wall = time.perf_counter() - start
    if report.failed:
        raise SystemExit(f"{job}: samples failed: {report.failed}")
    steady = 3600 * (len(finished) - 2) / (finished[-1] - finished[1]) if len(finished) > 2 else None
    return {"wall_s": wall, "per_hour": 3600 * count / wall, "steady_per_hour": steady}


def tree_env(tree: Path, boot: Path) -> dict:
    """The environment of a job run with ``tree``'s code and shaders (:data:`SITECUSTOMIZE`, written to ``boot``)."""
    boot.mkdir(parents=True, exist_ok=True)
    (boot / "sitecustomize.py").write_text(SITECUSTOMIZE)
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(boot), str(tree)])}


def run_job(job: str, tree: Path, out: Path, overlap: str = "auto") -> dict:
    """``job`` in a fresh process with ``tree``'s code; its figures (``overlap``: the views job's method)."""
    env = tree_env(tree, out.parent / "boot")
    if job == "twin":
        shutil.rmtree(out, ignore_errors=True)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "xrayraster", "scan", "examples/twin.toml", "-o", str(out), "--quiet"],
                       cwd=tree, env=env, check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        return {"wall_s": wall, "stages_s": json.loads((out / "scan.json").read_text())["seconds"]}
    done = subprocess.run([sys.executable, str(HERE), "--child", job, str(out), overlap], cwd=tree, env=env, check=True,
                          stdout=subprocess.PIPE, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def compare(job: str, a: Path, b: Path) -> dict:
    """Largest |Δμ| (cm⁻¹) between the volumes of ``a`` and ``b`` and whether all labels are equal;
    for views, the largest |Δ| (mm) between their path lengths."""
    import numpy as np
    import tifffile

    if job == "views":
        diff = max(float(np.abs(np.load(x) - np.load(b / x.name)).max()) for x in sorted(a.glob("*.npy")))
        return {"max_abs_diff_mm": diff}

    pairs = [(a, b)] if job == "twin" else [(a / "samples" / s.name, b / "samples" / s.name)
                                            for s in sorted((a / "samples").iterdir())]
    diff, same = 0.0, True
    for x, y in pairs:
        diff = max(diff, float(np.abs(tifffile.imread(x / "volume.tif") - tifffile.imread(y / "volume.tif")).max()))
        same &= bool(np.array_equal(tifffile.imread(x / "labels.tif"), tifffile.imread(y / "labels.tif")))
    return {"max_abs_diff_per_cm": diff, "labels_identical": same}


def main(argv=None) -> None:
    from .common import OUT, ROOT, announce, conclude, outputs, parser, say

    ap = parser(__doc__, "build128r only, one round (~1 min)")
    ap.add_argument("commit", help="the commit to run beside this checkout (e.g. edb156a)")
    ap.add_argument("--jobs", nargs="+", choices=JOBS, default=list(JOBS), help="jobs to run (default all)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds, each running every job in both trees (default 3)")
    ap.add_argument("--overlap", default="auto", choices=("auto", "resolve", "nested", "sum"),
                    help="the views job's method in both trees (default auto: each tree's own choice)")
    args = outputs(ap.parse_args(argv), "bench_commits")
    jobs, rounds = (["build128r"], 1) if args.quick else (args.jobs, args.rounds)
    t_start = time.perf_counter()
    command, machine = announce()
    work = OUT / "bench_commits"
    old = work / args.commit
    if not old.exists():
        work.mkdir(parents=True, exist_ok=True)
        subprocess.run(["git", "worktree", "add", "--detach", str(old), args.commit], cwd=ROOT, check=True)
    trees = {args.commit: old, "this checkout": ROOT}
    rows = []
    for number in range(1, rounds + 1):
        for job in jobs:
            runs = {name: run_job(job, tree, work / f"{job}_{k}", args.overlap)
                    for k, (name, tree) in enumerate(trees.items())}
            old_run, new_run = runs.values()
            row = {"round": number, "job": job, "runs": runs, **compare(job, work / f"{job}_0", work / f"{job}_1"),
                   "speedup": (old_run["wall_s"] / new_run["wall_s"])}
            rows.append(row)
            if job == "views":
                say(f"round {number} views (ms a view): " + "; ".join(
                    f"{name} {old_run['scenes'][name]['ms']:.2f} ({old_run['scenes'][name]['method']}) → "
                    f"{new['ms']:.2f} ({new['method']}), {old_run['scenes'][name]['ms'] / new['ms']:.2f}x"
                    for name, new in new_run["scenes"].items()) + f"; max |Δ| {row['max_abs_diff_mm']:.2g} mm")
                continue
            rate = "" if job == "twin" else (f"; {old_run['per_hour']:.0f} → {new_run['per_hour']:.0f} samples/h "
                                             f"(steady {old_run['steady_per_hour'] or 0:.0f} → "
                                             f"{new_run['steady_per_hour'] or 0:.0f})")
            say(f"round {number} {job}: {old_run['wall_s']:.1f} s → {new_run['wall_s']:.1f} s ({row['speedup']:.2f}x)"
                f"{rate}; max |Δμ| {row['max_abs_diff_per_cm']:.2g} cm⁻¹, labels identical: {row['labels_identical']}")
    conclude(args.json, {"command": command, "machine": machine, "commit": args.commit, "rows": rows}, machine, t_start)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        job, out, overlap = sys.argv[2], Path(sys.argv[3]), sys.argv[4]
        print(json.dumps(views_in_this_process(out, overlap) if job == "views" else build_in_this_process(job, out)))
    else:
        main()
