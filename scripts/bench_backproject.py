"""FDK backprojection alone: this checkout's kernels against a baseline commit's, alternating.

Cases (cone beam, full circle, the 3-D Shepp–Logan head projected exactly, cached in
out/bench_fdk_cache/):

* ``256``: scripts/bench_fdk.py's 256³ from 360 views of 256² (source 100 mm from the axis,
  detector 200 mm, field of view 25.6 mm, detector pixel 1.25× the magnified voxel);
* ``512``: its 512³ case from 64 views of 512² (a tenth of bench_fdk's 720: the same rate, a
  tenth of the time);
* ``twin``: examples/twin.toml's geometry (512³ voxels of 57.8 µm from views of 512², source 60 mm
  from the axis, detector 140 mm, voxel = magnified pixel), 64 views fed in batches of 32 as
  ``xrayraster scan`` feeds them;
* ``twin32`` and ``twin128`` (not run by default): the twin's geometry with 128 views in passes of
  32 (as ``xrayraster scan`` backprojected them until 2026-11-28) and of 128 (as it now does at
  512²: each pass reads and writes the whole volume).

Each run is a fresh process that imports xrayraster (and its kernels) either from this checkout or
from the baseline's files (``git archive BASE xrayraster shaders references`` into a temporary
folder: no worktree, nothing in this checkout changes), filters every view (untimed) and times the
backprojection alone: ``FDKStream._backproject`` over every batch and slab, best of ``--passes``.
Runs alternate baseline, ours, baseline, ours… ``--rounds`` times, each after waiting (up to
10 minutes) for the other processes' CPU use to fall under 10 %. Voxel updates per second =
voxels × views / seconds. Cycles per update = cores × clock / that rate, for two clocks: the one
/proc/cpuinfo reports and the one a chain of dependent additions runs at (measured with the C
compiler, where there is one: a virtual machine's /proc/cpuinfo shows the nominal clock, not the
boost the cores run at). The two codes' volumes are compared (largest difference over the range), and both against the
float64 reference (references/fdk.py) on 12³-voxel blocks around the four largest differences
(``--no-reference`` skips it): where they differ, which one is right.

Usage::

    python -m scripts.bench_backproject                  # 256, 512 and twin, 3 rounds (~6 min on 2 cores)
    python -m scripts.bench_backproject --cases 256 --rounds 1
    python -m scripts.bench_backproject --cases twin32 twin128 --rounds 2 --no-reference
    python -m scripts.bench_backproject --base edb156a   # the baseline commit (default)

Writes out/bench_backproject.json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# name -> (voxels a side, views, views per batch (None: the stream's own), geometry)
CASES = {"256": (256, 360, None, "bench_fdk"), "512": (512, 64, None, "bench_fdk"), "twin": (512, 64, 32, "twin"),
         "twin32": (512, 128, 32, "twin"), "twin128": (512, 128, 128, "twin")}
DEFAULT_CASES = ("256", "512", "twin")
MU = 0.05  # mm⁻¹, the phantom's skull

_CLOCK_C = r"""
#include <stdio.h>
#include <time.h>
int main(void) {
    struct timespec a, b;
    long x = 0, n = 1000000000L;
    clock_gettime(CLOCK_MONOTONIC, &a);
    for (long i = 0; i < n; i += 8)
        __asm__ volatile("add $1, %0\n add $1, %0\n add $1, %0\n add $1, %0\n"
                         "add $1, %0\n add $1, %0\n add $1, %0\n add $1, %0" : "+r"(x));
    clock_gettime(CLOCK_MONOTONIC, &b);
    printf("%f\n", n / ((b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec)) / 1e6);
    return (int)(x & 1);
}
"""


def cpuinfo_mhz() -> float:
    try:
        lines = [line for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("cpu MHz")]
        return max(float(line.split(":")[1]) for line in lines)
    except (OSError, ValueError):
        return float("nan")


def measured_mhz() -> float | None:
    """The clock one core runs a chain of dependent integer additions at (one a cycle), best of 3;
    None without a C compiler or off x86-64."""
    with tempfile.TemporaryDirectory() as tmp:
        source, binary = Path(tmp) / "clock.c", Path(tmp) / "clock"
        source.write_text(_CLOCK_C)
        try:
            subprocess.run(["cc", "-O1", "-o", str(binary), str(source)], check=True, capture_output=True)
            return max(float(subprocess.run([str(binary)], check=True, capture_output=True, text=True).stdout)
                       for _ in range(3))
        except (OSError, subprocess.CalledProcessError, ValueError):
            return None


def busy_share(seconds: float = 1.0) -> float:
    """Share of all cores busy over ``seconds`` (/proc/stat)."""
    def sample():
        values = list(map(int, Path("/proc/stat").read_text().splitlines()[0].split()[1:]))
        return sum(values), values[3] + values[4]

    total, idle = sample()
    time.sleep(seconds)
    total2, idle2 = sample()
    return 1 - (idle2 - idle) / max(1, total2 - total)


def wait_until_quiet(limit: float, timeout_s: float = 600) -> float:
    start = time.perf_counter()
    while (share := busy_share()) > limit and time.perf_counter() - start < timeout_s:
        pass
    return share


def case_geometry(name: str):
    import xrayraster as xr

    n, views, _, kind = CASES[name]
    if kind == "twin":  # examples/twin.toml
        return (xr.ConeBeamGeometry(60.0, 140.0, (n, n), 0.134867, xr.full_circle(views)),
                xr.VolumeGeometry((n, n, n), 0.0578), 14.0)
    voxel = 25.6 / n
    return (xr.ConeBeamGeometry(100.0, 200.0, (n, n), 1.25 * voxel * 2.0, xr.full_circle(views)),
            xr.VolumeGeometry((n, n, n), voxel), 12.0)


def projections_cache(name: str) -> Path:
    """The file of case ``name``'s projected phantom (the twin's cases share theirs by view count)."""
    _, views, _, kind = CASES[name]
    return ROOT / "out" / "bench_fdk_cache" / f"shepp_logan_{'twin' if kind == 'twin' else name}_{views}views.npy"


def worker(name: str, passes: int, save: Path | None) -> dict:
    """One process: the xrayraster first on sys.path backprojects case ``name`` ``passes`` times."""
    import numpy as np

    import xrayraster as xr
    import xrayraster.recon.opencl as opencl
    from references.phantoms import project, shepp_logan_3d

    # The kernels of the tree this process imported (an editable install maps xrayraster.shaders
    # to the checkout's shaders/, whichever xrayraster is imported).
    shaders = Path(xr.__file__).resolve().parents[1] / "shaders"
    opencl.read_shader = lambda source: (shaders / source).read_text()
    g, vol, radius = case_geometry(name)
    n, views, batch, _ = CASES[name]
    cache = projections_cache(name)
    if cache.exists():
        p = np.load(cache)
    else:
        head = shepp_logan_3d(radius, MU)
        p = np.stack([project(head, g[v])[0] for v in range(views)]).astype(np.float32)
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.save(cache, p)
    ctx = xr.CLContext()
    stream = xr.FDKStream(g, vol, context=ctx, **({"batch_views": batch} if batch else {}))
    batches = [range(s, min(s + stream.batch_views, views)) for s in range(0, views, stream.batch_views)]
    filtered = [stream._filter(b, p[b.start : b.stop]) for b in batches]
    slabs = stream._slabs if stream.plan.streamed else [stream._slab_buffer(z0) for z0 in stream._slab_starts()]
    starts = list(stream._slab_starts())

    def one_pass() -> float:
        ctx.queue.finish()
        t0 = time.perf_counter()
        for b, f in zip(batches, filtered):
            for z0, slab in zip(starts, slabs):
                stream._backproject(b, f, slab, z0)
        ctx.queue.finish()
        return time.perf_counter() - t0

    first = one_pass()  # the kernels are built by now: this one warms caches and pages
    if save is not None:
        import pyopencl as cl

        out = np.empty(vol.shape, np.float32)
        for z0, slab in zip(starts, slabs):
            cl.enqueue_copy(ctx.queue, out[z0 : z0 + min(stream.plan.slab, n - z0)], slab)
        ctx.queue.finish()
        np.save(save, out)
    times = [one_pass() for _ in range(passes)]
    return {"case": name, "size": n, "views": views, "batch_views": stream.batch_views, "updates": n**3 * views,
            "first_s": first, "times_s": times, "best_s": min(times), "device": str(ctx.info),
            "tree": str(shaders.parent), "kernel": stream._bp_kernel.function_name}


def against_reference(name: str, volumes: dict, blocks: int = 4, half: int = 6) -> dict:
    """Each volume's largest error against references/fdk.py (float64), over the volume's range, on
    ``blocks`` blocks of (2·half)³ voxels centred on the largest differences between the volumes."""
    import numpy as np

    import xrayraster as xr
    from references.fdk import fdk_reference

    g, vol, _ = case_geometry(name)
    n = vol.shape[0]
    p = np.load(projections_cache(name))
    first, second = volumes.values()
    span = float(np.ptp(first))
    diff = np.abs(second - first)
    worst = dict.fromkeys(volumes, 0.0)
    centres = []
    for flat in np.argsort(diff, axis=None)[::-1]:
        centre = np.array(np.unravel_index(flat, diff.shape))
        if any(np.all(np.abs(centre - c) < 2 * half) for c in centres):
            continue
        centres.append(centre)
        low = np.clip(centre - half, 0, n - 2 * half)
        offset = (low + (2 * half - 1) / 2 - (n - 1) / 2) * np.array(vol.voxel_size)
        block = xr.VolumeGeometry((2 * half,) * 3, vol.voxel_size, offset=tuple(offset.tolist()))
        want = fdk_reference(p, g, block)  # mm⁻¹, as the slabs the workers saved
        part = tuple(slice(a, a + 2 * half) for a in low)
        for key, data in volumes.items():
            worst[key] = max(worst[key], float(np.abs(data[part] - want).max() / span))
        if len(centres) == blocks:
            break
    return worst


def _baseline_tree(base: str, folder: Path) -> Path:
    """The baseline's xrayraster, shaders and references (git archive: no worktree, no checkout)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", base, "xrayraster", "shaders", "references"],
                             check=True, capture_output=True).stdout
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def _run(tree: Path, name: str, passes: int, save: Path) -> dict:
    code = ("import json, sys; sys.path[:0] = [sys.argv[1], sys.argv[2]]; import bench_backproject as b; "
            "print(json.dumps(b.worker(sys.argv[3], int(sys.argv[4]), b.Path(sys.argv[5]))))")
    done = subprocess.run([sys.executable, "-c", code, str(tree), str(ROOT / "scripts"), name, str(passes), str(save)],
                          env={**os.environ, "PYTHONPATH": str(tree)}, cwd=tree, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"the {name} run in {tree} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=list(DEFAULT_CASES))
    ap.add_argument("--rounds", type=int, default=3, help="baseline/ours alternations per case")
    ap.add_argument("--passes", type=int, default=2, help="timed backprojections per run (the best counts)")
    ap.add_argument("--base", default="edb156a", help="the baseline commit")
    ap.add_argument("--quiet", type=float, default=0.1,
                    help="wait (up to 10 min) before each run until other processes use less than this share of the CPU")
    ap.add_argument("--no-reference", action="store_true", help="skip the float64 reference on the blocks that differ most")
    ap.add_argument("--json", type=Path, default=ROOT / "out" / "bench_backproject.json")
    args = ap.parse_args(argv)
    import numpy as np

    cores = os.cpu_count() or 1
    clocks = {"cpuinfo": cpuinfo_mhz(), "measured": measured_mhz()}
    print(f"{cores} cores; clock {clocks['cpuinfo']:.0f} MHz (/proc/cpuinfo), "
          + (f"{clocks['measured']:.0f} MHz measured (dependent additions)" if clocks["measured"] else "not measured")
          + f"; baseline {args.base}; load {os.getloadavg()[0]:.2f}", flush=True)
    records, summary = [], []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trees = {"base": _baseline_tree(args.base, tmp / "base"), "ours": ROOT}
        for name in args.cases:
            for r in range(args.rounds):
                for code in ("base", "ours"):
                    share = wait_until_quiet(args.quiet)
                    load = os.getloadavg()[0]
                    rec = _run(trees[code], name, args.passes, tmp / f"{code}_{name}.npy")
                    rate = rec["updates"] / rec["best_s"]
                    cycles = {k: cores * mhz * 1e6 / rate for k, mhz in clocks.items() if mhz}
                    rec.update(code=code, round=r, busy_before=share, load_before=load, load_after=os.getloadavg()[0],
                               rate=rate, cycles_per_update=cycles)
                    records.append(rec)
                    print(f"{name:>4} ({rec['size']}³ × {rec['views']} views, batches of {rec['batch_views']}) {code:4} "
                          f"round {r}: {rec['best_s']:.3f} s, {rate / 1e9:.2f} G updates/s, cycles an update "
                          + ", ".join(f"{v:.2f} ({k})" for k, v in cycles.items())
                          + f"; CPU busy {share:.0%} before, load {load:.2f} → {rec['load_after']:.2f}; {rec['kernel']}",
                          flush=True)
            old, new = np.load(tmp / f"base_{name}.npy"), np.load(tmp / f"ours_{name}.npy")
            diff = float(np.abs(new - old).max() / np.ptp(old))
            rates = {code: [x["rate"] for x in records if x["case"] == name and x["code"] == code] for code in trees}
            line = {"case": name, "max_diff_over_range": diff, "base_rates": rates["base"], "our_rates": rates["ours"],
                    "worst_ratio": min(rates["ours"]) / max(rates["base"]),
                    "ratio_of_medians": float(np.median(rates["ours"]) / np.median(rates["base"]))}
            summary.append(line)
            print(f"{name}: max |ours − base| = {diff:.2e} of the volume's range; ours / base: "
                  f"{line['ratio_of_medians']:.2f}× (medians), {line['worst_ratio']:.2f}× (our worst over base's best)",
                  flush=True)
            if not args.no_reference:
                line["against_reference"] = against_reference(name, {"base": old, "ours": new})
                print(f"{name}: against the float64 reference on the 4 blocks that differ most, largest error over "
                      "the volume's range: " + ", ".join(f"{k} {v:.2e}" for k, v in line["against_reference"].items()),
                      flush=True)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"cores": cores, "clock_mhz": clocks, "base": args.base, "command": sys.argv,
                                     "summary": summary, "records": records}, indent=1))
    print(f"results {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
