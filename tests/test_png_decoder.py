"""The fast 8-bit grayscale PNG decoder against libpng (OpenCV) on every filter type and layout."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from radar_slam.datasets._io import read_gray_png, transposed
from radar_slam.datasets._png import PNG_SIGNATURE, decode_gray8
from radar_slam.errors import DatasetFormatError


def chunk(kind: bytes, body: bytes) -> bytes:
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))


def paeth(a: NDArray[np.int32], b: NDArray[np.int32], c: NDArray[np.int32]) -> NDArray[np.int32]:
    p = a + b - c
    pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
    return np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))


def filtered_rows(image: NDArray[np.uint8], kinds: list[int]) -> bytes:
    """The PNG scanlines of `image`, row i filtered with type kinds[i] (PNG specification)."""
    x = image.astype(np.int32)
    above = np.vstack([np.zeros((1, x.shape[1]), np.int32), x[:-1]])
    left = np.hstack([np.zeros((x.shape[0], 1), np.int32), x[:, :-1]])
    up_left = np.hstack([np.zeros((x.shape[0], 1), np.int32), above[:, :-1]])
    predictions = [0 * x, left, above, (left + above) // 2, paeth(left, above, up_left)]
    rows = [
        bytes([kind]) + ((x[i] - predictions[kind][i]) % 256).astype(np.uint8).tobytes()
        for i, kind in enumerate(kinds)
    ]
    return b"".join(rows)


def png_bytes(
    image: NDArray[np.uint8],
    kinds: list[int],
    idat_parts: int = 1,
    extra: bytes = b"",
    depth: int = 8,
    colour: int = 0,
) -> bytes:
    height, width = image.shape
    stream = zlib.compress(filtered_rows(image, kinds))
    step = -(-len(stream) // idat_parts)
    idats = b"".join(chunk(b"IDAT", stream[i : i + step]) for i in range(0, len(stream), step))
    header = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return PNG_SIGNATURE + chunk(b"IHDR", header) + extra + idats + chunk(b"IEND", b"")


def libpng(data: bytes) -> NDArray[np.uint8] | None:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)


@pytest.fixture
def image() -> NDArray[np.uint8]:
    rng = np.random.default_rng(3)
    smooth = np.add.outer(np.arange(37) * 7, np.arange(23) * 11) % 256
    noisy = smooth + rng.integers(0, 40, smooth.shape)
    noisy[5] = 255  # saturated and empty rows exercise the wrap-around of every filter
    noisy[6] = 0
    return (noisy % 256).astype(np.uint8)


@pytest.mark.parametrize("kind", [0, 1, 2, 3, 4])
def test_each_filter_type_decodes_like_libpng(image: NDArray[np.uint8], kind: int) -> None:
    data = png_bytes(image, [kind] * image.shape[0])
    decoded = decode_gray8(data)
    assert decoded is not None
    np.testing.assert_array_equal(decoded, image)
    np.testing.assert_array_equal(decoded, libpng(data))


def test_mixed_filters_split_stream_and_ancillary_chunks(image: NDArray[np.uint8]) -> None:
    kinds = [i % 5 for i in range(image.shape[0])]
    text = chunk(b"tEXt", b"Comment\x00radar")
    data = png_bytes(image, kinds, idat_parts=4, extra=text)
    decoded = decode_gray8(data)
    assert decoded is not None and decoded.dtype == np.uint8
    np.testing.assert_array_equal(decoded, image)
    np.testing.assert_array_equal(decoded, libpng(data))


def test_opencv_written_png_decodes_identically(image: NDArray[np.uint8]) -> None:
    ok, encoded = cv2.imencode(".png", np.tile(image, (4, 9)))
    assert ok
    decoded = decode_gray8(encoded.tobytes())
    assert decoded is not None
    np.testing.assert_array_equal(decoded, libpng(encoded.tobytes()))


def test_other_layouts_are_left_to_opencv(image: NDArray[np.uint8]) -> None:
    assert decode_gray8(cv2.imencode(".png", image.astype(np.uint16) * 200)[1].tobytes()) is None
    colour = cv2.imencode(".png", np.dstack([image] * 3))[1].tobytes()
    assert decode_gray8(colour) is None
    assert decode_gray8(b"not a png at all") is None


def test_damaged_files_are_left_to_opencv(image: NDArray[np.uint8]) -> None:
    data = png_bytes(image, [1] * image.shape[0])
    idat = data.index(b"IDAT") + 4
    flipped = data[:idat] + bytes([data[idat] ^ 0xFF]) + data[idat + 1 :]
    assert decode_gray8(flipped) is None  # CRC mismatch
    assert decode_gray8(data[: len(data) // 2]) is None  # truncated
    assert decode_gray8(data[: -len(chunk(b"IEND", b""))]) is None  # no IEND
    rows = bytearray(filtered_rows(image, [1] * image.shape[0]))
    rows[0] = 7  # no such filter type, with valid CRCs
    header = struct.pack(">IIBBBBB", image.shape[1], image.shape[0], 8, 0, 0, 0, 0)
    bad_filter = (
        PNG_SIGNATURE
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(bytes(rows)))
        + chunk(b"IEND", b"")
    )
    assert decode_gray8(bad_filter) is None
    huge = struct.pack(">IIBBBBB", 1 << 20, 1 << 20, 8, 0, 0, 0, 0)  # 1 TB for a tiny stream
    tiny = chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + chunk(b"IEND", b"")
    assert decode_gray8(PNG_SIGNATURE + chunk(b"IHDR", huge) + tiny) is None
    short_stream = PNG_SIGNATURE + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\x00"))
    assert decode_gray8(short_stream + chunk(b"IEND", b"")) is None


def test_reader_messages_unchanged_for_damaged_and_16_bit_files(
    tmp_path: Path, image: NDArray[np.uint8]
) -> None:
    good = tmp_path / "1.png"
    good.write_bytes(png_bytes(image, [4] * image.shape[0]))
    np.testing.assert_array_equal(read_gray_png(good, image.shape), image)
    truncated = tmp_path / "2.png"
    truncated.write_bytes(good.read_bytes()[:200])
    with pytest.raises(DatasetFormatError, match="cannot decode PNG"):
        read_gray_png(truncated, None)
    deep = tmp_path / "3.png"
    cv2.imwrite(str(deep), image.astype(np.uint16) * 200)
    with pytest.raises(DatasetFormatError, match="expected an 8-bit single-channel PNG"):
        read_gray_png(deep, None)


def test_transposed_is_a_contiguous_copy_of_the_transpose(image: NDArray[np.uint8]) -> None:
    turned = transposed(image[:, 3:])  # a non-contiguous view too
    np.testing.assert_array_equal(turned, image[:, 3:].T)
    assert turned.flags.c_contiguous and turned.dtype == np.uint8
