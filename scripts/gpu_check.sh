#!/bin/bash
# The GPU figures of BENCHMARKS.md ("On a GPU") in one bounded run on a bare GPU machine (no network).
# On the development machine, in the repository root: bash scripts/gpu_stage.sh (stages the wheels and
# GL packages the machine lacks into the ignored .whl/ and .gl/). On the GPU machine, from the
# repository root with .whl/ and .gl/ beside it:
#   bash scripts/gpu_check.sh      (stops itself after LIMIT seconds; writes $OUT/gpu_log.txt, else /tmp/out)
# ONLY="probe tests" runs just the steps named; EXTRA="python3 my_check.py" runs a command of your own
# after the probe, in the same environment.
# Keep it in step with the benchmarks: tests/checkout/test_layout_rules.py checks that the paths it
# names exist.
O=${OUT:-/tmp/out}; mkdir -p "$O" /tmp/xr; LIMIT=${LIMIT:-480}
step() {
  local n=$1 t=$2 s=$SECONDS; shift 2; [[ -n $ONLY && " $ONLY " != *" $n "* ]] && return 0; (( t > LIMIT - SECONDS )) && t=$((LIMIT - SECONDS))
  (( t < 20 )) && { echo "### $n SKIPPED"; return 1; }
  echo "### $n"; timeout -k 5 "$t" "$@"; local rc=$?; echo "### $n rc=$rc $((SECONDS - s)) s"; return $rc
}
main() {
  for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
  python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site .whl/*.whl || echo PIP FAILED
  python3 -m zipfile -e .whl/spekpy_w.zip /tmp/site
  export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1 XRAYRASTER_GL=egl
  j=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  ls /usr/share/glvnd/egl_vendor.d/*nvidia* &>/dev/null || { [ -e $j ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$j; }
  ldd /usr/lib/x86_64-linux-gnu/libGL.so.1 | grep -q "not found" && export GLCONTEXT_LINUX_LIBGL=libOpenGL.so.0
  if ! ls /etc/OpenCL/vendors/*.icd &>/dev/null; then
    lib=$(ldconfig -p | awk '/libnvidia-opencl\.so\.1/{print $NF; exit}')
    [ -n "$lib" ] || lib=$(find /usr/local/nvidia /usr/lib /usr/lib64 /lib /usr/local/cuda* /opt -name 'libnvidia-opencl.so*' 2>/dev/null | head -1)
    # The H200's run found none in those: the driver's libraries may be mounted anywhere.
    [ -n "$lib" ] || lib=$(timeout 30 find / \( -path /proc -o -path /sys \) -prune -o -name 'libnvidia-opencl.so*' -print 2>/dev/null | head -1)
    echo "ICD: ${lib:-NONE}"; [ -n "$lib" ] && mkdir -p /tmp/ocl && echo "$lib" >/tmp/ocl/nvidia.icd && export OCL_ICD_VENDORS=/tmp/ocl
  fi
  nvidia-smi --query-gpu=name,driver_version --format=csv,noheader; free -g | head -2
  step probe 90 python3 -c 'import xrayraster as xr; from xrayraster.recon.opencl import list_devices, CLContext
i = xr.GLContext().ctx.info; print("GL:", i["GL_RENDERER"], "|", i["GL_VERSION"]); print(*list_devices(), sep="\n")
c = CLContext(); print("CL chosen:", c.info, c.device.version, c.device.driver_version)' ||
    OCL_ICD_DEBUG=7 python3 -c "import pyopencl as c; c.get_platforms()" 2>&1 | grep -E "vendors|Consider|Load" | head
  [ -n "$EXTRA" ] && step extra "$LIMIT" bash -c "$EXTRA"
  step info 60 python3 -m xrayraster info
  step one_pass 120 python3 -m scripts.bench_one_pass --json "$O/bench_one_pass.json" --plots-dir /tmp/xr
  # Issue 39's 256³ build (target 5000 samples an hour) with the host's cores shared by more workers
  # (a file, not stdin: the pool's spawned workers import the main module).
  cat > /tmp/xr/build256.py <<'EOF'
import time, xrayraster as xr; from scripts.bench_dataset import dataset_table
if __name__ == "__main__":
    for workers in (8, 16):
        t = time.perf_counter(); r = xr.build(dataset_table("256", 16), f"/tmp/xr/b256_{workers}", workers=workers)
        w = time.perf_counter() - t; print(f"256³ build, {workers} workers: {len(r.built) / w * 3600:.0f} samples/h ({w:.1f} s)")
EOF
  step twin 150 python3 -m xrayraster scan examples/twin.toml -o /tmp/xr/twin --quiet  # issue 39: 15 s or less
  cp /tmp/xr/twin/scan.json "$O/twin_scan.json" 2>/dev/null
  # Beside the CPU's twin: the labels whole (compressed) and the volume's middle slices.
  step twin_outputs 60 python3 -c 'import numpy as np, tifffile, sys; o = sys.argv[1]
l = tifffile.imread("/tmp/xr/twin/labels.tif"); v = tifffile.imread("/tmp/xr/twin/volume.tif")
np.savez_compressed(o + "/twin_labels.npz", labels=l); n = [s // 2 for s in v.shape]
np.savez(o + "/twin_slices.npz", z=v[n[0]], y=v[:, n[1]], x=v[:, :, n[2]])
print("twin class means", [float(v[l == k].mean()) for k in range(int(l.max()) + 1)])' "$O"
  step twin_profile 120 python3 -m scripts.profile_scan examples/twin.toml --json "$O/profile_twin.json"
  step build256 150 python3 /tmp/xr/build256.py
  step tests 220 env XRAYRASTER_REQUIRE_GL=1 XRAYRASTER_REQUIRE_OPENCL=1 python3 -m pytest -q -p no:cacheprovider \
    tests/gl/test_glcontext.py tests/recon/test_opencl.py tests/recon/test_fdk.py tests/gl/test_render_paths.py \
    tests/gl/test_render_overlap.py tests/gl/test_render_stress.py tests/physics/test_radiograph.py \
    tests/cli/test_golden.py tests/pipeline/test_scan.py tests/gl/test_voxelize.py \
    -k "not independent_inside_test and not two_boxes"
  # The compute passes 1/1b against every triangle rasterised (small_triangle_pixels 0), which on an
  # H200 lost crossings at 256² and 512² (BENCHMARKS.md): 1 sends only triangles under a pixel there.
  step compute_passes 90 python3 - <<'EOF'
import dataclasses, numpy as np; from xrayraster.gl.pathlengths import PathLengthRenderer; from xrayraster.pipeline import load_scan_file
l = load_scan_file("examples/twin_small.toml"); s = l.with_mount(l.sample_scene()); g = l.geometry
for px in (128, 256, 512):
    geo = dataclasses.replace(g, detector_shape=(px, px), pixel_size=g.pixel_size[1] * g.detector_shape[1] / px)
    out = {k: PathLengthRenderer(geo, overlap="sum", small_triangle_pixels=k).path_lengths(s, 0) for k in (0, 1, 64)}
    for k in (1, 64):
        d = np.abs(out[k] - out[0]).max(0); print(f"compute passes {px}² small={k}: max {d.max():.3g} mm, {int((d > 1e-3).sum())} pixels off")
EOF
  step render 150 python3 -m scripts.bench_render --sizes 512 --levels 60 --supersampling 1 --sweep-size 512 --no-gvxr \
    --json "$O/bench_render.json" --plots-dir /tmp/xr
  step physics 150 python3 -m scripts.bench_physics --skip-sweep --no-gvxr --json "$O/bench_physics.json" --plots-dir /tmp/xr
  step fdk 240 python3 -m scripts.bench_fdk --sizes 256 --no-cases --no-rtk --json "$O/bench_fdk.json" --plot /tmp/xr/f.png
  step scan 120 python3 -m xrayraster scan examples/twin_small.toml -o /tmp/xr/scan --quiet -v
  cp /tmp/xr/scan/scan.json "$O/" 2>/dev/null
  step preview 120 python3 - <<'EOF'
import statistics as st, time; from pathlib import Path
from xrayraster.preview.document import Document, View; from xrayraster.preview.frames import Previewer
t = Path("examples/twin_small.toml").read_text()
for a, b in (("[32, 128]", "[512, 512]"), ("0.539467 ", "0.134867 "), ("voxels = 0.25", "voxels = 0.04")): t = t.replace(a, b)
Path("/tmp/xr/p.toml").write_text(t); d, p = Document.open("/tmp/xr/p.toml"), Previewer(); p.frame(d, View(0.0, noise=True))
w = []
for k in range(40): t0 = time.perf_counter(); f = p.frame(d, View(0.5 * k + 0.5, noise=True)); w.append(time.perf_counter() - t0)
print(f"preview 512²: median {1e3 * st.median(w):.1f} ms a frame, max {1e3 * max(w):.1f}; last frame's stages", f.seconds)
EOF
  echo "=== summary"; grep -E "twin class means|^GL:|CL chosen|compute passes|256³ build|### twin rc|^bench:|passed|failed|  512  1 |^ *512 |^ *1024 |ours:|seconds:|frames?/s|a frame|a view:|rc=[1-9]" "$O/gpu_log.txt"
}
main 2>&1 | tee "$O/gpu_log.txt"
