"""The preview while the angle is dragged: frames a second, input-to-paint latency, and the time from
the last input to the full frame, in a real browser.

    python -m scripts.bench_preview            # 512², the small twin at 229 k triangles (~20 s)
    python -m scripts.bench_preview --quick    # 128², the small twin's mesh (~15 s)

The scene is the reference twin's small sample (``examples/twin_small.toml``: 2 × 2 woven cells,
three materials, 40 kV, photon noise on) on a 512 × 512 detector of 0.135 mm pixels, meshed at a
tolerance of 0.04 voxel: about 200 k triangles. ``xrayraster preview`` serves it
(:class:`xrayraster.preview.server.Background`, every core), and Debian's Chromium, headless and
driven by Selenium, loads the page (and after the drag asks for the quick slice and takes the
screenshot docs/preview.png shows; --quick: out/preview.png). The drag is the angle slider's ``input`` events at 60 a second
(a hand on a 60 Hz display) for ``--seconds``, each 0.5° on from the last; the page sends the newest
state whenever the frame before has come back (xrayraster/preview/static/preview.js): while the
input moves, a reduced frame (the detector binned to at most 256² pixels), and the full frame once
it has been still for 80 ms. Frames a second are the frames painted during the drag over its
length; the latency of a frame runs from the first input event it answers to the end of its paint
(``performance.now()`` in the page); *to the full frame* runs from the last input event to the end
of the paint of the full frame at its angle. The server's stages are from the frames' headers.

Error: the frame on screen after the drag against ``xr.Renderer`` at the same angle (the
radiograph without noise, for a comparison free of random numbers), as the largest absolute
difference: at most half a level of the 16-bit frame encoding.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

import xrayraster as xr
from references.browser import headless_chromium
from xrayraster.pipeline import load_scan_file
from xrayraster.preview.encoding import LEVELS
from xrayraster.preview.frames import MOVING_PIXELS, turned
from xrayraster.preview.server import Background

from .common import OUT, ROOT, announce, conclude, outputs, parser, say

SIZES = {"full": (512, 0.134867, 0.04), "quick": (128, 0.539467, 0.25)}  # pixels, pitch mm, mesh tolerance (voxels)

DRAG = """
const [seconds, done] = [arguments[0], arguments[arguments.length - 1]];
const slider = document.getElementById('angle'), p = xrPreview;
const painted = p.painted, reduced = p.paintedReduced, latencies = p.latencies.length, start = performance.now();
let angle = parseFloat(slider.value);
const timer = setInterval(() => {
  angle = (angle + 0.5) % 360;
  slider.value = angle;
  slider.dispatchEvent(new Event('input'));
  const last = performance.now();
  if (last - start > 1000 * seconds) {
    clearInterval(timer);
    const frames = p.painted - painted, reducedFrames = p.paintedReduced - reduced;
    const dragLatencies = p.latencies.slice(latencies);
    const settle = setInterval(() => {  // the full frame of the last input
      const h = p.frame && p.frame.header;
      if (h && Math.abs(h.angle_deg - angle) < 1e-6 && h.binning === 1) {
        clearInterval(settle);
        done({frames, reduced: reducedFrames, seconds: (last - start) / 1000, latencies: dragLatencies, angle,
              full_ms: p.paintedAt - last, reduced_shape: p.reduced && p.reduced.header.shape,
              reduced_seconds: p.reduced && p.reduced.header.seconds,
              label: document.getElementById('resolution').textContent});
      }
    }, 5);
  }
}, 1000 / 60);
"""


NOISE = """
const [on, done] = arguments, box = document.getElementById('noise'), painted = xrPreview.painted;
box.checked = on;
box.dispatchEvent(new Event('change'));
const t = setInterval(() => { if (xrPreview.painted > painted) { clearInterval(t); done(); } }, 20);
"""


SLICE = """
const done = arguments[0];
document.getElementById('slice').click();
const t = setInterval(() => { if (xrPreview.slice) { clearInterval(t); done(); } }, 50);
"""


def scan_file(size: str) -> Path:
    pixels, pitch, tolerance = SIZES[size]
    text = (ROOT / "examples" / "twin_small.toml").read_text()
    text = text.replace("detector_shape = [32, 128]", f"detector_shape = [{pixels}, {pixels}]")
    text = text.replace("pixel_size = 0.539467 ", f"pixel_size = {pitch} ")
    text = text.replace("mesh_tolerance_voxels = 0.25", f"mesh_tolerance_voxels = {tolerance}")
    path = OUT / "bench_preview" / f"twin_{pixels}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def error_at(path: Path, angle_deg: float, header: dict, levels: list) -> float:
    """Largest |frame on screen − the renderer's noise-free line integrals| at that angle."""
    loaded = load_scan_file(path)
    scene = loaded.with_mount(loaded.sample_scene())
    with xr.Renderer(turned(loaded.geometry, angle_deg), overlap="resolve") as renderer:
        expected = renderer.project(scene, loaded.spectrum, 0, detector=loaded.detector).image
    shown = header["lo"] + np.array(levels, np.float64).reshape(header["shape"]) * ((header["hi"] - header["lo"]) / LEVELS)
    return float(np.abs(shown - expected).max())


def main() -> None:
    ap = parser(__doc__, "128², the small twin's mesh (~20 s)")
    ap.add_argument("--seconds", type=float, default=8.0, help="how long the drag lasts (default 8)")
    ap.add_argument("--no-reduce", action="store_true",
                    help="full frames while dragging too (as before reduced frames), to compare on this machine")
    args = ap.parse_args()
    args = outputs(args, "bench_preview_full_frames" if args.no_reduce else "bench_preview")
    t_start = time.perf_counter()
    command, machine = announce()
    path = scan_file("quick" if args.quick else "full")
    driver = headless_chromium()
    try:
        with Background(path, port=8791, moving_pixels=2**62 if args.no_reduce else MOVING_PIXELS) as server:
            driver.get(server.url)
            driver.set_script_timeout(600)
            driver.execute_async_script(
                "const done = arguments[0]; const t = setInterval(() => { if (xrPreview.painted) "
                "{ clearInterval(t); done(); } }, 50);")
            # Noise on for the drag, as a user tunes a noisy scan; off for the error check at the end.
            driver.execute_async_script(NOISE, True)
            drag = driver.execute_async_script(DRAG, args.seconds)
            driver.execute_async_script(SLICE)
            driver.set_window_size(1400, 1150)
            driver.save_screenshot(str((OUT if args.quick or args.no_reduce else ROOT / "docs") / "preview.png"))
            seconds = driver.execute_script("return xrPreview.frame.header.seconds;")
            seconds["page"] = driver.execute_script("return xrPreview.pageMs;") / 1000
            shape = driver.execute_script("return xrPreview.frame.header.shape;")
            driver.execute_async_script(NOISE, False)
            frame = driver.execute_script("const f = xrPreview.frame; return {header: f.header, levels: Array.from(f.levels)};")
    finally:
        driver.quit()
    loaded = load_scan_file(path)
    count = loaded.with_mount(loaded.sample_scene()).num_triangles
    error = error_at(path, frame["header"]["angle_deg"], frame["header"], frame["levels"])
    step = (frame["header"]["hi"] - frame["header"]["lo"]) / LEVELS
    fps = drag["frames"] / drag["seconds"]
    latencies = sorted(drag["latencies"])
    reduced = drag["reduced_shape"]
    of_them = f" ({drag['reduced']} of them reduced to {reduced[0]}×{reduced[1]} px)" if reduced else " (none reduced)"
    say(f"{shape[0]}×{shape[1]} px, {count} triangles, 3 materials, noise on: {drag['frames']} frames in "
        f"{drag['seconds']:.1f} s of dragging = {fps:.1f} frames/s{of_them}; input to paint median "
        f"{statistics.median(latencies):.0f} ms, 90th percentile {latencies[int(0.9 * (len(latencies) - 1))]:.0f} ms")
    say(f"the full frame painted {drag['full_ms']:.0f} ms after the last input (the page: {drag['label']!r})")
    if drag["reduced_seconds"]:
        say("server stages of the last reduced frame (ms): "
            + ", ".join(f"{k} {1000 * v:.0f}" for k, v in drag["reduced_seconds"].items()))
    say("server stages of the last full frame (ms): " + ", ".join(f"{k} {1000 * v:.0f}" for k, v in seconds.items()))
    say(f"error: max |frame − renderer| {error:.2e} (half a level: {step / 2:.2e}) at {frame['header']['angle_deg']:.2f}°")
    payload = {"command": command, "reduce": not args.no_reduce, "machine": machine, "detector": shape, "triangles": count,
               "frames": drag["frames"], "reduced_frames": drag["reduced"], "reduced_shape": reduced,
               "seconds": drag["seconds"], "fps": fps, "latencies_ms": latencies, "full_ms": drag["full_ms"],
               "server_seconds": seconds, "reduced_server_seconds": drag["reduced_seconds"], "error": error,
               "half_level": step / 2}
    conclude(args.json, payload, machine, t_start)


if __name__ == "__main__":
    main()
