"""Sinogram spectra and the translation-invariant RaPlace descriptor.

Fourier slice theorem: the DFT along l of the Radon sinogram row S(theta, .) equals the 2-D
Fourier transform F of the image along the radial line k (cos theta, sin theta). So the
descriptor |S^(theta, k)| is sampled directly from one 2-D FFT of the Cartesian image, without
computing the Radon transform.

Frames and units. The Cartesian image follows raplace.warp (sensor at the centre, +x forward up,
+y left to the left, `cell_m` pixels). Angles theta are counter-clockwise from +x in the sensor
frame; l = x cos theta + y sin theta [m]; frequencies k are along l [cycles per metre]. With the
image content rotated by a and translated by t,
    S_q(theta, l) = S_m(theta - a, l - t . (cos theta, sin theta)),
so the magnitude |S^(theta, k)| ignores t and shifts along theta by a. Since
S(theta + pi, l) = S(theta, -l), |S^| repeats every pi: the descriptor covers theta in [0, pi).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import scipy.fft
from numpy.typing import NDArray

from raplace import RaPlaceError
from raplace.config import DescriptorConfig, MagnitudeTransform
from raplace.preprocess import CartesianImager

Z_NORMALISE_EPS = 1e-12
"""Guard for the standard deviation of a constant (empty) descriptor."""


@dataclass(frozen=True)
class ImageSpectrum:
    """The 2-D DFT of a zero-padded Cartesian image, ready for radial interpolation.

    Attributes:
        grid: (size, size, 2) float32 real and imaginary parts, zero frequency at
            [size // 2, size // 2]; axis 0 is the frequency along x, axis 1 along y (both
            increasing with the index).
        cell_m: pixel size of the image [m]; the grid spacing is 1 / (size * cell_m) cycles/m.
    """

    grid: NDArray[np.float32]
    cell_m: float

    @property
    def size(self) -> int:
        return int(self.grid.shape[0])

    @property
    def freq_step_cpm(self) -> float:
        """Spacing of the frequency grid [cycles per metre]."""
        return 1.0 / (self.size * self.cell_m)


def image_spectrum(cart: NDArray, cell_m: float, pad_factor: int = 2) -> ImageSpectrum:
    """2-D DFT of a Cartesian image zero-padded to `pad_factor` times its side.

    Args:
        cart: (n, n) image, n even, in the raplace.warp convention.
        cell_m: pixel size [m].
        pad_factor: integer >= 1.

    The image is flipped so that indices increase with x and y, and rolled so that the pixel at
    x = y = +cell_m / 2 sits at index 0 (the sensor is half a pixel before it); the remaining
    half-pixel phase is applied in `radial_spectrum`.
    """
    cart = np.asarray(cart, dtype=np.float32)
    n = cart.shape[0]
    if cart.ndim != 2 or cart.shape[1] != n or n % 2:
        raise RaPlaceError(f"cart must be a square image of even side, got shape {cart.shape}")
    if pad_factor < 1:
        raise RaPlaceError(f"pad_factor must be >= 1, got {pad_factor}")
    size = pad_factor * n
    spectrum = _centred_fft2(cart[::-1, ::-1], size)
    grid = spectrum.view(np.float32).reshape(size, size, 2)
    return ImageSpectrum(grid=grid, cell_m=float(cell_m))


def _centred_fft2(image: NDArray[np.float32], size: int) -> NDArray[np.complex64]:
    """fftshift(fft2(ifftshift(padded))) of `image` (n, n) zero-padded at the centre of a
    (size, size) array, computed from its n non-zero rows: a real FFT along the rows, an FFT
    along the columns for the non-negative column frequencies, the rest by Hermitian symmetry
    (a quarter of the full complex 2-D FFT's work, no padded copies)."""
    n = image.shape[0]
    q, c = n // 2, size // 2
    # ifftshift puts the image's second half first and its first half at the end, both axes.
    rows = np.zeros((n, size), dtype=np.float32)
    rows[:q, :q] = image[q:, q:]
    rows[:q, size - q :] = image[q:, :q]
    rows[q:, :q] = image[:q, q:]
    rows[q:, size - q :] = image[:q, :q]
    half = np.zeros((size, c + 1), dtype=np.complex64)  # columns: frequencies 0..size/2
    transformed = scipy.fft.rfft(rows, axis=1, workers=1)
    half[:q] = transformed[:q]
    half[size - q :] = transformed[q:]
    half = scipy.fft.fft(half, axis=0, workers=1, overwrite_x=True)
    out = np.empty((size, size), dtype=np.complex64)
    out[:c, c:] = half[c:, :c]  # fftshift: frequency (i - c, j - c) at index (i, j)
    out[c:, c:] = half[:c, :c]
    # F(kx, ky) = conj F(-kx, -ky) for the negative column frequencies.
    flipped_rows = (c - np.arange(size)) % size
    np.conjugate(half[flipped_rows, c:0:-1], out=out[:, :c])
    return out


def unit_phasor(angle_rad: NDArray) -> NDArray[np.complex64]:
    """exp(i angle) as complex64 (numpy's complex exp is about 6x slower than cos and sin)."""
    angle = np.asarray(angle_rad, dtype=np.float32)
    out = np.empty(angle.shape, dtype=np.complex64)
    out.real = np.cos(angle)
    out.imag = np.sin(angle)
    return out


def radial_spectrum(
    spectrum: ImageSpectrum,
    thetas_rad: NDArray[np.float64],
    freqs_cpm: NDArray[np.float64],
) -> NDArray[np.complex64]:
    """Sinogram spectrum S^(theta, k) = F(k cos theta, k sin theta), bicubically interpolated.

    Args:
        spectrum: the image's padded 2-D DFT.
        thetas_rad: (n_theta,) angles, CCW from +x [rad] (any real values).
        freqs_cpm: (n_freq,) frequencies along l [cycles/m], |k| <= 1 / (2 cell_m).

    Returns:
        (n_theta, n_freq) complex64: the DFT along l (l in pixels, sum over pixels) of the Radon
        transform row at each theta, with l = 0 at the sensor.
    """
    thetas = np.asarray(thetas_rad, dtype=np.float64)[:, None]
    freqs = np.asarray(freqs_cpm, dtype=np.float64)[None, :]
    kx = freqs * np.cos(thetas)
    ky = freqs * np.sin(thetas)
    scale = spectrum.size * spectrum.cell_m
    centre = spectrum.size // 2
    rows = (centre + kx * scale).astype(np.float32)
    cols = (centre + ky * scale).astype(np.float32)
    values = sample_spectrum(spectrum, rows, cols)
    # Pixel centres sit at (index + 0.5) * cell from the sensor: undo that half-pixel offset.
    values *= unit_phasor(-np.pi * spectrum.cell_m * (kx + ky))
    return values


def sample_spectrum(
    spectrum: ImageSpectrum, rows: NDArray[np.float32], cols: NDArray[np.float32]
) -> NDArray[np.complex64]:
    """The spectrum bicubically interpolated at fractional grid (rows, cols) (any equal shapes;
    zero outside the grid), as complex64 of that shape."""
    sampled = cv2.remap(
        spectrum.grid,
        cols,
        rows,
        interpolation=cv2.INTER_CUBIC,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0.0,
    )
    return np.ascontiguousarray(sampled).view(np.complex64)[..., 0]


def sinogram(
    cart: NDArray, cell_m: float, n_theta: int, pad_factor: int = 2
) -> NDArray[np.float64]:
    """Radon sinogram S(theta, l) of a Cartesian image through the Fourier slice theorem.

    Args:
        cart: (n, n) image in the raplace.warp convention.
        cell_m: pixel size [m].
        n_theta: angles theta_i = i * pi / n_theta, i < n_theta.
        pad_factor: zero padding of the 2-D FFT; the l axis spans pad_factor * n pixels.

    Returns:
        (n_theta, pad_factor * n) line sums (sum of pixel values along each line, pixel units);
        column j is l = (j - pad_factor * n / 2) * cell_m [m], l = x cos theta + y sin theta.
    """
    spec = image_spectrum(cart, cell_m, pad_factor)
    size = spec.size
    freqs = (np.arange(size, dtype=np.float64) - size // 2) * spec.freq_step_cpm
    thetas = np.arange(n_theta) * np.pi / n_theta
    rows = radial_spectrum(spec, thetas, freqs).astype(np.complex128)
    # Frequencies are in fftshift order and l = 0 must land on column size // 2.
    lines = scipy.fft.fftshift(scipy.fft.ifft(scipy.fft.ifftshift(rows, axes=1), axis=1), axes=1)
    return lines.real


def descriptor_angles(n_theta: int, oversample: int = 1) -> NDArray[np.float64]:
    """(n_theta * oversample,) angles [rad], in groups of `oversample` centred on i pi / n_theta."""
    offsets = (np.arange(oversample) - 0.5 * (oversample - 1)) / oversample
    return ((np.arange(n_theta)[:, None] + offsets[None, :]) * np.pi / n_theta).ravel()


def descriptor_freqs(n_freq: int, max_freq_cpm: float) -> NDArray[np.float64]:
    """(n_freq,) frequencies k_j = j * max_freq_cpm / n_freq, j = 1..n_freq [cycles/m]."""
    return np.arange(1, n_freq + 1, dtype=np.float64) * (max_freq_cpm / n_freq)


def z_normalise(values: NDArray) -> NDArray[np.float32]:
    """Zero mean, unit standard deviation over the whole array (over the last two axes)."""
    values = np.asarray(values, dtype=np.float32)
    mean = values.mean(axis=(-2, -1), keepdims=True)
    std = values.std(axis=(-2, -1), keepdims=True)
    return ((values - mean) / np.maximum(std, Z_NORMALISE_EPS)).astype(np.float32)


def transform_magnitude(magnitude: NDArray, how: MagnitudeTransform) -> NDArray:
    """Apply the configured compression to |S^| (see DescriptorConfig.magnitude)."""
    if how == "linear":
        return magnitude
    if how == "sqrt":
        return np.sqrt(magnitude)
    if how == "log1p":
        return np.log1p(magnitude)
    raise RaPlaceError(f"unknown magnitude transform {how!r}")


def descriptor(cart: NDArray, cell_m: float, cfg: DescriptorConfig) -> NDArray[np.float32]:
    """The RaPlace descriptor of a Cartesian image.

    Args:
        cart: (n, n) image in the raplace.warp convention (a disc of content around the sensor).
        cell_m: pixel size [m].
        cfg: descriptor settings.

    Returns:
        (cfg.n_theta, cfg.n_freq) float32, z-normalised: row i is theta_i = i * pi / n_theta,
        column j is k_j = (j + 1) * max_freq_cpm / n_freq. Rotating the scene by a CCW shifts the
        rows by +a (circularly, modulo pi); translating it leaves it unchanged.
    """
    nyquist = 0.5 / cell_m
    if cfg.max_freq_cpm > nyquist:
        raise RaPlaceError(
            f"max_freq_cpm {cfg.max_freq_cpm} exceeds the image Nyquist {nyquist} cycles/m"
        )
    spec = image_spectrum(cart, cell_m, cfg.pad_factor)
    thetas = descriptor_angles(cfg.n_theta, cfg.theta_oversample)
    freqs = descriptor_freqs(cfg.n_freq, cfg.max_freq_cpm)
    magnitude = np.abs(radial_spectrum(spec, thetas, freqs))
    magnitude = magnitude.reshape(cfg.n_theta, cfg.theta_oversample, cfg.n_freq).mean(axis=1)
    return z_normalise(transform_magnitude(magnitude, cfg.magnitude))


def coarse_descriptor(desc: NDArray, theta_pool: int, n_freq: int) -> NDArray[np.float32]:
    """Low-resolution descriptor for hierarchical retrieval.

    Args:
        desc: (..., n_theta, n_freq_full) descriptors; n_theta divisible by `theta_pool`.
        theta_pool: rows averaged into one.
        n_freq: lowest frequency columns kept.

    Returns:
        (..., n_theta // theta_pool, n_freq) float32, z-normalised.
    """
    desc = np.asarray(desc, dtype=np.float32)
    n_theta = desc.shape[-2]
    if theta_pool < 1 or n_theta % theta_pool:
        raise RaPlaceError(f"n_theta {n_theta} is not divisible by theta_pool {theta_pool}")
    if not 1 <= n_freq <= desc.shape[-1]:
        raise RaPlaceError(f"coarse n_freq must be in [1, {desc.shape[-1]}], got {n_freq}")
    kept = desc[..., :n_freq]
    pooled = kept.reshape(*desc.shape[:-2], n_theta // theta_pool, theta_pool, n_freq).mean(-2)
    return z_normalise(pooled)


class DescriptorExtractor:
    """Polar scan -> RaPlace descriptor (n_theta, n_freq) float32; caches the warping maps."""

    def __init__(self, cfg: DescriptorConfig) -> None:
        self.cfg = cfg
        self.imager = CartesianImager(cfg.preprocess, cfg.image)

    @property
    def shape(self) -> tuple[int, int]:
        """Descriptor shape (n_theta, n_freq)."""
        return (self.cfg.n_theta, self.cfg.n_freq)

    def __call__(
        self, polar: NDArray, azimuths_rad: NDArray[np.float64], range_resolution_m: float
    ) -> NDArray[np.float32]:
        """Descriptor of one scan.

        Args:
            polar: (n_azimuths, n_bins) intensities.
            azimuths_rad: (n_azimuths,) CCW azimuth of each row [rad].
            range_resolution_m: bin size [m].
        """
        cart = self.imager(polar, azimuths_rad, range_resolution_m)
        return descriptor(cart, self.cfg.image.cell_m, self.cfg)
