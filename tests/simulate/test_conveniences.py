"""Python conveniences: every view in one call (with progress), ``.save`` on Projections, Volume
and LabelVolume (read back with tifffile as Fiji reads them), quick-looks large enough to see with
their scale, and the GL context's thread check."""

from __future__ import annotations

import json
import os
import threading

import numpy as np
import pytest
import tifffile
import trimesh
from PIL import Image

import xrayraster as xr
from xrayraster.core.tiff import QUICKLOOK_MIN_PX, quicklook_factor, write_quicklook

GEOMETRY = xr.ConeBeamGeometry(100.0, 200.0, (24, 30), 0.8, xr.full_circle(5))
MONO = xr.Spectrum.monochromatic(60.0, 1e6)
AL, STEEL = xr.Material.named("aluminium"), xr.Material.named("steel")


@pytest.fixture(scope="module")
def scene():
    s = xr.Scene()
    s.add(trimesh.creation.box((8.0, 8.0, 8.0)), AL, name="cube")
    s.add(trimesh.creation.icosphere(subdivisions=2, radius=2.0), STEEL, name="ball",
          transform=xr.Transform.translation((0.0, 0.0, 3.0)), priority=1)
    return s


@pytest.fixture
def renderer(gl):
    with xr.Renderer(GEOMETRY, context=gl) as r:
        yield r


def _resolution_mm(tif) -> tuple[float, float]:
    """(y, x) pixel size in mm as Fiji reads it: 1 / (X|Y)Resolution (pixels per unit, unit mm)."""
    tags = tif.pages[0].tags
    x, y = tags["XResolution"].value, tags["YResolution"].value
    return y[1] / y[0], x[1] / x[0]


# ----------------------------------------------------------------------------- all views in one call


def test_path_lengths_all_equals_the_per_view_calls_with_a_callback(renderer, scene):
    calls = []
    views = [4, 1, 2]
    p = renderer.path_lengths_all(scene, views, progress=lambda done, total: calls.append((done, total)))
    assert calls == [(1, 3), (2, 3), (3, 3)]
    assert isinstance(p, xr.Projections) and p.quantity == "path_length" and p.unit == "mm"
    assert p.geometry == GEOMETRY[views] and p.geometry.angles == tuple(GEOMETRY.angles[v] for v in views)
    for k, v in enumerate(views):
        np.testing.assert_array_equal(p.data[k], renderer.path_lengths(scene, v))
    assert p.provenance["views"] == views and p.provenance["materials"] == ["aluminium", "steel"]
    assert p.data[:, 1].max() > 3.5  # the ball is seen: the stack is not empty


def test_project_all_defaults_to_every_view_and_equals_project(renderer, scene):
    p = renderer.project_all(scene, MONO, progress=False, noise=True, seed=7)
    assert p.data.shape == (5, 24, 30) and p.geometry == GEOMETRY[list(range(5))] == GEOMETRY
    assert (p.quantity, p.unit) == ("lineint", "1")
    for v in range(5):
        shot = renderer.project(scene, MONO, v, noise=True, seed=7)
        np.testing.assert_array_equal(p.data[v], shot.image)
    prov = p.provenance
    assert prov["views"] == [0, 1, 2, 3, 4] and prov["seed"] == 7 and prov["noise"] is True
    assert prov["spectrum"] == MONO.description and prov["materials"] == ["aluminium", "steel"]
    assert prov["starved_pixels"] == [0] * 5 and prov["method"] in ("resolve", "nested", "sum")
    json.dumps(p.metadata())  # every provenance value is JSON-ready


def test_project_lengths_is_project_all_without_the_gl(renderer, scene):
    """The physics of kept path lengths, as a fit runs it: every byte and the provenance of project_all,
    for the scene with its materials replaced too (same meshes, same channels)."""
    from xrayraster.physics.realism import Realism

    tube = xr.Spectrum.from_tube(60.0)
    realism = Realism(gain_variation=0.01, scatter="kernel")
    lengths = renderer.path_lengths_all(scene, progress=False)
    denser = scene.with_materials({AL: xr.Material(AL.name, AL.composition, AL.density * 1.1)})
    assert [o.mesh for o in denser.objects] == [o.mesh for o in scene.objects] and len(denser.materials) == 2
    for case in (scene, denser):
        want = renderer.project_all(case, tube, noise=True, seed=3, realism=realism, spectral_table=True, progress=False)
        got = renderer.project_lengths(case, lengths, tube, noise=True, seed=3, realism=realism, spectral_table=True)
        np.testing.assert_array_equal(got.data, want.data)
        assert got.provenance == want.provenance
    with pytest.raises(xr.XrayrasterError, match="path lengths of the scene's 2 materials"):
        renderer.project_lengths(scene, renderer.project_all(scene, MONO, progress=False), MONO)
    with pytest.raises(xr.XrayrasterError, match="two materials became one"):
        scene.with_materials({STEEL: AL})


@pytest.mark.parametrize("workers", [1, 3])
def test_project_all_overlaps_the_physics_and_keeps_every_byte(renderer, scene, monkeypatch, workers):
    """The physics of view k runs on a thread (``workers`` of them, as beside a GPU) while the GL
    renders view k + 1: with the scan's shared patterns (flats, gain map, a focal spot) and views
    out of order, every view is still the bytes project() gives alone, and the physics did run off
    the main thread, at the caller's priority as the kernel reports it (a lowered one starved the
    physics whenever another process rendered: 13x slower samples in a two-worker build)."""
    realism = xr.Realism(focal_spot_mm=0.3, flat_fields=4, gain_variation=0.01)
    threads = set()
    physics_of = renderer._physics_of
    niceness = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    def watched(*args, **kwargs):
        run = physics_of(*args, **kwargs)

        def physics(view, lengths):
            threads.add((threading.current_thread().name, os.getpriority(os.PRIO_PROCESS, threading.get_native_id())))
            return run(view, lengths)

        return physics

    monkeypatch.setattr(renderer, "_physics_of", watched)
    monkeypatch.setattr(renderer, "physics_workers", workers)
    views = [3, 0, 4, 1]
    p = renderer.project_all(scene, MONO, views, noise=True, seed=11, realism=realism, progress=False)
    names = {name for name, _ in threads}
    assert names and all(name.startswith("xrayraster-physics") for name in names) and len(names) <= workers
    for k, v in enumerate(views):
        np.testing.assert_array_equal(p.data[k], renderer.project(scene, MONO, v, noise=True, seed=11,
                                                                  realism=realism).image)
    assert {nice for _, nice in threads} == {niceness}
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == niceness


@pytest.mark.parametrize("mode, unit", [("integrating", "keV deposited"), ("counting", "counts")])
def test_raw_units_follow_the_detector(renderer, scene, mode, unit):
    detector = xr.Detector(mode=mode)
    p = renderer.project_all(scene, MONO, [2], detector=detector, output="raw", progress=False)
    assert (p.quantity, p.unit) == ("raw", unit)
    np.testing.assert_array_equal(p.data[0], renderer.project(scene, MONO, 2, detector=detector, output="raw").image)


def test_progress_true_draws_a_bar_on_stderr_and_false_draws_none(renderer, scene, capsys):
    renderer.path_lengths_all(scene, [0, 1], progress=True)
    err = capsys.readouterr().err
    assert "2/2" in err and "view" in err
    renderer.path_lengths_all(scene, [0, 1], progress=False)
    renderer.path_lengths_all(scene, [0, 1])  # default: no bar, stderr is not a terminal under pytest
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("views, match", [([5], "not an index"), ([], "empty"), (3, "list of view indices")])
def test_bad_views_name_the_fix(renderer, scene, views, match):
    with pytest.raises(xr.RenderError, match=match):
        renderer.path_lengths_all(scene, views, progress=False)


def test_bad_progress_is_an_error(renderer, scene):
    with pytest.raises(xr.RenderError, match="progress must be"):
        renderer.path_lengths_all(scene, [0], progress="yes")


# ----------------------------------------------------------------------------- .save


def test_projections_save_reads_back_as_fiji_reads_it(tmp_path):
    rng = np.random.default_rng(1)
    geometry = GEOMETRY[[0, 3]]
    p = xr.Projections(rng.random((2, 24, 30), dtype=np.float32), geometry, "transmission", "1", {"note": "x"})
    out = p.save(tmp_path / "p.tif")
    with tifffile.TiffFile(out) as tif:
        data = tif.asarray()
        assert tif.imagej_metadata["unit"] == "mm"
        assert _resolution_mm(tif) == pytest.approx((0.8, 0.8), rel=1e-6)
        info = json.loads(tif.imagej_metadata["Info"])
    np.testing.assert_array_equal(data, p.data)
    assert info["geometry"] == geometry.to_dict() and info["output"] == "transmission" and info["note"] == "x"
    back = xr.Projections.load(out)
    assert back.geometry == geometry and back.provenance == {"note": "x"}
    with Image.open(tmp_path / "p.png") as png:
        assert max(png.size) >= QUICKLOOK_MIN_PX and png.text["scale_bar"].endswith("mm at the detector")


def test_path_length_save_quicklook_sums_materials(tmp_path):
    data = np.zeros((1, 2, 24, 30), np.float32)
    data[0, 0, 5, 7], data[0, 1, 5, 7] = 1.0, 3.0
    data[0, 1, 10, 10] = 2.0
    xr.Projections(data, GEOMETRY[[0]], "path_length", "mm").save(tmp_path / "l.tif")
    with Image.open(tmp_path / "l.png") as png:
        f = int(png.text["upscale"])
        pixels = np.asarray(png)[: 24 * f : f, ::f]
    assert pixels[::-1][5, 7] == 255 and pixels[::-1][10, 10] == 128  # 4 mm is the peak; 2 mm half of it


def test_volume_save(tmp_path):
    grid = xr.VolumeGeometry((6, 10, 12), (0.6, 0.5, 0.4), offset=(0.3, 0.0, -0.2))
    data = np.random.default_rng(2).normal(size=grid.shape).astype(np.float32)
    out = xr.Volume(data, grid, provenance={"filter": "hann"}).save(tmp_path / "v.tif")
    with tifffile.TiffFile(out) as tif:
        back = tif.asarray()
        assert tif.series[0].axes == "ZYX" and tif.imagej_metadata["unit"] == "mm"
        assert tif.imagej_metadata["spacing"] == pytest.approx(0.6)
        assert _resolution_mm(tif) == pytest.approx((0.5, 0.4), rel=1e-6)
        info = json.loads(tif.imagej_metadata["Info"])
    np.testing.assert_array_equal(back, data)
    assert info["volume_geometry"] == grid.to_dict() and info["units"] == "1/cm" and info["filter"] == "hann"
    with Image.open(tmp_path / "v.png") as png:
        assert png.text["mm_per_pixel"].startswith("0.4 x 0.5")


def test_fdk_volume_carries_its_provenance(tmp_path, cl):
    grid = xr.VolumeGeometry((4, 8, 8), 1.0)
    volume = xr.fdk(np.zeros((5, 24, 30), np.float32), GEOMETRY, grid, filter="hann", context=cl)
    assert volume.unit == "1/cm" and volume.provenance["geometry"] == GEOMETRY.to_dict()
    assert volume.provenance["filter"] == "hann" and volume.provenance["method"] == "FDK"
    info = json.loads(tifffile.TiffFile(volume.save(tmp_path / "r.tif")).imagej_metadata["Info"])
    assert xr.ConeBeamGeometry.from_dict(info["geometry"]) == GEOMETRY


def test_label_volume_save_with_fractions(tmp_path):
    grid = xr.VolumeGeometry((4, 6, 8), 0.25)
    data = np.zeros(grid.shape, np.uint8)
    data[1:3, 2:4, 2:6] = 2
    fractions = np.stack([(data == 0), (data == 2)]).astype(np.float32)
    out = xr.LabelVolume(data, grid, (0, 2), fractions).save(tmp_path / "lab.tif")
    with tifffile.TiffFile(out) as tif:
        back = tif.asarray()
        assert _resolution_mm(tif) == pytest.approx((0.25, 0.25), rel=1e-6)
        info = json.loads(tif.imagej_metadata["Info"])
    assert back.dtype == np.uint8 and np.array_equal(back, data)
    assert info["volume_geometry"] == grid.to_dict() and info["labels_present"] == [2]
    with tifffile.TiffFile(tmp_path / "lab_fractions.tif") as tif:
        assert tif.series[0].axes == "ZCYX"
        np.testing.assert_array_equal(tif.asarray(), fractions.transpose(1, 0, 2, 3))
        assert json.loads(tif.imagej_metadata["Info"])["channel_labels"] == [0, 2]
    assert (tmp_path / "lab.png").is_file()


# ----------------------------------------------------------------------------- quick-looks


def test_small_quicklooks_are_enlarged_by_an_integer_factor_with_a_scale_bar(tmp_path):
    image = np.arange(30 * 40, dtype=np.float64).reshape(30, 40)
    png = write_quicklook(tmp_path / "q.png", image, (0.2, 0.5), where="at the detector")
    with Image.open(png) as im:
        text, pixels = dict(im.text), np.asarray(im)
    factor = 13  # ceil(512 / 40)
    assert text["upscale"] == "13" and pixels.shape[1] == 40 * factor and pixels.shape[0] > 30 * factor
    expected = np.round(255 * image / image.max()).astype(np.uint8)[::-1]
    np.testing.assert_array_equal(pixels[: 30 * factor], np.kron(expected, np.ones((factor, factor), np.uint8)))
    assert text["mm_per_pixel"] == "0.5 x 0.2 (x by y, image pixel)"
    length = float(text["scale_bar"].split(" mm")[0])
    assert text["scale_bar"] == f"{length:g} mm at the detector" and length in (1, 2, 5)
    strip = pixels[30 * factor:]
    bar_row = strip[7]  # the bar is 4 px tall, 6 px below the picture
    bar = np.flatnonzero(bar_row[: len(bar_row) // 2] == 255)
    assert len(bar) == round(length / (0.5 / factor)) and bar[0] == 6  # its length is the stated mm
    assert strip[:, bar[-1] + 8:].max() > 200  # and the label is drawn beside it


def test_large_images_keep_their_size_and_no_scale_without_a_pixel_size(tmp_path):
    assert quicklook_factor((600, 700)) == 1 and quicklook_factor((4, 4)) == 128 and quicklook_factor((256, 320)) == 2
    png = write_quicklook(tmp_path / "big.png", np.ones((520, 600)))
    with Image.open(png) as im:
        assert im.size == (600, 520) and "scale_bar" not in im.text


# ----------------------------------------------------------------------------- threads


def test_a_renderer_used_from_another_thread_says_so_and_still_works_in_its_own(scene):
    box = xr.Scene()
    box.add(trimesh.creation.box((8.0, 8.0, 8.0)), "a")
    with xr.Renderer(GEOMETRY) as r:  # its own context, made in this (the main) thread
        before = r.path_lengths(box, 0)
        caught = []

        def use():
            try:
                r.path_lengths(box, 0)
            except Exception as exc:  # noqa: BLE001 - what is raised is the test
                caught.append(exc)

        worker = threading.Thread(target=use, name="worker-1")
        worker.start()
        worker.join()
        assert len(caught) == 1 and isinstance(caught[0], xr.GLContextError)
        message = str(caught[0])
        assert "belongs to the thread that created it" in message and "'MainThread'" in message
        assert "'worker-1'" in message and "create the Renderer (or GLContext) in the thread that uses it" in message
        np.testing.assert_array_equal(r.path_lengths(box, 0), before)
        assert abs(before[0, 12, 15] - 8.0) < 1e-3  # through the 8 mm cube's centre
