"""The pictures a user reads (issue 22): a scan's slices.png and a dataset's gallery. Their text is
not read back; the tests find each part by the boxes the composition reports and check its pixels:
the panels' size and colours, the colour bar's grey rising to its top, the legend's swatches (only
the labels shown), the Software chunk and the same bytes for the same arrays."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from xrayraster.core.errors import ConfigError
from xrayraster.core.figure import PALETTE, bar_ticks, legend_entry
from xrayraster.core.ownership import SOFTWARE
from xrayraster.core.pictures import gallery_picture, slices_picture, write_gallery, write_slices
from xrayraster.core.tiff import quicklook_factor
from xrayraster.core.volume import VolumeGeometry

SHAPE = (8, 20, 30)  # z, y, x
NAMES = {"0": "background", "1": "matrix", "2": "weft", "3": "warp"}


def box_sample(mu: float = 0.5):
    """A box of μ = ``mu`` cm⁻¹ labelled 1 (matrix), its upper y part 3 (warp); no label 2."""
    volume = np.zeros(SHAPE, np.float32)
    labels = np.zeros(SHAPE, np.uint8)
    volume[2:6, 4:16, 5:25] = mu
    labels[2:6, 4:16, 5:25] = 1
    labels[2:6, 12:16, 5:25] = 3
    return volume, labels


def panel(picture, name):
    x0, y0, x1, y1 = picture.boxes[name]
    return picture.image[y0:y1, x0:x1]


def test_each_panel_is_its_central_slice_enlarged_with_y_and_z_up():
    volume, labels = box_sample()
    picture = slices_picture(volume, labels, NAMES)
    factor = quicklook_factor(SHAPE)
    for row, (rows, cols) in {"z": (20, 30), "y": (8, 30), "x": (8, 20)}.items():
        for column in ("reconstruction", "labels", "overlay"):
            assert panel(picture, f"{row}/{column}").shape == (rows * factor, cols * factor, 3)
    shown = panel(picture, "z/labels")[factor // 2::factor, factor // 2::factor]  # one pixel a voxel
    expected = np.zeros((20, 30, 3), np.uint8)
    expected[labels[4] == 1] = PALETTE[0]
    expected[labels[4] == 3] = PALETTE[2]
    np.testing.assert_array_equal(shown, expected[::-1])  # +y up: the warp part at the top
    side = panel(picture, "x/labels")[factor // 2::factor, factor // 2::factor]
    assert (side[::-1][2:6, 12:16] == PALETTE[2]).all() and (side[::-1][2:6, 4:12] == PALETTE[0]).all()


def test_the_grey_and_the_overlay_follow_the_window():
    volume, labels = box_sample()
    picture = slices_picture(volume, labels, NAMES)
    assert picture.window == (0.0, 1.0)  # every labelled voxel 0.5: the window widened around it
    factor = quicklook_factor(SHAPE)
    grey = panel(picture, "z/reconstruction")[factor // 2::factor, factor // 2::factor][::-1]
    assert (grey[labels[4] > 0] == 128).all() and (grey[labels[4] == 0] == 0).all()
    overlay = panel(picture, "z/overlay")[factor // 2::factor, factor // 2::factor][::-1].astype(int)
    blend = np.round(0.65 * 128 + 0.35 * PALETTE[0].astype(float)).astype(int)
    assert (overlay[labels[4] == 1] == blend).all() and (overlay[labels[4] == 0] == 0).all()


def test_the_colour_bar_rises_from_black_to_white_and_its_ticks_span_the_window():
    volume, labels = box_sample()
    volume[labels > 0] += np.linspace(0.0, 0.3, int((labels > 0).sum()), dtype=np.float32)
    picture = slices_picture(volume, labels, NAMES)
    x0, y0, x1, y1 = picture.boxes["colour_bar"]
    assert y1 - y0 >= 100 and x1 - x0 >= 10
    bar = picture.image[y0:y1, x0:x1].astype(int)
    assert (bar == bar[:, :1]).all()  # grey: every column and channel alike
    levels = bar[::-1, 0, 0]  # bottom to top
    assert (np.diff(levels) >= 0).all() and levels[0] <= 1 and levels[-1] >= 254
    ticks = bar_ticks(picture.window, y1 - y0)
    assert ticks[0][0] == picture.window[0] and ticks[-1][0] == picture.window[1] and len(ticks) >= 3
    assert all(a[0] < b[0] for a, b in zip(ticks, ticks[1:]))


def test_the_legend_shows_the_labels_shown_and_only_them():
    volume, labels = box_sample()
    picture = slices_picture(volume, labels, NAMES)
    assert sorted(k for k in picture.boxes if k.startswith("legend/")) == ["legend/1", "legend/3"]
    for label in (1, 3):
        assert (panel(picture, f"legend/{label}") == PALETTE[label - 1]).all()
    colours = {tuple(c) for c in panel(picture, "legend").reshape(-1, 3).tolist()}
    assert tuple(PALETTE[0]) in colours and tuple(PALETTE[2]) in colours
    assert not colours & {tuple(c) for c in PALETTE[[1, 3, 4, 5]].tolist()}


def test_label_names_come_from_either_key_type_or_fall_back():
    assert legend_entry({"2": "weft"}, 2) == "2 weft"
    assert legend_entry({2: "weft"}, 2) == "2 weft"
    assert legend_entry({"2": "weft"}, 4) == "label 4"
    assert legend_entry(None, 1) == "label 1"


def test_a_grid_adds_the_scale_bar():
    volume, labels = box_sample()
    assert "scale_bar" not in slices_picture(volume, labels).boxes
    grid = VolumeGeometry(SHAPE, 0.1)
    x0, _, x1, _ = slices_picture(volume, labels, NAMES, grid).boxes["scale_bar"]
    mm_per_px = 0.1 / quicklook_factor(SHAPE)
    assert (x1 - x0) * mm_per_px == pytest.approx(0.5, abs=mm_per_px)  # a round length no longer than 160 px


def test_the_png_is_marked_as_ours_and_the_same_bytes_each_time(tmp_path):
    volume, labels = box_sample()
    grid = VolumeGeometry(SHAPE, 0.1)
    first = write_slices(tmp_path / "a.png", volume, labels, NAMES, grid)
    second = write_slices(tmp_path / "b.png", volume.copy(), labels.copy(), dict(NAMES), grid)
    assert first.read_bytes() == second.read_bytes()
    with Image.open(first) as image:
        assert image.text["Software"] == SOFTWARE
        assert image.size == slices_picture(volume, labels, NAMES, grid).image.shape[1::-1]
        assert image.text["grey_window"] == "0 1 1/cm"


def test_the_gallery_has_one_row_per_sample_in_one_window(tmp_path):
    samples = [(*box_sample(mu), NAMES, f"sample {i}") for i, mu in enumerate((0.5, 1.0, 0.25))]
    picture = gallery_picture(samples)
    rows = [picture.boxes[f"{i}/reconstruction"] for i in range(3)]
    assert "3/reconstruction" not in picture.boxes
    assert all(a[3] < b[1] for a, b in zip(rows, rows[1:]))  # top to bottom, apart
    assert [picture.boxes[f"{i}/labels"][1] for i in range(3)] == [r[1] for r in rows]
    # One window over all: the brighter sample is brighter in the picture.
    centres = [picture.image[(r[1] + r[3]) // 2, (r[0] + r[2]) // 2, 0] for r in rows]
    assert centres[1] > centres[0] > centres[2]
    assert picture.window[0] <= 0.25 and picture.window[1] >= 1.0
    assert sorted(k for k in picture.boxes if k.startswith("legend/")) == ["legend/1", "legend/3"]
    path = write_gallery(tmp_path / "gallery.png", samples)
    assert path.read_bytes() == write_gallery(tmp_path / "again.png", samples).read_bytes()
    with Image.open(path) as image:
        assert image.text["Software"] == SOFTWARE


def test_a_gallery_needs_a_sample():
    with pytest.raises(ConfigError, match="at least one sample"):
        gallery_picture([])


def test_slices_without_labels_have_no_legend():
    volume, _ = box_sample()
    picture = slices_picture(volume, np.zeros(SHAPE, np.uint8))
    assert not [k for k in picture.boxes if k.startswith("legend")] and "colour_bar" in picture.boxes
