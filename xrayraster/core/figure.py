"""The parts the pictures of :mod:`.pictures` are drawn from: text (cm⁻¹ with a real superscript),
the grey window of reconstructions and its colour bar, the label palette and its legend, and a
scale bar.

A part is one function ``part(draw, xy, ...)``: it draws onto PIL's ``ImageDraw`` with its
top-left corner at ``xy`` and returns the box it covers, (x0, y0, x1, y1) with exclusive ends.
Given ``draw=None`` it only measures, so a picture plans its layout with the code that draws it.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from .tiff import scale_bar_length

Box = tuple[int, int, int, int]

# Label colours (RGB), label k taking entry (k - 1) mod len: matrix, weft, warp first. Blue, orange
# and dark red differ in lightness as well as hue, so they stay apart for colour-blind readers and
# at the overlay's 35 % over grey (simulated protan, deutan and tritan vision: the three at least
# 129 RGB units apart, 54 in the overlay; a purple warp came within 62 and 19 of the blue).
PALETTE = np.array([(70, 110, 220), (240, 165, 20), (180, 30, 60), (60, 185, 90), (110, 215, 235), (150, 90, 40)],
                   dtype=np.uint8)
BACKGROUND = (44, 44, 44)  # not black: the panels' air is black, and their edges must show
INK = (235, 235, 235)
TEXT_PX = 22
TITLE_PX = 27  # column titles: larger than the rows' captions under them
WINDOW_PERCENTILES = (1.0, 99.5)  # of the labelled voxels: matrix and yarns differ visibly, air is black
BAR_PX = 22  # the colour bar's width
_TICK_PX = 6
_SUPERSCRIPTS = {"⁻": "-", "¹": "1", "²": "2", "³": "3"}  # the bundled font has none of them
_SUPERSCRIPT_SHARE = 0.65  # a superscript's size, of the text's


@lru_cache(maxsize=None)
def font(px: int):
    """Pillow's bundled font at ``px`` pixels: the same glyphs on every machine, so a picture is the
    same bytes everywhere (a system font would differ from machine to machine)."""
    from PIL import ImageFont

    return ImageFont.load_default(size=px)


def line_px(px: int = TEXT_PX) -> int:
    """The height of a line of text of size ``px``, with its spacing."""
    return round(px * 1.4)


def text(draw, xy, words: str, px: int = TEXT_PX, fill=INK) -> Box:
    """``words`` with their top-left corner at ``xy``; ⁻¹ (and ², ³) drawn small and raised."""
    x, y = xy
    for chunk, raised in _runs(words):
        size = round(px * _SUPERSCRIPT_SHARE) if raised else px
        if draw is not None:
            draw.text((x, y - (round(px * 0.12) if raised else 0)), chunk, font=font(size), fill=fill)
        x += math.ceil(font(size).getlength(chunk))
    return xy[0], y, x, y + line_px(px)


def wrap(words: str, width: int, px: int = TEXT_PX) -> list[str]:
    """``words`` cut at spaces into lines no wider than ``width`` (a longer word keeps its own line)."""
    lines: list[str] = []
    for word in words.split():
        if lines and text(None, (0, 0), f"{lines[-1]} {word}", px)[2] <= width:
            lines[-1] += f" {word}"
        else:
            lines.append(word)
    return lines


def _runs(words: str) -> list[tuple[str, bool]]:
    """``words`` cut into (characters, raised) runs, superscripts spelt in plain characters."""
    runs: list[tuple[str, bool]] = []
    for character in words:
        raised = character in _SUPERSCRIPTS
        plain = _SUPERSCRIPTS.get(character, character)
        if runs and runs[-1][1] == raised:
            runs[-1] = (runs[-1][0] + plain, raised)
        else:
            runs.append((plain, raised))
    return runs


def grey_window(pairs) -> tuple[float, float]:
    """The grey window (cm⁻¹) of (volume, labels) pairs: the 1st and 99.5th percentiles of their
    labelled voxels together (every voxel's, where none is labelled), so pictures drawn with it
    compare. The labelled voxels of every 2nd plane and row set it: a quarter of the copy, and the
    same window within a grey level of 255 (measured: 0.2 on the twin, 1.0 on its small version).
    A window of one value is widened to that value ± its size (± 1 at 0)."""
    pairs = [(np.asarray(v), np.asarray(lab)) for v, lab in pairs]
    pooled = np.concatenate([v[::2, ::2][lab[::2, ::2] > 0] for v, lab in pairs])
    if not pooled.size:
        pooled = np.concatenate([v[::2, ::2].ravel() for v, _ in pairs])
    low, high = (float(v) for v in np.percentile(pooled, WINDOW_PERCENTILES))
    if high > low:
        return low, high
    half = abs(low) or 1.0
    return low - half, low + half


def grey(image: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """``image`` (cm⁻¹) as grey levels 0 to 255 over ``window``, clipped outside it."""
    low, high = window
    return np.round(255 * np.clip((image - low) / (high - low), 0.0, 1.0)).astype(np.uint8)


def label_colours(labels: np.ndarray) -> np.ndarray:
    """(rows, cols, 3) uint8: each label's palette colour, air (0) black."""
    labels = np.asarray(labels, dtype=np.int64)
    return np.where((labels > 0)[..., None], PALETTE[(labels - 1) % len(PALETTE)], 0).astype(np.uint8)


def legend_entry(names, label: int) -> str:
    """``label`` and its name in ``names`` (keys ints or strings, as scan.json's ``labels``): ``1 matrix``;
    ``label 4`` when unnamed."""
    name = (names or {}).get(label, (names or {}).get(str(label)))
    return f"label {label}" if name is None else f"{label} {name}"


def enlarge(picture: np.ndarray, factor: int) -> np.ndarray:
    """Every pixel of ``picture`` a ``factor`` × ``factor`` block (nearest neighbour)."""
    return np.repeat(np.repeat(picture, factor, axis=0), factor, axis=1)


def colour_bar(draw, xy, height: int, window: tuple[float, float], px: int = TEXT_PX) -> tuple[Box, Box]:
    """A vertical grey bar, ``window``'s high end at the top, with ticks labelled in cm⁻¹: the two
    ends (3 significant digits) and round values between them. Returns (the box it covers, the
    bar's own box, whose pixels are the grey levels and nothing else)."""
    x, y = xy
    low, high = window
    half = line_px(px) // 2  # the end labels reach half a line beyond the bar
    bar = (x + 1, y + half + 1, x + 1 + BAR_PX, y + half + 1 + height)  # inside a 1-pixel frame
    if draw is not None:
        values = high - (np.arange(height) + 0.5) / height * (high - low)  # each row's centre
        for row, level in enumerate(grey(values, window).tolist()):
            draw.line([(bar[0], bar[1] + row), (bar[2] - 1, bar[1] + row)], fill=(level,) * 3)
        draw.rectangle([x, bar[1] - 1, bar[2], bar[3]], outline=INK)
    right = bar[2] + 1
    for value, label in bar_ticks(window, height, px):
        at = bar[1] + round((high - value) / (high - low) * (height - 1))
        if draw is not None:
            draw.line([(bar[2] + 1, at), (bar[2] + _TICK_PX, at)], fill=INK)
        right = max(right, text(draw, (bar[2] + _TICK_PX + 4, at - half), label, px)[2])
    return (x, y, right, bar[3] + 1 + half), bar


def bar_ticks(window: tuple[float, float], height: int, px: int = TEXT_PX) -> list[tuple[float, str]]:
    """(value, label) of the colour bar's ticks, low to high: the window's ends and the multiples of
    a round step (1, 2 or 5 × 10^k, about 4 to a bar) a line's height or more away from both."""
    low, high = window
    raw = (high - low) / 4
    power = 10.0 ** math.floor(math.log10(raw))
    step = min((m * power for m in (1, 2, 5, 10) if m * power >= raw), default=10 * power)
    digits = max(0, -math.floor(math.log10(step)))
    room = line_px(px) / height * (high - low)  # a line's height, in cm⁻¹
    inner = [k * step for k in range(math.ceil(low / step), math.floor(high / step) + 1)]
    kept = [(v, f"{v:.{digits}f}") for v in inner if v - low >= room and high - v >= room]
    return [(low, f"{low:.3g}"), *kept, (high, f"{high:.3g}")]


def legend(draw, xy, entries: dict[int, str], px: int = TEXT_PX) -> tuple[Box, dict[int, Box]]:
    """One line per label of ``entries`` (label → its text, in order): its colour's swatch and the
    text. Returns (the box it covers, label → its swatch's box, whose pixels are its colour)."""
    x, y = xy
    swatches, right = {}, x
    for label, entry in entries.items():
        swatch = (x + 1, y + 3, x + 1 + px, y + 3 + px)  # inside a 1-pixel frame
        if draw is not None:
            draw.rectangle([x, swatch[1] - 1, swatch[2], swatch[3]], outline=INK)
            colour = PALETTE[(label - 1) % len(PALETTE)]
            draw.rectangle([swatch[0], swatch[1], swatch[2] - 1, swatch[3] - 1], fill=tuple(int(c) for c in colour))
        swatches[label] = swatch
        right = max(right, text(draw, (swatch[2] + 8, y), entry, px)[2])
        y += max(line_px(px), px + 8)
    return (x, xy[1], right, y), swatches


def scale_bar(draw, xy, mm_per_px: float, max_px: float, px: int = TEXT_PX, note: str = "") -> tuple[Box, Box]:
    """A horizontal bar of a round length in mm (at most ``max_px`` long) labelled with its length
    and ``note``. Returns (the box it covers, the bar's box)."""
    length, bar_px = scale_bar_length(mm_per_px, max_px)
    x, y = xy
    middle = y + line_px(px) // 2
    bar = (x, middle - 2, x + bar_px, middle + 2)
    if draw is not None:
        draw.rectangle([bar[0], bar[1], bar[2] - 1, bar[3] - 1], fill=INK)
    label = text(draw, (bar[2] + 8, y), f"{length:g} mm" + (f" {note}" if note else ""), px)
    return (x, y, label[2], label[3]), bar
