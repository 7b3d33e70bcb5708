"""A frame as one binary WebSocket message the page decodes (``static/preview.js``, ``decodeFrame``).

Layout, little-endian: a uint32 header length, the header (UTF-8 JSON: ``id``, ``shape``,
``lo``, ``hi``, ``quantity``, ``unit``, ``angle_deg``, ``seconds``, ``layout``, ``binning`` (1: the
full frame; b: a reduced one, the detector binned b × b) and ``full_shape``), spaces up to an even
offset, then rows × cols uint16 levels. Level q stands for ``lo + q · (hi − lo) / 65535``:
a float32 frame at half the bytes, off by at most (hi − lo) / 131070 (a 512² frame is 512 KiB,
not 1 MiB, for a page behind an SSH tunnel). The page applies window and level itself, so moving
them costs no round trip.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from ..core.figure import PALETTE
from .frames import Frame
from .quick_slice import QuickSlice

LEVELS = 65535


def quantized(image: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``image``'s levels (uint16) and the range ``lo``, ``hi`` they span (non-finite values at ``lo``)."""
    values = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    lo, hi = float(values.min()), float(values.max())
    scale = LEVELS / (hi - lo) if hi > lo else 0.0
    return np.rint((values - lo) * scale).astype("<u2"), lo, hi


def encode(frame: Frame, request_id: int, extra: dict | None = None) -> bytes:
    return _packed(frame.image, {
        "id": request_id, "quantity": frame.quantity, "unit": frame.unit, "angle_deg": frame.angle_deg,
        "seconds": frame.seconds, "layout": frame.layout, "binning": frame.binning,
        "full_shape": list(frame.full_shape or frame.image.shape), **(extra or {}),
    })


def encode_slice(cut: QuickSlice) -> bytes:
    """A quick slice as a frame (cm⁻¹) whose levels are followed by its labels, one uint16 a voxel;
    the header names the labels and gives the label colours of a scan's ``slices.png``."""
    header = {"quantity": "attenuation", "unit": "1/cm", "names": {str(k): v for k, v in cut.names.items()},
              "z_mm": cut.z_mm, "views": cut.views, "detector_shape": list(cut.detector_shape),
              "voxel_mm": cut.voxel_mm, "seconds": cut.seconds, "palette": PALETTE.tolist()}
    return _packed(cut.image, header) + cut.labels.astype("<u2").tobytes()


def _packed(image: np.ndarray, header: dict) -> bytes:
    levels, lo, hi = quantized(image)
    text = json.dumps({**header, "shape": list(image.shape), "lo": lo, "hi": hi}).encode()
    text += b" " * ((4 + len(text)) % 2)  # the levels start at an even offset (a Uint16Array view)
    return struct.pack("<I", len(text)) + text + levels.tobytes()


def decode(message: bytes) -> tuple[dict, np.ndarray]:
    """The header and the float64 values of an :func:`encode`\\ d frame (what the page computes);
    an :func:`encode_slice`\\ d slice's labels follow the values as ``header["labels"]``."""
    (length,) = struct.unpack_from("<I", message)
    header = json.loads(message[4:4 + length])
    count = int(np.prod(header["shape"]))
    words = np.frombuffer(message, "<u2", offset=4 + length)
    if len(words) > count:
        header["labels"] = words[count:].reshape(header["shape"])
    return header, header["lo"] + words[:count].reshape(header["shape"]) * ((header["hi"] - header["lo"]) / LEVELS)
