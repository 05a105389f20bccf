"""Compiled kernels of the sinogram relative pose (`raplace.pose`), run without the GIL.

Loop verification runs on the pipeline's loop thread next to the odometry: these kernels fuse
the per-element numpy passes of the pose estimate (cross-power whitening, per-row peaks, the
robust translation fit, the aligned correlation) into single loops that release the GIL, so
the other threads keep running. Each matches its numpy formulation up to float rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray

PARABOLA_EPS = 1e-12
"""Curvatures below this are treated as flat (as `raplace.scoring.parabolic_vertex`)."""
SINGULAR_EPS = 1e-12
"""A 2 x 2 normal matrix with a smaller determinant (relative) is not solved."""


@numba.njit(nogil=True, cache=True)
def whitened_cross_power(
    query: NDArray[np.complex64],
    map_rows: NDArray[np.complex64],
    whitening: float,
    eps: float,
) -> NDArray[np.complex64]:
    """(n, m) complex64 q * conj(m) / max(|q conj(m)|, eps) ** whitening, column 0 (DC) zero."""
    n, m = query.shape
    out = np.empty((n, m), dtype=np.complex64)
    w = np.float32(whitening)
    floor = np.float32(eps)
    for i in range(n):
        out[i, 0] = 0.0
        for j in range(1, m):
            a = query[i, j]
            b = map_rows[i, j]
            re = a.real * b.real + a.imag * b.imag
            im = a.imag * b.real - a.real * b.imag
            if w > 0:
                magnitude = max(np.float32(math.sqrt(re * re + im * im)), floor)
                if w == np.float32(0.5):
                    scale = np.float32(1.0) / np.float32(math.sqrt(magnitude))
                else:
                    scale = np.float32(1.0) / np.float32(magnitude**w)
                re *= scale
                im *= scale
            out[i, j] = complex(re, im)
    return out


@numba.njit(nogil=True, cache=True)
def row_peak_positions(values: NDArray[np.float32]) -> NDArray[np.float64]:
    """(n,) sub-sample position of each row's circular maximum (first maximum; parabola through
    it and its circular neighbours, offset within +-0.5): `raplace.scoring.circular_peak`'s."""
    n, length = values.shape
    out = np.empty(n)
    for i in range(n):
        best = 0
        top = values[i, 0]
        for j in range(1, length):
            if values[i, j] > top:
                top = values[i, j]
                best = j
        before = float(values[i, (best - 1) % length])
        centre = float(top)
        after = float(values[i, (best + 1) % length])
        curvature = before - 2.0 * centre + after
        if abs(curvature) <= PARABOLA_EPS:
            curvature = -PARABOLA_EPS
        offset = min(max(0.5 * (before - after) / curvature, -0.5), 0.5)
        out[i] = best + offset
    return out


@numba.njit(nogil=True, cache=True)
def _truncated_cost(
    cos_t: NDArray[np.float64],
    sin_t: NDArray[np.float64],
    shifts: NDArray[np.float64],
    x: float,
    y: float,
    threshold_sq: float,
) -> float:
    cost = 0.0
    for i in range(len(shifts)):
        r = shifts[i] - (x * cos_t[i] + y * sin_t[i])
        cost += min(r * r, threshold_sq)
    return cost


@numba.njit(nogil=True, cache=True)
def _inlier_least_squares(
    cos_t: NDArray[np.float64],
    sin_t: NDArray[np.float64],
    shifts: NDArray[np.float64],
    x: float,
    y: float,
    threshold: float,
) -> tuple[float, float, bool]:
    """Least squares (x, y) over the angles within `threshold` of (x, y); ok False when fewer
    than 2 inliers or a singular system (the input is returned)."""
    cc = cs = ss = cb = sb = 0.0
    count = 0
    for i in range(len(shifts)):
        c, s, b = cos_t[i], sin_t[i], shifts[i]
        if abs(b - (x * c + y * s)) < threshold:
            count += 1
            cc += c * c
            cs += c * s
            ss += s * s
            cb += c * b
            sb += s * b
    det = cc * ss - cs * cs
    if count < 2 or det <= SINGULAR_EPS * (cc * ss + 1e-300):
        return x, y, False
    return (ss * cb - cs * sb) / det, (cc * sb - cs * cb) / det, True


@numba.njit(nogil=True, cache=True)
def fit_translation_kernel(
    cos_t: NDArray[np.float64],
    sin_t: NDArray[np.float64],
    shifts: NDArray[np.float64],
    threshold: float,
    iterations: int,
) -> tuple[float, float, float, NDArray[np.bool_]]:
    """`raplace.pose.fit_translation` on precomputed cos / sin of the angles: (x, y, truncated
    RMS residual, inlier mask)."""
    n = len(shifts)
    half = n // 2
    threshold_sq = threshold * threshold
    best_cost = np.inf
    x = y = 0.0
    for p in range(half):  # orthogonal pair (theta_p, theta_p + pi/2)
        c, s = cos_t[p], sin_t[p]
        b1, b2 = shifts[p], shifts[half + p]
        px = c * b1 - s * b2
        py = s * b1 + c * b2
        cost = _truncated_cost(cos_t, sin_t, shifts, px, py, threshold_sq)
        if cost < best_cost:
            best_cost, x, y = cost, px, py
    for _ in range(iterations):
        x, y, ok = _inlier_least_squares(cos_t, sin_t, shifts, x, y, threshold)
        if not ok:
            break
    inliers = np.empty(n, dtype=np.bool_)
    total = 0.0
    for i in range(n):
        r = shifts[i] - (x * cos_t[i] + y * sin_t[i])
        inliers[i] = abs(r) < threshold
        total += min(r * r, threshold_sq)
    return x, y, math.sqrt(total / n), inliers


@numba.njit(nogil=True, cache=True)
def aligned_correlation_kernel(
    query: NDArray[np.complex64],
    map_rows: NDArray[np.complex64],
    row_shifts_m: NDArray[np.float64],
    freq_step_cpm: float,
) -> float:
    """Normalised correlation of the query rows and the map rows moved by the per-row shifts
    b_i [m] (`raplace.pose.aligned_correlation`, frequencies k_j = j * freq_step_cpm): sum of
    k Re(q conj(m) e^(2 pi i k b)) over sqrt(sum k |q|^2 sum k |m|^2), DC excluded."""
    n, m = query.shape
    num = q_power = m_power = 0.0
    for i in range(n):
        angle = 2.0 * math.pi * freq_step_cpm * row_shifts_m[i]
        step = complex(math.cos(angle), math.sin(angle))
        phase = step  # e^(2 pi i k_j b_i) for j = 1, by recurrence
        for j in range(1, m):
            weight = j * freq_step_cpm
            a = complex(query[i, j])
            b = complex(map_rows[i, j])
            num += weight * (a * b.conjugate() * phase).real
            q_power += weight * (a.real * a.real + a.imag * a.imag)
            m_power += weight * (b.real * b.real + b.imag * b.imag)
            phase *= step
    den = math.sqrt(q_power * m_power)
    return num / den if den > 0 else 0.0


@numba.njit(nogil=True, cache=True)
def radial_sampling(
    thetas_rad: NDArray[np.float64],
    freq_step_cpm: float,
    n_freq: int,
    size: int,
    cell_m: float,
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.complex64]]:
    """Where `raplace.descriptor.radial_spectrum` samples a padded 2-D DFT of side `size` for
    the radial lines at `thetas_rad` and k_j = j * freq_step_cpm (j < n_freq), and the phase
    that moves the pixel centres' half-pixel offset back to the sensor.

    Returns:
        (rows, cols) (n_theta, n_freq) float32 map coordinates (cv2.remap's map2, map1) and
        (n_theta, n_freq) complex64 e^(-i pi cell (kx + ky)).
    """
    n = len(thetas_rad)
    rows = np.empty((n, n_freq), dtype=np.float32)
    cols = np.empty((n, n_freq), dtype=np.float32)
    phase = np.empty((n, n_freq), dtype=np.complex64)
    scale = size * cell_m
    centre = size // 2
    for i in range(n):
        c = math.cos(thetas_rad[i])
        s = math.sin(thetas_rad[i])
        angle = -math.pi * cell_m * freq_step_cpm * (c + s)
        step = complex(math.cos(angle), math.sin(angle))
        value = complex(1.0, 0.0)
        for j in range(n_freq):
            k = j * freq_step_cpm
            rows[i, j] = centre + k * c * scale
            cols[i, j] = centre + k * s * scale
            phase[i, j] = value
            value *= step
    return rows, cols, phase
