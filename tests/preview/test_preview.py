"""The preview: documents edited and saved, frames against the renderer and the command line, the
frame encoding, the server's answers and refusals (Starlette's test client), and the page in a
real headless browser (Debian's Chromium, driven by Selenium): the image follows the angle slider
and a drag on the image, and is the renderer's view at that angle, window and level paint what they say, a bad value shows
its error and keeps the last good image, and the saved settings render with `xrayraster render`
to the frame on screen. While the input moves, frames are reduced (the binned detector's render,
labelled so on the page), the full frame follows when it stops, and superseded requests are dropped.

XRAYRASTER_PREVIEW_SCREENSHOT=PATH also saves the page as the browser test leaves it."""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("starlette", reason="the preview extra: pip install 'xrayraster[preview]'")

from starlette.testclient import TestClient  # noqa: E402
from starlette.websockets import WebSocketDisconnect  # noqa: E402

import xrayraster as xr  # noqa: E402
from xrayraster.cli import main  # noqa: E402
from xrayraster.core.errors import ConfigError  # noqa: E402
from xrayraster.gl.pathlengths import PathLengthRenderer  # noqa: E402
from xrayraster.io.scene_file import load_scene_file  # noqa: E402
from xrayraster.preview.document import Document, View  # noqa: E402
from xrayraster.preview.encoding import LEVELS, decode, encode  # noqa: E402
from xrayraster.preview.frames import MOVING_PIXELS, Frame, Previewer, binned, binning, turned  # noqa: E402
from xrayraster.preview.notebook import free_port  # noqa: E402
from xrayraster.preview.server import Background, make_app  # noqa: E402
from xrayraster.preview.session import Preview  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture
def scene_file(tmp_path) -> Path:
    """The bracket-and-ball example, its detector made small (64 × 80) so a frame takes milliseconds,
    copied away from its mesh (which Document.open must find through the absolute path it makes)."""
    text = (EXAMPLES / "bracket_and_ball.toml").read_text()
    text = text.replace("detector_shape = [256, 320]", "detector_shape = [64, 80]").replace(
        "pixel_size = 0.15 ", "pixel_size = 0.6  ").replace('mesh = "meshes/bracket.stl"',
                                                           f'mesh = "{EXAMPLES / "meshes" / "bracket.stl"}"')
    path = tmp_path / "scene.toml"
    path.write_text(text)
    return path


@pytest.fixture
def previewer(gl):
    p = Previewer(threads=1)
    yield p
    p.release()


def reference(path: Path, angle_deg: float, **options) -> np.ndarray:
    """View 0 of the file turned to ``angle_deg``, by a Renderer of its own (lineint unless told)."""
    loaded = load_scene_file(path)
    with xr.Renderer(turned(loaded.geometry, angle_deg), threads=1) as renderer:
        return renderer.project(loaded.scene, loaded.spectrum, 0, detector=loaded.detector, **options).image


def test_a_frame_is_the_renderers_view_at_that_angle(scene_file, previewer):
    document = Document.open(scene_file)
    for angle in (0.0, 33.5, 271.25):
        frame = previewer.frame(document, View(angle_deg=angle))
        assert frame.angle_deg == pytest.approx(angle)
        assert frame.unit == "1" and frame.quantity == "lineint"
        np.testing.assert_array_equal(frame.image, reference(scene_file, angle))
    noisy = previewer.frame(document, View(angle_deg=12.0, output="transmission", noise=True, seed=7))
    np.testing.assert_array_equal(noisy.image, reference(scene_file, 12.0, output="transmission", noise=True, seed=7))


def test_turning_keeps_the_uploaded_scene_and_a_new_tube_reads_no_mesh_again(scene_file, previewer):
    document = Document.open(scene_file)
    previewer.frame(document, View(angle_deg=0.0))
    renderer = previewer._renderer
    uploaded = renderer.engine._scene
    previewer.frame(document, View(angle_deg=90.0))
    assert previewer._renderer is renderer and renderer.engine._scene is uploaded  # no mesh upload
    scene = previewer.load(document).scene
    tube = document.edited({"source.kvp": 60.0, "geometry.source_to_origin": 150.0})
    previewer.frame(tube, View(angle_deg=90.0))
    assert previewer._renderer is renderer
    assert previewer.load(tube).scene is scene  # the scanner changed: no mesh read from the file again
    assert previewer.load(tube.edited({"objects.0.priority": 5.0})).scene is not scene


def test_path_length_frames_show_one_material(scene_file, previewer):
    document = Document.open(scene_file)
    frame = previewer.frame(document, View(angle_deg=10.0, output="path_length", material=1))
    loaded = load_scene_file(scene_file)
    with xr.Renderer(turned(loaded.geometry, 10.0)) as renderer:
        np.testing.assert_array_equal(frame.image, renderer.path_lengths(loaded.scene, 0)[1])
    assert frame.unit == "mm" and frame.quantity == "path length: steel"
    with pytest.raises(ConfigError, match="material 5 is not one of the scene's 2 materials"):
        previewer.frame(document, View(output="path_length", material=5))


def test_a_binned_detector_keeps_its_centre_extent_and_offsets():
    """A reduced frame's detector: ⌈n / b⌉ pixels a side over the same extent, the same for a
    circular geometry and its per-view vectors; the binning the smallest power of two that fits."""
    cone = xr.ConeBeamGeometry(100.0, 250.0, (64, 81), (0.6, 0.5), (0.3, 1.2), detector_offset=(1.5, -2.0),
                               source_offset=(0.25, 0.5))
    coarse = binned(cone, 2)
    assert coarse.detector_shape == (32, 41) and coarse.pixel_size == pytest.approx((1.2, 0.5 * 81 / 41), rel=1e-15)
    assert (coarse.detector_offset, coarse.source_offset) == (cone.detector_offset, cone.source_offset)
    np.testing.assert_allclose(binned(cone.to_vec(), 2).array, coarse.to_vec().array, rtol=0, atol=1e-12)
    for geometry in (cone, coarse):  # the same detector: centre and both ends of a row, in mm
        s, d, u, v = np.split(geometry.to_vec().array[1], 4)
        np.testing.assert_allclose([d, d + u * geometry.detector_shape[1] / 2, d + v * geometry.detector_shape[0] / 2],
                                   [d, d + np.array([np.cos(1.2), np.sin(1.2), 0]) * 0.5 * 81 / 2,
                                    d + np.array([0, 0, 0.6 * 32])], rtol=0, atol=1e-12)
    parallel = xr.ParallelBeamGeometry((10, 10), 1.0, (0.0,))
    assert binned(parallel, 4).detector_shape == (3, 3) and binned(parallel, 4).pixel_size == (10 / 3, 10 / 3)
    assert binned(cone, 1) is cone
    assert MOVING_PIXELS == 256 * 256 and binning((512, 512), MOVING_PIXELS) == 2
    assert binning((64, 80), MOVING_PIXELS) == 1 and binning((64, 80), 40 * 40) == 2 and binning((513, 512), 256**2) == 4
    assert binning((3, 5), 1) == 8  # at most one pixel left


def test_a_moving_frame_is_the_binned_detectors_render_and_the_full_one_follows(scene_file, gl):
    """While the input moves a frame is reduced: the view on the binned detector, exactly as a renderer
    of that geometry renders it (path lengths, and a noisy radiograph); each binning keeps its own
    renderer and uploaded scene, so going back to the full frame uploads nothing again."""
    document = Document.open(scene_file)
    loaded = load_scene_file(scene_file)
    previewer = Previewer(threads=1, moving_pixels=40 * 40)  # 64 × 80 binned 2 × 2: 32 × 40
    try:
        full = previewer.frame(document, View(angle_deg=10.0))
        assert full.binning == 1 and full.full_shape == (64, 80) and full.image.shape == (64, 80)
        uploaded = previewer._renderer.engine._scene
        for angle in (10.5, 11.0, 11.5):
            moving = previewer.frame(document, View(angle_deg=angle, output="path_length", material=1), moving=True)
            assert moving.binning == 2 and moving.full_shape == (64, 80) and moving.image.shape == (32, 40)
            assert moving.angle_deg == pytest.approx(angle)
            with PathLengthRenderer(binned(turned(loaded.geometry, angle), 2)) as renderer:
                np.testing.assert_array_equal(moving.image, renderer.path_lengths(loaded.scene, 0)[1])
        noisy = previewer.frame(document, View(angle_deg=12.0, noise=True, seed=3), moving=True)
        with xr.Renderer(binned(turned(loaded.geometry, 12.0), 2), threads=1) as renderer:
            expected = renderer.project(loaded.scene, loaded.spectrum, 0, detector=loaded.detector, noise=True, seed=3)
        np.testing.assert_array_equal(noisy.image, expected.image)
        same = previewer.frame(document, View(angle_deg=12.0)).layout  # the same detector, seen from above
        np.testing.assert_allclose(noisy.layout["detector"], same["detector"], rtol=1e-12)
        assert noisy.layout["fov_mm"] == pytest.approx(same["fov_mm"], rel=1e-12)
        final = previewer.frame(document, View(angle_deg=12.0))  # the input stopped: the full frame
        assert final.binning == 1 and previewer._renderer.engine._scene is uploaded  # no upload again
        np.testing.assert_array_equal(final.image, reference(scene_file, 12.0))
        assert set(previewer._renderers) == {1, 2}
        bigger = document.edited({"geometry.detector_shape": [128, 160], "geometry.pixel_size": 0.3})
        assert previewer.frame(bigger, View(angle_deg=12.0), moving=True).binning == 4
        assert set(previewer._renderers) == {1, 4}  # one reduced renderer at a time
    finally:
        previewer.release()
    small = Previewer(threads=1)  # 64 × 80 is within MOVING_PIXELS: moving frames are full ones
    try:
        frame = small.frame(document, View(angle_deg=3.0), moving=True)
        assert frame.binning == 1 and set(small._renderers) == {1}
        np.testing.assert_array_equal(frame.image, reference(scene_file, 3.0))
    finally:
        small.release()
    with pytest.raises(ConfigError, match="moving_pixels must be a positive integer, got 0"):
        Previewer(moving_pixels=0)


def test_edits_are_checked_by_the_files_own_loader(scene_file):
    document = Document.open(scene_file)
    with pytest.raises(ConfigError, match=r"\[source\]: kvp must be > 0, got -3"):
        document.edited({"source.kvp": -3}).load()
    with pytest.raises(ConfigError, match="'sourse.kvp': no key 'sourse'"):
        document.edited({"sourse.kvp": 40})
    with pytest.raises(ConfigError, match="source_to_detector .* must exceed source_to_origin"):
        document.edited({"geometry.source_to_origin": 400.0}).load()
    assert "focal_spot_mm" not in document.edited({"source.focal_spot_mm": 0.1}).edited(
        {"source.focal_spot_mm": None}).table["source"]
    assert document.table["source"]["kvp"] == 80  # edits never change the document they start from


@pytest.mark.parametrize("view, message", [
    ({"output": "sinogram"}, "output must be one of raw, transmission, lineint, path_length"),
    ({"angle_deg": "north"}, "angle_deg must be a number"),
    ({"seed": -1}, "seed must be an integer >= 0"),
    ({"zoom": 2}, r"view: unknown key\(s\) zoom; allowed: angle_deg, material, noise, output, seed"),
])
def test_bad_views_are_named(view, message):
    with pytest.raises(ConfigError, match=message):
        View.from_dict(view)


@pytest.mark.parametrize("edits", [
    {"geometry.num_views": None, "geometry.angles_deg": [10.0, 17.5, 100.0, -33.25, 10.0 + 1e-9]},
    {"geometry.start_angle_deg": 5.0, "geometry.arc_deg": 200.0},
])
def test_a_saved_file_and_a_frame_turn_the_views_alike(scene_file, tmp_path, edits):
    """The angles of a saved file's views (degrees in the file) are the frame's turned geometry's
    (radians), to float64 rounding; and both keep the file's spacing with the first at the asked angle."""
    import tomli_w

    document = Document.open(scene_file).edited(edits)
    own = np.array(document.load().geometry.angles)
    for angle in (47.5, -120.25, 0.0):
        table = document.saved(View(angle_deg=angle))
        if "geometry.angles_deg" in edits:
            degrees = table["geometry"]["angles_deg"]
            assert degrees[0] == angle  # exactly the asked angle, as the page shows it
            np.testing.assert_allclose(np.diff(degrees), np.diff(edits["geometry.angles_deg"]), rtol=0, atol=1e-12)
        else:
            assert table["geometry"]["start_angle_deg"] == angle
        path = tmp_path / "saved.toml"
        path.write_text(tomli_w.dumps(table))
        from_file = np.array(load_scene_file(path).geometry.angles)
        on_screen = np.array(turned(document.load().geometry, angle).angles)
        assert on_screen[0] == math.radians(angle) and from_file[0] == pytest.approx(math.radians(angle), rel=0, abs=1e-15)
        for angles in (from_file, on_screen):  # the spacing of the file's own views is kept
            np.testing.assert_allclose(np.diff(angles), np.diff(own), rtol=0, atol=1e-13)
        np.testing.assert_allclose(from_file, on_screen, rtol=0, atol=1e-13)


def test_a_weave_file_previews_as_the_scan_file_it_saves_as(tmp_path, previewer):
    from xrayraster.io.weave_file import DEFAULT_SOURCE
    from xrayraster.pipeline import load_scan_file
    import tomli_w

    shutil.copy(EXAMPLES / "weave.toml", tmp_path / "weave.toml")
    document = Document.open(tmp_path / "weave.toml")
    assert document.kind == "scan" and document.table["source"] == DEFAULT_SOURCE
    saved = tmp_path / "scan.toml"
    saved.write_text(tomli_w.dumps(document.saved(View(angle_deg=20.0))))
    loaded = load_scan_file(saved)  # a scan file `xrayraster scan` takes
    assert loaded.weave is not None and loaded.geometry.angles[0] == pytest.approx(np.radians(20.0))


def test_saved_settings_render_to_the_frame_on_screen(scene_file, previewer, tmp_path):
    """The TOML a user saves is a scene file `xrayraster render` takes unchanged, and its view 0 is the frame."""
    import tomli_w
    import tifffile

    document = Document.open(scene_file).edited({"source.kvp": 60.0, "geometry.source_to_origin": 90.0})
    view = View(angle_deg=47.5, output="transmission")
    frame = previewer.frame(document, view)
    saved = tmp_path / "elsewhere" / "settings.toml"
    saved.parent.mkdir()
    saved.write_text(tomli_w.dumps(document.saved(view)))
    out = tmp_path / "view.tif"
    assert main(["render", str(saved), "-o", str(out), "--output", "transmission"]) == 0
    np.testing.assert_array_equal(tifffile.imread(out), frame.image)


def test_the_encoding_is_within_half_a_level():
    rng = np.random.default_rng(3)
    image = rng.normal(2.0, 1.5, (33, 47)).astype(np.float32)
    image[0, 0] = np.nan  # a non-finite value is sent as the lowest level, never breaks the frame
    header, values = decode(encode(Frame(image, "lineint", "1", 12.5, {"physics": 0.01}), 9))
    finite = np.isfinite(image)
    step = (header["hi"] - header["lo"]) / LEVELS
    assert header["id"] == 9 and header["shape"] == [33, 47] and header["angle_deg"] == 12.5
    assert np.abs(values[finite] - image[finite]).max() <= step / 2 * (1 + 1e-9)
    flat = decode(encode(Frame(np.full((4, 5), 1.25, np.float32), "mm", "mm", None, {}), 1))[1]
    assert np.all(flat == 1.25)  # a constant frame (no range) decodes to itself


@contextmanager
def client(scene_file, **options):
    """A test client of the app serving ``scene_file``; its preview closed after (its render thread
    and renderer would otherwise outlive the test, to the interpreter's exit)."""
    preview = Preview(Document.open(scene_file), threads=1)
    app = make_app(preview, host="127.0.0.1", port=8000, **options)
    try:
        with TestClient(app, base_url="http://127.0.0.1:8000") as c:
            yield c
    finally:
        preview.close()


def test_the_server_answers_frames_and_errors_and_keeps_serving(scene_file, gl):
    with client(scene_file) as c, c.websocket_connect("ws://127.0.0.1:8000/frames") as ws:
        hello = ws.receive_json()
        assert hello["type"] == "hello" and hello["materials"] == ["aluminium", "steel"]
        assert {"source.kvp", "geometry.source_to_origin", "source.filters.Al"} <= {k["key"] for k in hello["controls"]}
        ws.send_text(json.dumps({"id": 1, "edits": {"source.kvp": -3}, "view": hello["view"]}))
        assert ws.receive_json() == {"id": 1, "error": f"{scene_file} [source]: kvp must be > 0, got -3"}
        ws.send_text("not json")
        assert ws.receive_json() == {"id": None, "error": "a request must be JSON: Expecting value: line 1 column 1 (char 0)"}
        ws.send_text(json.dumps({"id": 2, "edits": {}, "view": {**hello["view"], "angle_deg": 30.0}}))
        header, values = decode(ws.receive_bytes())
        assert header["id"] == 2 and header["angle_deg"] == pytest.approx(30.0)
        step = (header["hi"] - header["lo"]) / LEVELS
        assert np.abs(values - reference(scene_file, 30.0)).max() <= step / 2 * (1 + 1e-6) + 1e-7
        saved = c.post("/save/settings.toml", json={"edits": {"source.mas": 2.0}, "view": {"angle_deg": 30.0}})
        assert saved.status_code == 200 and "start_angle_deg = 30.0" in saved.text and "mas = 2.0" in saved.text
        bad = c.post("/save/settings.toml", json={"edits": {"source.mass": 2.0}, "view": {}})
        assert bad.status_code == 400 and "no key 'mass'" in bad.json()["error"]
        refused = c.post("/slice", json={"edits": {}, "view": {}})
        assert refused.status_code == 400 and "a slice needs a scan file" in refused.json()["error"]


def test_moving_requests_get_reduced_frames_and_superseded_requests_are_dropped(scene_file, gl):
    """``moving: true`` asks for a reduced frame (the header says its binning and the full shape);
    requests that arrive while a frame renders replace each other: the one after it is the newest,
    the ones between are dropped, never answered."""
    import threading

    preview = Preview(Document.open(scene_file), threads=1, moving_pixels=40 * 40)
    app = make_app(preview, host="127.0.0.1", port=8000)
    with TestClient(app, base_url="http://127.0.0.1:8000") as c, c.websocket_connect("ws://127.0.0.1:8000/frames") as ws:
        view = ws.receive_json()["view"]
        ws.send_text(json.dumps({"id": 1, "edits": {}, "view": {**view, "angle_deg": 20.0}, "moving": True}))
        header, values = decode(ws.receive_bytes())
        assert header["id"] == 1 and header["binning"] == 2 and header["shape"] == [32, 40]
        assert header["full_shape"] == [64, 80]
        loaded = load_scene_file(scene_file)
        with xr.Renderer(binned(turned(loaded.geometry, 20.0), 2), threads=1) as renderer:
            within_a_level(header, values, renderer.project(loaded.scene, loaded.spectrum, 0, detector=loaded.detector).image)
        ws.send_text(json.dumps({"id": 2, "edits": {}, "view": {**view, "angle_deg": 20.0}}))
        header, values = decode(ws.receive_bytes())
        assert header["id"] == 2 and header["binning"] == 1 and header["shape"] == header["full_shape"] == [64, 80]
        within_a_level(header, values, reference(scene_file, 20.0))
        ws.send_text(json.dumps({"id": 3, "edits": {}, "view": view, "moving": "yes"}))
        assert ws.receive_json() == {"id": 3, "error": "a request's moving must be true or false, got 'yes'"}

        # The render thread held busy: request 4 waits on it, 5 to 8 arrive meanwhile.
        hold, held = threading.Event(), threading.Event()
        blocker = preview._render.submit(lambda: (held.set(), hold.wait(TIMEOUT_S)))
        assert held.wait(TIMEOUT_S)
        ws.send_text(json.dumps({"id": 4, "edits": {}, "view": {**view, "angle_deg": 4.0}, "moving": True}))
        wait_for(lambda: preview._render._jobs.qsize() == 1, "request 4 on the render thread's queue")
        for i in range(5, 9):
            ws.send_text(json.dumps({"id": i, "edits": {}, "view": {**view, "angle_deg": float(i)}, "moving": True}))
        time.sleep(0.3)  # the server has read them all
        hold.set()
        blocker.result(TIMEOUT_S)
        answered = [decode(ws.receive_bytes())[0] for _ in range(2)]
        assert [(h["id"], h["angle_deg"]) for h in answered] == [(4, pytest.approx(4.0)), (8, pytest.approx(8.0))]
        ws.send_text(json.dumps({"id": 9, "edits": {}, "view": view}))
        assert decode(ws.receive_bytes())[0]["id"] == 9  # 5, 6 and 7 never answered: the next answer is 9's
    preview.close()


def test_a_page_gone_mid_frame_leaves_the_server_serving(scene_file, gl):
    with client(scene_file) as c:
        with c.websocket_connect("ws://127.0.0.1:8000/frames") as ws:
            view = ws.receive_json()["view"]
            ws.send_text(json.dumps({"id": 1, "edits": {}, "view": view}))
        with c.websocket_connect("ws://127.0.0.1:8000/frames") as ws:  # the next page
            view = ws.receive_json()["view"]
            ws.send_text(json.dumps({"id": 2, "edits": {}, "view": {**view, "angle_deg": 5.0}}))
            header, _ = decode(ws.receive_bytes())
            assert header["id"] == 2 and header["angle_deg"] == pytest.approx(5.0)


def test_beyond_loopback_it_warns_and_every_request_needs_the_token(scene_file):
    from xrayraster.core.errors import XrayrasterWarning
    from xrayraster.preview.server import _server

    with pytest.warns(XrayrasterWarning, match="beyond this machine's loopback"):
        server, preview, url = _server(scene_file, "0.0.0.0", 8000, 1)
    preview.close()
    # 0.0.0.0 is no address a browser can open: the machine's name is printed instead
    assert url.startswith(f"http://{socket.gethostname()}:8000/?token=") and len(url.split("=", 1)[1]) >= 20


def test_ctrl_c_stops_the_server_with_status_130(scene_file):
    import signal
    import subprocess
    import sys

    process = subprocess.Popen([sys.executable, "-m", "xrayraster", "preview", str(scene_file), "--port",
                                str(free_port())], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline()
        assert line.startswith(f"preview of {scene_file} at http://127.0.0.1:"), line
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=30) == 130
        assert "interrupted" in process.stderr.read()
    finally:
        process.kill()


def test_other_origins_hosts_and_missing_tokens_are_refused(scene_file, gl):
    with client(scene_file) as c:
        assert c.get("/").status_code == 200
        assert c.get("/", headers={"host": "evil.example:8000"}).status_code == 403
        assert c.post("/save/settings.toml", json={}, headers={"origin": "http://evil.example"}).status_code == 403
        with pytest.raises(WebSocketDisconnect):
            with c.websocket_connect("ws://127.0.0.1:8000/frames", headers={"origin": "http://evil.example"}) as ws:
                ws.receive_json()
    with client(scene_file, token="s3cret") as c:
        assert c.get("/").status_code == 403
        assert c.get("/?token=wrong").status_code == 403
        assert c.get("/?token=s3cret").status_code == 200


def test_a_scan_files_frame_is_its_scans_view_and_a_new_seed_remeshes(previewer):
    """A scan file's frame: its sample with the mount, overlaps resolved, noisy views from the
    spectral table, as xrayraster scan projects them; a weave key meshes the sample again."""
    from xrayraster.pipeline import load_scan_file

    document = Document.open(EXAMPLES / "twin_small.toml")
    view = document.initial_view()
    assert view.noise and view.seed == 0  # the file's [scan] table
    frame = previewer.frame(document, View(angle_deg=15.0, noise=True, seed=0))
    loaded = load_scan_file(EXAMPLES / "twin_small.toml")
    scene = loaded.with_mount(loaded.sample_scene())
    with xr.Renderer(turned(loaded.geometry, 15.0), overlap="resolve") as renderer:
        expected = renderer.project(scene, loaded.spectrum, 0, detector=loaded.detector, noise=True, seed=0,
                                    realism=loaded.realism, spectral_table=True).image
    np.testing.assert_array_equal(frame.image, expected)
    sample = previewer._sample[1]
    again = previewer.frame(document.edited({"source.kvp": 45.0}), View(angle_deg=15.0))
    assert previewer._sample[1] is sample  # the tube changed, not the sample
    reseeded = previewer.frame(document.edited({"weave.sample.seed": 7}), View(angle_deg=15.0))
    assert previewer._sample[1] is not sample and np.abs(reseeded.image - again.image).max() > 0.01


def test_the_layout_is_the_scan_seen_from_above(scene_file, previewer):
    frame = previewer.frame(Document.open(scene_file), View(angle_deg=0.0))
    source, ends, fov = np.array(frame.layout["source"]), np.array(frame.layout["detector"]), frame.layout["fov_mm"]
    half = 80 * 0.6 / 2  # 80 columns of 0.6 mm: the detector's half width
    assert np.linalg.norm(source) == pytest.approx(100.0)  # source_to_origin
    assert np.linalg.norm(ends, axis=1) == pytest.approx([np.hypot(150.0, half)] * 2)  # 250 − 100 mm beyond the axis
    assert fov == pytest.approx(100.0 * half / np.hypot(250.0, half))  # the fan's edge rays' distance from the axis


def test_a_quick_slice_is_the_middle_of_the_grid_from_a_cut_down_scan(previewer):
    from xrayraster.core.volume import VolumeGeometry
    from xrayraster.pipeline import load_scan_file

    document = Document.open(EXAMPLES / "twin_small.toml")
    cut = previewer.quick_slice(document, document.initial_view())
    loaded = load_scan_file(EXAMPLES / "twin_small.toml")  # 120 views of 32 × 128 onto a (24, 128, 128) grid
    assert cut.views == 90 and cut.detector_shape[1] == 128 and cut.detector_shape[0] <= 32
    assert cut.image.shape == cut.labels.shape == (128, 128)
    assert cut.z_mm == pytest.approx(0.5 * 0.2312)  # the middle slice (12 of 24), 0.2312 mm voxels
    # The labels are those of the sample on that one slice, as xr.voxelize gives them on its own.
    grid = VolumeGeometry((1, 128, 128), 0.2312, (cut.z_mm, 0.0, 0.0))
    np.testing.assert_array_equal(cut.labels, xr.voxelize(loaded.sample_scene(), grid).data[0])
    assert cut.names == {0: "background", 1: "matrix", 2: "weft", 3: "warp"}
    # Denser carbon reconstructs higher: warp (1.82 g/cm³) over weft (1.72) over matrix (1.08) over air.
    means = [float(cut.image[cut.labels == k].mean()) for k in range(4)]
    assert abs(means[0]) < 0.2 * means[1] and means[1] < means[2] < means[3]
    with pytest.raises(ConfigError, match="a slice needs a scan file"):
        previewer.quick_slice(Document.open(EXAMPLES / "bracket_and_ball.toml"), View())


def test_show_is_the_array_in_grey_beside_its_colour_bar():
    from xrayraster.core.figure import grey

    ramp = np.linspace(0.0, 2.0, 20 * 30).reshape(20, 30)
    picture = np.asarray(xr.show(ramp, window=(0.5, 1.5), unit="1/cm"))
    factor = 400 // 30  # enlarged to about 400 px
    shown = picture[6:6 + 20 * factor:factor, 6:6 + 30 * factor:factor, 0]
    np.testing.assert_array_equal(shown, grey(ramp, (0.5, 1.5)))
    bar = picture[6:6 + 20 * factor, 6 + 30 * factor + 19, 0].astype(int)  # the bar's first column
    assert bar[2] > 250 and bar[-3] < 5 and np.all(np.diff(bar[1:-1]) <= 0)  # white at the top, black below
    middle = np.asarray(xr.show(np.stack([ramp * 0, ramp, ramp * 0]), window=(0.5, 1.5)))
    np.testing.assert_array_equal(middle[6:6 + 20 * factor:factor, 6:6 + 30 * factor:factor, 0], shown)
    with pytest.raises(ConfigError, match="show takes a 2-D array"):
        xr.show(np.zeros(5))


def test_xr_preview_serves_the_page_once_per_file(scene_file, gl):
    import urllib.request

    from xrayraster.preview.notebook import _RUNNING

    first, again = xr.preview(scene_file), xr.preview(scene_file)
    url = getattr(first, "src", getattr(first, "url", None))  # an IFrame where IPython is installed
    try:
        assert url == getattr(again, "src", getattr(again, "url", None))
        with urllib.request.urlopen(url) as page:
            assert page.status == 200 and b"xrayraster preview" in page.read()
    finally:
        _RUNNING.pop(str(scene_file.resolve())).stop()



def test_xr_preview_of_a_scene_in_memory_shows_the_scene_file_it_writes(tmp_path, gl, previewer):
    """``xr.preview(scene)`` writes the scene as a scene file (framed about the axis, the weave
    files' tube) into a new folder and serves it: a frame of that file is the in-memory scene's
    radiograph bit for bit, the framing keeps the whole scene inside the detector (the border is
    empty), a folder in use is refused, and the scene's options are refused for a file."""
    import trimesh

    from xrayraster.preview.notebook import _RUNNING

    scene = xr.Scene()
    scene.add(trimesh.creation.box((4.0, 3.0, 2.0)), xr.Material.named("aluminium"), name="plate",
              transform=xr.Transform.translation((1.0, 0.5, 0.3)))
    scene.add(trimesh.creation.icosphere(2, radius=1.0), xr.Material.named("steel"), priority=1, name="ball")
    xr.preview(scene, directory=tmp_path / "view")
    path = tmp_path / "view" / "scene.toml"
    try:
        loaded = load_scene_file(path)
        frame = previewer.frame(Document.open(path), View(angle_deg=20.0))
        with xr.Renderer(turned(loaded.geometry, 20.0), threads=1) as renderer:
            expected = renderer.project(scene, loaded.spectrum, 0).image
        np.testing.assert_array_equal(frame.image, expected)
        assert expected.max() > 0.1 and not np.concatenate([expected[[0, -1]].ravel(), expected[:, [0, -1]].ravel()]).any()
        assert "40 kVp, W anode at 12°, filters: Al 2 mm, 1.25 mAs" in loaded.spectrum.description
    finally:
        _RUNNING.pop(str(path.resolve())).stop()
    with pytest.raises(ConfigError, match="is not an empty folder"):
        xr.preview(scene, directory=tmp_path / "view")
    with pytest.raises(ConfigError, match="geometry, source and directory are for an xr.Scene"):
        xr.preview(path, geometry=loaded.geometry)

# -- the page in a browser ---------------------------------------------------------------------

TIMEOUT_S = 60


def wait_for(condition, what: str):
    end = time.monotonic() + TIMEOUT_S
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def shown(browser) -> tuple[dict, np.ndarray]:
    """The header and the decoded values of the frame the page holds (as the page decodes them)."""
    frame = browser.execute_script("const f = xrPreview.frame; return {header: f.header, levels: Array.from(f.levels)};")
    header = frame["header"]
    levels = np.array(frame["levels"], dtype=np.float64).reshape(header["shape"])
    return header, header["lo"] + levels * ((header["hi"] - header["lo"]) / LEVELS)


def painted(browser) -> np.ndarray:
    """The canvas's grey levels (its red channel)."""
    data = browser.execute_script(
        "const c = document.getElementById('image'); "
        "return Array.from(c.getContext('2d').getImageData(0, 0, c.width, c.height).data);")
    rows, cols = browser.execute_script("const c = document.getElementById('image'); return [c.height, c.width];")
    return np.array(data, dtype=np.uint8).reshape(rows, cols, 4)[..., 0]


def frames(browser) -> int:
    return browser.execute_script("return xrPreview.painted;")


def within_a_level(header: dict, values: np.ndarray, expected: np.ndarray) -> None:
    step = (header["hi"] - header["lo"]) / LEVELS
    assert np.abs(values - expected).max() <= step / 2 * (1 + 1e-6) + 1e-7


def test_the_page_turns_paints_reports_errors_and_saves_what_render_renders(browser, scene_file, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import Select

    import tifffile

    with Background(scene_file, port=free_port(), threads=1) as server:
        browser.execute_cdp_cmd("Browser.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(tmp_path)})
        browser.get(server.url)
        wait_for(lambda: frames(browser) >= 1, "the first frame")
        header, first = shown(browser)
        assert header["angle_deg"] == 0.0 and header["unit"] == "1"
        within_a_level(header, first, reference(scene_file, 0.0))

        # The slider, moved as a user moves it: four steps of 0.25° with the arrow key.
        slider = browser.find_element(By.ID, "angle")
        slider.send_keys(*[Keys.ARROW_RIGHT] * 4)
        wait_for(lambda: shown(browser)[0]["angle_deg"] == pytest.approx(1.0), "the frame at 1°")
        header, turned = shown(browser)
        assert np.abs(turned - first).max() > 0.01  # the picture changed
        within_a_level(header, turned, reference(scene_file, 1.0))

        # Dragging the image sideways turns the sample half a degree a screen pixel.
        canvas = browser.find_element(By.ID, "image")
        ActionChains(browser).move_to_element(canvas).click_and_hold().move_by_offset(8, 0).release().perform()
        wait_for(lambda: shown(browser)[0]["angle_deg"] == pytest.approx(5.0), "the frame at 1° + 8 × 0.5°")
        header, dragged = shown(browser)
        within_a_level(header, dragged, reference(scene_file, 5.0))
        slider.send_keys(*[Keys.ARROW_LEFT] * 16)  # back to 1° in steps of 0.25°
        wait_for(lambda: shown(browser)[0]["angle_deg"] == pytest.approx(1.0), "the frame at 1° again")

        # What is painted is the frame through the page's window and level (auto: 0.5-99.5 %).
        window = browser.execute_script("return xrPreview.window;")
        low = window["level"] - window["width"] / 2
        expected = np.clip(np.round(255 * (turned - low) / window["width"]), 0, 255)
        np.testing.assert_array_equal(painted(browser), expected)

        # A bad value: its error is shown, the last good image stays.
        count, before = frames(browser), painted(browser)
        kv = browser.find_element(By.CSS_SELECTOR, "input[type=number][data-key='source.kvp']")
        kv.clear()
        kv.send_keys("-5", Keys.ENTER)
        error = browser.find_element(By.ID, "error")
        wait_for(lambda: error.is_displayed() and "kvp must be > 0, got -5" in error.text, "the error text")
        assert frames(browser) == count
        np.testing.assert_array_equal(painted(browser), before)

        # A good value again, then the settings saved and rendered by the command line.
        kv.clear()
        kv.send_keys("70", Keys.ENTER)
        wait_for(lambda: frames(browser) > count and not error.is_displayed(), "the frame at 70 kV")
        _, primary = shown(browser)

        # Scatter picked from its list: it adds signal behind the sample, so its line integrals fall.
        count = frames(browser)
        Select(browser.find_element(By.CSS_SELECTOR, "select[data-key='physics.scatter']")).select_by_value("kernel")
        wait_for(lambda: frames(browser) > count, "the frame with scatter")
        header, final = shown(browser)
        assert final.sum() < primary.sum() and (final <= primary + 1e-6).all()
        browser.find_element(By.ID, "save-settings").click()
        saved = wait_for(lambda: (tmp_path / "settings.toml").exists() and tmp_path / "settings.toml", "the download")
        time.sleep(0.2)  # Chromium renames the finished download into place
        out = tmp_path / "render.tif"
        assert main(["render", str(saved), "-o", str(out)]) == 0
        within_a_level(header, final, tifffile.imread(out))
        if os.environ.get("XRAYRASTER_PREVIEW_SCREENSHOT"):
            browser.save_screenshot(os.environ["XRAYRASTER_PREVIEW_SCREENSHOT"])


DRAG = """
const [seconds, done] = [arguments[0], arguments[arguments.length - 1]];
const slider = document.getElementById('angle'), label = document.getElementById('resolution');
const canvas = document.getElementById('image'), p = xrPreview, start = performance.now();
const seen = [];  // what the page showed while the input moved: frames, label, canvas
let angle = parseFloat(slider.value);
const timer = setInterval(() => {
  angle += 0.5;
  slider.value = angle;
  slider.dispatchEvent(new Event('input'));
  const h = p.frame && p.frame.header, box = canvas.getBoundingClientRect();
  if (h) seen.push({id: h.id, binning: h.binning, label: label.textContent, cls: canvas.className,
                    size: [canvas.height, canvas.width], box: [box.width, box.height]});
  if (performance.now() - start > 1000 * seconds) {
    clearInterval(timer);
    const last = performance.now();
    const settle = setInterval(() => {
      const h = p.frame.header, box = canvas.getBoundingClientRect();
      if (Math.abs(h.angle_deg - angle) < 1e-6 && h.binning === 1) {
        clearInterval(settle);
        done({seen, angle, full_ms: p.paintedAt - last, label: label.textContent, cls: canvas.className,
              size: [canvas.height, canvas.width], box: [box.width, box.height]});
      }
    }, 5);
  }
}, 1000 / 60);
"""


def test_while_the_angle_is_dragged_the_page_shows_reduced_frames_then_the_full_one(browser, scene_file):
    """Dragging the angle slider (input events at 60 a second): the page asks for reduced frames,
    which are the binned detector's render, stretched to the full frame's size on screen and labelled
    so; once the input stops, it asks for the full frame, labelled "full resolution", the
    renderer's view at the last angle."""
    loaded = load_scene_file(scene_file)
    with Background(scene_file, port=free_port(), threads=1, moving_pixels=40 * 40) as server:
        browser.get(server.url)
        wait_for(lambda: frames(browser) >= 1, "the first frame")
        browser.set_script_timeout(TIMEOUT_S)
        drag = browser.execute_async_script(DRAG, 1.0)
        reduced = browser.execute_script("const f = xrPreview.reduced; return {header: f.header, levels: Array.from(f.levels)};")
        header, final = shown(browser)
    moving = [s for s in drag["seen"] if s["binning"] == 2]
    assert moving, "no reduced frame was shown while the angle moved"
    for s in moving:
        assert s["label"] == "preview: 1/2 resolution while moving (32 × 40 of 64 × 80 pixels)"
        assert s["cls"] == "reduced" and s["size"] == [32, 40]
        assert s["box"] == pytest.approx(drag["box"], abs=1)  # stretched to the full frame's size on screen
    assert drag["label"] == "full resolution (64 × 80 pixels)" and drag["cls"] == "" and drag["size"] == [64, 80]
    assert header["binning"] == 1 and header["angle_deg"] == pytest.approx(drag["angle"])
    within_a_level(header, final, reference(scene_file, drag["angle"]))  # the full frame, exactly the renderer's
    assert 0 < drag["full_ms"] < 5000
    h = reduced["header"]
    assert h["binning"] == 2 and h["shape"] == [32, 40] and h["full_shape"] == [64, 80]
    levels = np.array(reduced["levels"], dtype=np.float64).reshape(h["shape"])
    with xr.Renderer(binned(turned(loaded.geometry, h["angle_deg"]), 2), threads=1) as renderer:
        expected = renderer.project(loaded.scene, loaded.spectrum, 0, detector=loaded.detector).image
    within_a_level(h, h["lo"] + levels * ((h["hi"] - h["lo"]) / LEVELS), expected)


def test_the_slice_button_shows_the_quick_slice_and_its_labels(browser, previewer):
    from selenium.webdriver.common.by import By

    document = Document.open(EXAMPLES / "twin_small.toml")
    expected = previewer.quick_slice(document, document.initial_view())
    with Background(EXAMPLES / "twin_small.toml", port=free_port(), threads=1) as server:
        browser.get(server.url)
        wait_for(lambda: frames(browser) >= 1, "the first frame")
        browser.find_element(By.ID, "slice").click()
        cut = wait_for(lambda: browser.execute_script("return xrPreview.slice || null;"), "the quick slice")
        caption = browser.find_element(By.ID, "slice-caption").text
        legend = browser.find_element(By.ID, "slice-legend").text
    np.testing.assert_array_equal(np.array(cut["labels"]).reshape(expected.labels.shape), expected.labels)
    assert cut["header"]["views"] == 90 and "90 views" in caption and "1/cm" in caption
    assert legend.split() == ["1", "matrix", "2", "weft", "3", "warp"]


@pytest.mark.parametrize("family, shown, hidden", [
    ("layer_to_layer", set(), {"weave.binder_step", "weave.binder_offset", "weave.warp_ratio"}),
    ("orthogonal", {"weave.warp_ratio", "weave.binder_ratio"}, {"weave.binder_step", "weave.binder_offset"}),
    ("offset_angle_interlock", {"weave.binder_step", "weave.binder_offset"}, {"weave.warp_ratio"}),
    ("plain", {"weave.plies"}, {"weave.weft_layers", "weave.weft_per_layer", "weave.binder_ratio", "weave.harness"}),
    ("satin", {"weave.plies"}, {"weave.weft_layers", "weave.binder_step"}),
])
def test_a_weave_shows_the_sliders_of_its_family(tmp_path, family, shown, hidden):
    """Each family's own fields get sliders at the cell's values; another family's fields, and the
    stuffer ratio of a cell without stuffers, get none."""
    from xrayraster.preview.controls import controls
    from xrayraster.preview.document import Document

    path = tmp_path / "weave.toml"
    path.write_text(f'[weave]\nfamily = "{family}"\n')
    document = Document.open(path)
    loaded = document.load()
    got = {c["key"]: c["value"] for c in controls(document, loaded)}
    assert shown <= set(got) and not hidden & set(got)
    assert all(got[key] == getattr(loaded.weave.sample.cell, key.split(".")[-1]) for key in shown)
    if family == "satin":  # its harness, left to the family: the pattern's size
        assert got["weave.harness"] == len(loaded.weave.sample.cell.pattern) == 5


def test_scatter_is_a_list_to_pick_from_at_the_files_value(tmp_path):
    from xrayraster.preview.controls import controls
    from xrayraster.preview.document import Document

    small = (Path(__file__).resolve().parents[2] / "examples" / "scan_small.toml").read_text()
    path = tmp_path / "scan.toml"
    for text, value in (("[weave]\n", "none"), (small + '\n[physics]\nscatter = "kernel"\n', "kernel")):
        path.write_text(text)
        document = Document.open(path)
        control = next(c for c in controls(document, document.load()) if c["key"] == "physics.scatter")
        assert control["kind"] == "choice" and control["choices"] == ["none", "kernel"] and control["value"] == value
