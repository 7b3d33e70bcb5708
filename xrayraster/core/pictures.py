"""The pictures a user reads: a scan's ``slices.png`` (its central slices: the reconstruction, the
labels and the two overlaid) and a dataset's gallery (the central z slice of a few samples, in one
grey window). Each says what it shows without the docs: which slice each row is, a colour bar in
cm⁻¹, a legend of the label colours it shows and, where the grid is known, a scale bar in mm.

They live in ``core``, beside the quick-look writer, because they need nothing above it: arrays in,
PNG out. ``*_picture`` compose the image (and the boxes of its parts, which tests read); ``write_*``
write it atomically, with the Software chunk that marks it as ours (:func:`~.tiff.png_text`). Both
are pure: the same arrays give the same bytes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import figure
from .errors import ConfigError
from .files import atomic_write
from .figure import Box
from .tiff import png_text, quicklook_factor

OVERLAY_ALPHA = 0.35  # the label colour's share in the overlay: enough to read classes, the grey still shows
GALLERY_PX = 256  # a gallery panel's long side is enlarged to at least this (integer factor): six rows fit a screen
MARGIN, GAP = 16, 10
SCALE_BAR_PX = 160  # the scale bar's longest length: it fits the side column
SLICES_COLUMNS = ("reconstruction", "labels", "overlay")
GALLERY_COLUMNS = ("reconstruction", "labels")
_AXES = "zyx"


@dataclass(frozen=True)
class Picture:
    """``image`` (rows, cols, 3) uint8, the ``window`` (cm⁻¹) its grey shows, and the ``boxes``
    (x0, y0, x1, y1; exclusive ends) of its parts: ``"<row>/<column>"`` for each panel (row ``z``,
    ``y``, ``x`` in a scan's slices, the sample's place in a gallery), ``colour_bar`` (the bar's grey
    pixels only), ``legend`` and ``legend/<label>`` (a swatch: its colour only), ``scale_bar``."""

    image: np.ndarray
    window: tuple[float, float]
    boxes: dict[str, Box]


def show(array, *, window: tuple[float, float] | None = None, unit: str = "", title: str = ""):
    """A 2-D array (a 3-D one's middle slice along its first axis) as a grey picture, row 0 at the
    top, enlarged to about 400 pixels, with a colour bar over ``window`` (default its finite values'
    1st to 99.5th percentile) labelled in ``unit``, and ``title`` above: a PIL image, which a
    notebook shows inline (``xr.show``)."""
    from PIL import Image, ImageDraw

    data = np.asarray(array, dtype=np.float64)
    if data.ndim == 3:
        data = data[data.shape[0] // 2]
    if data.ndim != 2 or not data.size:
        raise ConfigError(f"show takes a 2-D array (or a 3-D stack: its middle slice), got shape {data.shape}")
    finite = data[np.isfinite(data)]
    if window is None:
        low, high = (float(v) for v in np.percentile(finite, figure.WINDOW_PERCENTILES)) if finite.size else (0.0, 1.0)
        window = (low, high) if high > low else (low - (abs(low) or 1.0), low + (abs(low) or 1.0))
    picture = figure.enlarge(figure.grey(np.nan_to_num(data, nan=window[0]), window), max(1, 400 // max(data.shape)))
    top = figure.line_px() + 8 if title else 6
    bar_box, _ = figure.colour_bar(None, (0, 0), picture.shape[0], window)
    caption = f"{unit}" if unit else ""
    width = picture.shape[1] + 18 + max(bar_box[2], figure.text(None, (0, 0), caption)[2] if caption else 0) + 8
    canvas = Image.new("RGB", (width, top + picture.shape[0] + figure.line_px() + 12), figure.BACKGROUND)
    canvas.paste(Image.fromarray(np.repeat(picture[..., None], 3, axis=2)), (6, top))
    draw = ImageDraw.Draw(canvas)
    if title:
        figure.text(draw, (6, 4), title)
    figure.colour_bar(draw, (picture.shape[1] + 18, top - figure.line_px() // 2), picture.shape[0], window)
    if caption:
        figure.text(draw, (picture.shape[1] + 18, top + picture.shape[0] + 6), caption)
    return canvas


def write_slices(path, volume: np.ndarray, labels: np.ndarray, names=None, grid=None) -> Path:
    """Write :func:`slices_picture` as a PNG at ``path``, atomically; returns the path."""
    return _write(path, slices_picture(volume, labels, names, grid))


def write_gallery(path, samples) -> Path:
    """Write :func:`gallery_picture` as a PNG at ``path``, atomically; returns the path."""
    return _write(path, gallery_picture(samples))


def slices_picture(volume: np.ndarray, labels: np.ndarray, names=None, grid=None) -> Picture:
    """The central slices across z, y and x (one row each, +z or +y up, each row captioned with its
    slice): the reconstruction (grey, cm⁻¹), the labels (colours) and the two overlaid. The grey
    window spans the 1st to the 99.5th percentile of the labelled voxels (:func:`.figure.grey_window`);
    a colour bar shows it, a legend names the label colours shown (``names``: label → name, keys ints
    or strings, e.g. scan.json's ``labels``; ``label k`` where unnamed) and, with the
    :class:`~.volume.VolumeGeometry` ``grid``, a scale bar gives mm and each caption the slice's place.
    Small grids are enlarged by one nearest-neighbour factor (:func:`~.tiff.quicklook_factor`)."""
    volume, labels = np.asarray(volume), np.asarray(labels)
    window = figure.grey_window([(volume, labels)])
    factor = quicklook_factor(volume.shape)
    rows, shown = [], []
    for axis in range(3):
        middle = volume.shape[axis] // 2
        grey = np.repeat(figure.grey(np.take(volume, middle, axis=axis)[::-1], window)[..., None], 3, axis=-1)
        lab = np.take(labels, middle, axis=axis)[::-1]
        colour = figure.label_colours(lab)
        blend = np.round((1 - OVERLAY_ALPHA) * grey + OVERLAY_ALPHA * colour).astype(np.uint8)
        overlay = np.where((lab > 0)[..., None], blend, grey)
        rows.append((_AXES[axis], _slice_caption(axis, middle, volume.shape[axis], grid),
                     [figure.enlarge(p, factor) for p in (grey, colour, overlay)]))
        shown.append(lab)
    side = [("bar", "grey, cm⁻¹"), ("legend", "labels")]  # (part, title); _side drops an empty legend
    if grid is not None:
        vz, vy, vx = grid.voxel_size
        side.append(("scale", "along x" if not vy == vx == vz else ""))
    notes = (f"Central slices of the reconstruction (grey: linear attenuation in cm⁻¹ from {window[0]:.3g} to "
             f"{window[1]:.3g}, the 1st to the 99.5th percentile of the labelled voxels; values outside "
             f"clip), of the labels (air, 0, black) and of the two overlaid (labels at {OVERLAY_ALPHA:.0%}).")
    scale = grid.voxel_size[2] / factor if grid is not None else None
    return _compose(rows, SLICES_COLUMNS, window, _present(shown, names), side, scale, header=None, footer=notes)


def gallery_picture(samples) -> Picture:
    """One row per sample of ``samples``, (volume float32 (z, y, x) cm⁻¹, labels, label names,
    caption) tuples: the central z slice in grey and its labels in colour, under the caption. One
    grey window (:func:`.figure.grey_window` over every sample's labelled voxels) and one colour bar
    serve all rows, so their greys compare; the picture says so. One legend names the label colours
    shown, the names taken from the first sample naming each."""
    samples = [tuple(s) for s in samples]
    if not samples:
        raise ConfigError("a gallery needs at least one sample")
    window = figure.grey_window([(v, lab) for v, lab, _, _ in samples])
    rows, shown, names = [], [], {}
    for index, (volume, labels, named, caption) in enumerate(samples):
        middle = np.shape(volume)[0] // 2
        lab = np.asarray(labels[middle])[::-1]
        grey = np.repeat(figure.grey(np.asarray(volume[middle])[::-1], window)[..., None], 3, axis=-1)
        factor = max(1, -(-GALLERY_PX // max(lab.shape)))
        rows.append((str(index), str(caption), [figure.enlarge(p, factor) for p in (grey, figure.label_colours(lab))]))
        shown.append(lab)
        for key, name in (named or {}).items():
            names.setdefault(str(key), name)
    header = (f"The central z slice of {len(samples)} sample{'s' if len(samples) > 1 else ''}: the reconstruction "
              f"in one grey window for all of them, so their greys compare ({window[0]:.3g} to {window[1]:.3g} "
              f"cm⁻¹, the 1st to the 99.5th percentile of their labelled voxels), and the labels; +y up.")
    side = [("bar", "grey, cm⁻¹, all rows"), ("legend", "labels")]
    return _compose(rows, GALLERY_COLUMNS, window, _present(shown, names), side, None, header=header, footer=None)


def _slice_caption(axis: int, index: int, size: int, grid) -> str:
    """Which slice a row of slices.png is, and how its picture lies: ``central z slice: voxel z = 12
    of 24 (at z = +0.12 mm); x across, y up`` (the place in mm with a ``grid`` only)."""
    name = _AXES[axis]
    across, up = {0: ("x", "y"), 1: ("x", "z"), 2: ("y", "z")}[axis]
    at = ""
    if grid is not None:
        centre = (index - (size - 1) / 2) * grid.voxel_size[axis] + grid.offset[axis]
        at = f" (at {name} = {centre:+.2f} mm)"
    return f"central {name} slice: voxel {name} = {index} of {size}{at}; {across} across, {up} up"


def _present(slices, names) -> dict[int, str]:
    """The legend's entries: each label (not air) the pictures show, in order, with its name."""
    labels = np.unique(np.concatenate([np.unique(s) for s in slices]))
    return {int(k): figure.legend_entry(names, int(k)) for k in labels if k > 0}


def _compose(rows, columns, window, entries, side, mm_per_px, *, header, footer) -> Picture:
    """Lay out and draw a picture: an optional header; column titles; per row, its caption over
    its panels, each column as wide as its widest panel; beside the first row, the side parts
    (``side``: (part, title) pairs: ``bar``, ``legend``, ``scale``); an optional footer."""
    from PIL import Image, ImageDraw

    line = figure.line_px()
    widths = [max(r[2][c].shape[1] for r in rows) for c in range(len(columns))]
    lefts = [MARGIN + sum(widths[:c]) + GAP * c for c in range(len(columns))]
    captions = max(figure.text(None, (MARGIN, 0), r[1])[2] for r in rows)
    side_x = max(lefts[-1] + widths[-1], captions) + 3 * GAP  # the first row's caption runs beside the side parts
    first_panel = rows[0][2][0].shape[0]
    bar_px = max(4 * line, min(first_panel - 2 * line, 320))
    side_box = _side(None, (side_x, 0), side, window, entries, bar_px, mm_per_px)[0]
    width = side_box[2] + MARGIN
    head = figure.wrap(header, width - 2 * MARGIN) if header else []
    foot = figure.wrap(footer, width - 2 * MARGIN) if footer else []

    boxes: dict[str, Box] = {}
    y = MARGIN + len(head) * line + (GAP if head else 0)
    titles_y, y = y, y + figure.line_px(figure.TITLE_PX) + GAP
    places = []
    for key, caption, pictures in rows:
        places.append((key, caption, pictures, y))
        y += line + max(p.shape[0] for p in pictures) + 2 * GAP
    side_top = places[0][3]
    height = max(y, side_top + side_box[3]) + len(foot) * line + MARGIN

    canvas = Image.new("RGB", (width, height), figure.BACKGROUND)
    draw = ImageDraw.Draw(canvas)
    for number, words in enumerate(head):
        figure.text(draw, (MARGIN, MARGIN + number * line), words)
    for title, left in zip(columns, lefts):
        figure.text(draw, (left, titles_y), title, figure.TITLE_PX)
    for key, caption, pictures, top in places:
        figure.text(draw, (MARGIN, top), caption)
        for title, left, picture in zip(columns, lefts, pictures):
            canvas.paste(Image.fromarray(np.ascontiguousarray(picture)), (left, top + line))
            boxes[f"{key}/{title}"] = (left, top + line, left + picture.shape[1], top + line + picture.shape[0])
    boxes.update(_side(draw, (side_x, side_top), side, window, entries, bar_px, mm_per_px)[1])
    for number, words in enumerate(foot):
        figure.text(draw, (MARGIN, height - MARGIN - (len(foot) - number) * line), words)
    return Picture(np.asarray(canvas), window, boxes)


def _side(draw, xy, parts, window, entries, bar_px, mm_per_px) -> tuple[Box, dict[str, Box]]:
    """The parts beside the first row, top to bottom, each under its title: the colour bar, the
    legend, the scale bar. Returns (the box they cover, their boxes by name)."""
    x, y = xy
    line = figure.line_px()
    right, boxes = x, {}
    for part, title in parts:
        if part == "legend" and not entries:  # nothing labelled in the slices shown
            continue
        if part == "scale":
            covered, boxes["scale_bar"] = figure.scale_bar(draw, (x, y), mm_per_px, SCALE_BAR_PX, note=title)
        else:
            right = max(right, figure.text(draw, (x, y), title)[2])
            y += line
            if part == "bar":
                covered, boxes["colour_bar"] = figure.colour_bar(draw, (x, y), bar_px, window)
            else:
                covered, swatches = figure.legend(draw, (x, y), entries)
                boxes["legend"] = covered
                boxes.update({f"legend/{label}": box for label, box in swatches.items()})
        right, y = max(right, covered[2]), covered[3] + line
    return (xy[0], xy[1], right, y), boxes


def _write(path, picture: Picture) -> Path:
    from PIL import Image

    image = Image.fromarray(picture.image)
    info = png_text(grey_window=f"{picture.window[0]:.6g} {picture.window[1]:.6g} 1/cm")
    return atomic_write(Path(path), lambda tmp: image.save(tmp, format="PNG", pnginfo=info))
