"""A fast decoder of the PNG layout radar scans use: 8-bit grayscale, not interlaced.

Decoding a radar scan PNG is dominated by inflating its zlib stream; libdeflate (the `deflate`
package) inflates about twice as fast as zlib, which OpenCV's libpng uses, and the PNG row
filters are undone in one compiled pass (numba; like libdeflate it releases the GIL, so a reader
thread decodes in parallel). The result is byte for byte the image OpenCV decodes.

`decode_gray8` reads only that layout and only well-formed files: any other PNG (16-bit, colour,
palette, interlaced) and anything it finds wrong (a bad chunk CRC, a truncated stream, no IEND)
returns None, and the caller decodes the file with OpenCV instead, which also words the errors
of corrupt files.
"""

from __future__ import annotations

import struct

import deflate
import numba
import numpy as np
from numpy.typing import NDArray

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
CHUNK_HEAD = struct.Struct(">I4s")  # length, type
CHUNK_CRC = struct.Struct(">I")
IHDR = struct.Struct(">IIBBBBB")  # width, height, bit depth, colour type, compression, filter,
# interlace
GRAY = 0
BIT_DEPTH_8 = 8
ANCILLARY_BIT = 0x20  # bit 5 of a chunk type's first byte: ancillary (skippable) chunk
MAX_PIXELS = 1 << 30
"""Largest image decoded here (OpenCV's default limit, CV_IO_MAX_IMAGE_PIXELS)."""
MAX_DEFLATE_RATIO = 1032
"""Deflate expands its input at most about 1032-fold: a header promising more is damaged."""


def decode_gray8(data: bytes) -> NDArray[np.uint8] | None:
    """The (height, width) uint8 image of an 8-bit grayscale, non-interlaced PNG file's bytes.

    Returns None for any other PNG and for a file with a damaged critical chunk (bad CRC,
    truncated, unknown critical chunk, no IEND) or a damaged image stream; ancillary chunks are
    skipped as libpng skips them.
    """
    parsed = _parse_chunks(data)
    if parsed is None:
        return None
    (width, height), stream = parsed
    expected = (width + 1) * height  # one filter-type byte per row
    if width * height > MAX_PIXELS or expected > MAX_DEFLATE_RATIO * len(stream):
        return None  # no huge allocation for a damaged header: OpenCV decides
    try:
        raw = deflate.zlib_decompress(stream, expected)
    except deflate.DeflateError:
        return None
    if len(raw) != expected:
        return None
    image = np.empty((height, width), dtype=np.uint8)
    filtered = np.frombuffer(raw, dtype=np.uint8).reshape(height, width + 1)
    if not _unfilter(filtered, image):
        return None
    return image


def _parse_chunks(data: bytes) -> tuple[tuple[int, int], bytes] | None:
    """((width, height), the concatenated IDAT data) of a supported, well-formed PNG, or None."""
    if not data.startswith(PNG_SIGNATURE):
        return None
    view = memoryview(data)
    pos = len(PNG_SIGNATURE)
    size: tuple[int, int] | None = None
    stream: list[memoryview] = []
    while pos + CHUNK_HEAD.size + CHUNK_CRC.size <= len(data):
        length, kind = CHUNK_HEAD.unpack_from(data, pos)
        body_start = pos + CHUNK_HEAD.size
        body_end = body_start + length
        if body_end + CHUNK_CRC.size > len(data):
            return None
        pos = body_end + CHUNK_CRC.size
        if kind[0] & ANCILLARY_BIT:
            continue
        (crc,) = CHUNK_CRC.unpack_from(data, body_end)
        if deflate.crc32(view[body_start:body_end], deflate.crc32(kind)) != crc:
            return None
        if kind == b"IHDR":
            size = _supported_size(view[body_start:body_end])
            if size is None:
                return None
        elif kind == b"IDAT" and size is not None:
            stream.append(view[body_start:body_end])
        elif kind == b"IEND":
            return (size, b"".join(stream)) if size is not None and stream else None
        else:
            return None  # PLTE, an unknown critical chunk, or IDAT before IHDR
    return None  # no IEND: truncated


def _supported_size(header: memoryview) -> tuple[int, int] | None:
    """(width, height) when the IHDR body describes an 8-bit grayscale, non-interlaced image."""
    if len(header) != IHDR.size:
        return None
    width, height, depth, colour, compression, filtering, interlace = IHDR.unpack(header)
    if (depth, colour, compression, filtering, interlace) != (BIT_DEPTH_8, GRAY, 0, 0, 0):
        return None
    if width == 0 or height == 0:
        return None
    return int(width), int(height)


@numba.njit(nogil=True, cache=True)
def _unfilter(filtered, image):  # type: ignore[no-untyped-def]
    """Undo the PNG row filters (one byte per pixel) of (h, w + 1) `filtered` into (h, w)
    `image`; False on an unknown filter type. Types: 0 none, 1 sub, 2 up, 3 average, 4 Paeth;
    the row above the first and the pixel left of the first column count as 0."""
    height, width = image.shape
    above = np.zeros(width, dtype=np.int32)
    for r in range(height):
        kind = filtered[r, 0]
        row = filtered[r, 1:]
        out = image[r]
        if kind == 0:
            for c in range(width):
                out[c] = row[c]
        elif kind == 1:
            left = np.int32(0)
            for c in range(width):
                left = (np.int32(row[c]) + left) & 0xFF
                out[c] = left
        elif kind == 2:
            for c in range(width):
                out[c] = (np.int32(row[c]) + above[c]) & 0xFF
        elif kind == 3:
            left = np.int32(0)
            for c in range(width):
                left = (np.int32(row[c]) + ((left + above[c]) >> 1)) & 0xFF
                out[c] = left
        elif kind == 4:
            left = np.int32(0)
            up_left = np.int32(0)
            for c in range(width):
                up = above[c]
                p = left + up - up_left
                pa = abs(p - left)
                pb = abs(p - up)
                pc = abs(p - up_left)
                if pa <= pb and pa <= pc:
                    predicted = left
                elif pb <= pc:
                    predicted = up
                else:
                    predicted = up_left
                left = (np.int32(row[c]) + predicted) & 0xFF
                up_left = up
                out[c] = left
        else:
            return False
        for c in range(width):
            above[c] = out[c]
    return True
