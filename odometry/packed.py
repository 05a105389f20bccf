"""Packed real 2-D spectra: OpenCV's CCS layout, the cheapest spectra of real images.

The DFT of a real (H, W) image (H, W even) is Hermitian, so H * W real numbers hold it. OpenCV's
`cv2.dft` packs them into a (H, W) float32 array ("CCS"): columns 1 .. W - 2 hold (Re, Im) pairs
of the frequencies k_c = 1 .. W / 2 - 1 for every row frequency; column 0 (k_c = 0) and column
W - 1 (k_c = W / 2) hold the real values of k_r = 0 (row 0) and k_r = H / 2 (row H - 1) and the
(Re, Im) pairs of k_r = 1 .. H / 2 - 1 in rows (2 k_r - 1, 2 k_r). Computing and inverting a packed
spectrum writes half the memory of a complex one; `pack` converts from the half spectrum of
`numpy.fft.rfft2` ((H, W // 2 + 1) complex).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

PackedSpectrum = NDArray[np.float32]


def forward(image: NDArray[np.float32]) -> PackedSpectrum:
    """Packed spectrum (H, W) float32 of a real (H, W) float32 image (H, W even, >= 4)."""
    shape = image.shape
    if len(shape) != 2 or shape[0] % 2 or shape[1] % 2 or min(shape) < 4:
        raise ValueError(f"packed spectra need a 2-D image with even sides >= 4, got {shape}")
    return np.asarray(cv2.dft(np.ascontiguousarray(image, dtype=np.float32)), dtype=np.float32)


def inverse(packed: PackedSpectrum) -> NDArray[np.float32]:
    """The real image (H, W) float32 of a packed spectrum, unscaled (H * W times the image
    whose `forward` it is: fold 1 / (H W) into a weight applied before)."""
    return np.asarray(cv2.idft(packed, flags=cv2.DFT_REAL_OUTPUT), dtype=np.float32)


def pack(half: NDArray[np.complexfloating]) -> PackedSpectrum:
    """The packed spectrum (H, W) of a half spectrum (H, W // 2 + 1) of a real image; the
    imaginary parts at the four real positions are dropped."""
    h, w = half.shape[0], 2 * (half.shape[1] - 1)
    out = np.empty((h, w), dtype=np.float32)
    out[:, 1 : w - 1 : 2] = half[:, 1 : w // 2].real
    out[:, 2 : w - 1 : 2] = half[:, 1 : w // 2].imag
    for col, k in ((0, 0), (w - 1, w // 2)):
        column = half[:, k]
        out[0, col] = column[0].real
        out[1 : h - 1 : 2, col] = column[1 : h // 2].real
        out[2 : h - 1 : 2, col] = column[1 : h // 2].imag
        out[h - 1, col] = column[h // 2].real
    return out


def forward_rows(image: NDArray[np.float32]) -> PackedSpectrum:
    """Packed spectra (rows, n) float32 of every row of a real (rows, n) float32 image: per row
    Re(0), then (Re, Im) pairs of the frequencies 1 .. (n - 1) // 2, then Re(n / 2) when n is
    even (OpenCV's 1-D CCS layout)."""
    image = np.ascontiguousarray(image, dtype=np.float32)
    return np.asarray(cv2.dft(image, flags=cv2.DFT_ROWS), dtype=np.float32)
