"""A frame as one binary WebSocket message the page decodes (``static/preview.js``, ``decodeFrame``).

Layout, little-endian: a uint32 header length, the header (UTF-8 JSON: ``id``, ``shape``,
``lo``, ``hi``, ``quantity``, ``unit``, ``angle_deg``, ``seconds``, ``stats``, ``layout``), spaces up to an
even offset, then rows × cols uint16 levels. Level q stands for ``lo + q · (hi − lo) / 65535``:
a float32 frame at half the bytes, off by at most (hi − lo) / 131070 (a 512² frame is 512 KiB,
not 1 MiB, for a page behind an SSH tunnel). The page applies window and level itself, so moving
them costs no round trip.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from .frames import Frame

LEVELS = 65535


def quantized(image: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``image``'s levels (uint16) and the range ``lo``, ``hi`` they span (non-finite values at ``lo``)."""
    values = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    lo, hi = float(values.min()), float(values.max())
    scale = LEVELS / (hi - lo) if hi > lo else 0.0
    return np.rint((values - lo) * scale).astype("<u2"), lo, hi


def encode(frame: Frame, request_id: int, extra: dict | None = None) -> bytes:
    levels, lo, hi = quantized(frame.image)
    image = frame.image
    header = {
        "id": request_id, "shape": list(image.shape), "lo": lo, "hi": hi, "quantity": frame.quantity,
        "unit": frame.unit, "angle_deg": frame.angle_deg, "seconds": frame.seconds,
        "stats": {"min": float(image.min()), "max": float(image.max()), "mean": float(image.mean())},
        "layout": frame.layout,
        **(extra or {}),
    }
    text = json.dumps(header).encode()
    text += b" " * ((4 + len(text)) % 2)  # the levels start at an even offset (a Uint16Array view)
    return struct.pack("<I", len(text)) + text + levels.tobytes()


def decode(message: bytes) -> tuple[dict, np.ndarray]:
    """The header and the float64 values of an :func:`encode`\\ d frame (what the page computes)."""
    (length,) = struct.unpack_from("<I", message)
    header = json.loads(message[4:4 + length])
    levels = np.frombuffer(message, "<u2", offset=4 + length).reshape(header["shape"])
    return header, header["lo"] + levels * ((header["hi"] - header["lo"]) / LEVELS)
