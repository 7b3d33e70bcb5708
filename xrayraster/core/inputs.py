"""The files a user gives a command, checked before their format is parsed: one place that says
what is wrong with a path (missing, a directory, unreadable) or with a text file's bytes (binary,
not UTF-8), in one line naming the file, so every reader fails the same way (exit status 2).
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import ConfigError
from .tiff import read_tiff

# Bytes no text file holds: a NUL says binary even when the rest happens to decode as UTF-8.
BINARY_MARK = b"\x00"


def check_input_file(path, what: str, error: type[Exception] = ConfigError) -> Path:
    """``path`` as a Path if it names a regular file this process can read; else ``error`` with one
    line: ``{what} {path}: <what is wrong>; <the fix>``. ``what`` names the file's role ("scene file")."""
    path = Path(path)
    if not path.exists():
        raise error(f"{what} {path}: no such file; check the path")
    if path.is_dir():
        raise error(f"{what} {path}: is a directory, not a file; give the path of a file")
    if not path.is_file():
        raise error(f"{what} {path}: is not a regular file (a device or pipe); give the path of a file")
    if not os.access(path, os.R_OK):
        raise error(f"{what} {path}: cannot be read (permission denied); make it readable (chmod u+r)")
    return path


def read_text_file(path, what: str, error: type[Exception] = ConfigError) -> str:
    """The text of the user's file ``path``, decoded as UTF-8; a leading byte-order mark (as some
    Windows editors write) is dropped. A path :func:`check_input_file` refuses, a binary file or
    text in another encoding (latin-1) is ``error`` naming the file, in one line."""
    return decode_text(read_file_bytes(path, what, error), path, what, error)


def read_file_bytes(path, what: str, error: type[Exception] = ConfigError) -> bytes:
    """The bytes of the user's file ``path``: a path :func:`check_input_file` refuses, or a read that
    fails (raced away, an I/O error), is ``error`` naming the file."""
    path = check_input_file(path, what, error)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise error(f"{what} {path}: cannot be read ({exc.strerror or exc})") from None


def decode_text(data: bytes, path, what: str, error: type[Exception] = ConfigError) -> str:
    """``data``, the bytes of the user's file ``path``, as UTF-8 text (a byte-order mark dropped);
    a binary file or text in another encoding is ``error`` naming the file and the byte at fault."""
    if BINARY_MARK in data:
        raise error(f"{what} {path}: is a binary file, not text; give the {what} itself (UTF-8 text)")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{what} {path}: is not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}); "
                    "save it as UTF-8") from None


def read_tiff_file(path, what: str, error: type[Exception] = ConfigError):
    """(array, JSON info) of the user's TIFF ``path`` (:func:`~xrayraster.core.tiff.read_tiff`); a path
    :func:`check_input_file` refuses, or a file tifffile cannot parse, is ``error`` naming it."""
    path = check_input_file(path, what, error)
    try:
        return read_tiff(path)
    except (OSError, ValueError) as exc:  # tifffile's TiffFileError is a ValueError
        reason = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        raise error(f"{what} {path}: cannot be read as a TIFF ({reason}); give a TIFF stack") from None
