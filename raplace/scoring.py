"""Rotation-searching cross-correlation of RaPlace descriptors and the mutable-threshold distance.

Descriptors D(theta, k) are (n_theta, n_freq), theta in [0, pi), z-normalised (raplace.descriptor).
The released RaPlace code correlates along the frequency axis; here the correlation is circular
along theta, which is the rotation search:

    C_qm(s) = sum_theta sum_k Q(theta, k) M(theta - s, k),

computed for every database entry at once from the theta-spectra (rfft along theta):
one einsum over (entries, theta harmonics, k) and one batched inverse FFT. A query that is the
map rotated by a CCW peaks at s = a (modulo pi).

Mutable threshold (RaPlace): d = |max C_qq - max_s C_qm(s)|. The auto-correlation peak of a
z-normalised descriptor is its size n_theta * n_freq, so we divide by it: d = 1 - (peak
normalised cross-correlation), in [0, 2]; the paper's d differs only by that constant scale.
"""

from __future__ import annotations

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from raplace import RaPlaceError

PARABOLA_EPS = 1e-12
"""Guard for a flat correlation peak in the sub-bin interpolation."""


def theta_spectrum(desc: NDArray) -> NDArray[np.complex64]:
    """rfft along theta: (..., n_theta, n_freq) -> (..., n_theta // 2 + 1, n_freq) complex64."""
    desc = np.asarray(desc, dtype=np.float32)
    return scipy.fft.rfft(desc, axis=-2, workers=1).astype(np.complex64, copy=False)


def autocorrelation_peak(desc: NDArray) -> float:
    """max_s C_qq(s) = sum Q^2 (Cauchy-Schwarz: the zero-shift value is the maximum)."""
    desc = np.asarray(desc, dtype=np.float64)
    return float(np.sum(desc * desc))


def parabolic_vertex(
    before: ArrayLike, centre: ArrayLike, after: ArrayLike, limit: float = 0.5
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Vertex of the parabola through samples at -1, 0, +1: (value, offset in [-limit, limit])."""
    before, centre, after = (np.asarray(v, dtype=np.float64) for v in (before, centre, after))
    curvature = before - 2.0 * centre + after
    safe = np.where(np.abs(curvature) > PARABOLA_EPS, curvature, -PARABOLA_EPS)
    offset = np.clip(0.5 * (before - after) / safe, -limit, limit)
    return centre - 0.25 * (before - after) * offset, offset


def circular_peak(values: NDArray) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Sub-bin maximum of circular sequences along the last axis.

    Args:
        values: (..., n) samples of periodic functions.

    Returns:
        (peak value (...,), peak position (...,) in samples, in [-0.5, n - 0.5)), each from a
        parabola through the best sample and its two circular neighbours.
    """
    values = np.asarray(values, dtype=np.float64)
    n = values.shape[-1]
    best = np.argmax(values, axis=-1)
    centre = np.take_along_axis(values, best[..., None], axis=-1)[..., 0]
    before = np.take_along_axis(values, ((best - 1) % n)[..., None], axis=-1)[..., 0]
    after = np.take_along_axis(values, ((best + 1) % n)[..., None], axis=-1)[..., 0]
    peak, offset = parabolic_vertex(before, centre, after)
    return peak, best + offset


def correlate(
    query_spectrum: NDArray[np.complex64], db_spectra: NDArray[np.complex64], n_theta: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Peak of the circular theta cross-correlation of one query against many entries.

    Args:
        query_spectrum: (n_theta // 2 + 1, n_freq) theta-spectrum of the query descriptor.
        db_spectra: (n_entries, n_theta // 2 + 1, n_freq) theta-spectra of the entries.
        n_theta: descriptor rows (the theta period pi is n_theta samples).

    Returns:
        (peak (n_entries,), yaw (n_entries,) [rad]): the sub-bin maximum of C_qm and the
        rotation a in [-pi/2, pi/2) of the query relative to each entry (the entry's yaw in the
        query frame), modulo pi.
    """
    if db_spectra.ndim != 3 or db_spectra.shape[1:] != query_spectrum.shape:
        raise RaPlaceError(
            f"spectra shapes differ: query {query_spectrum.shape}, database {db_spectra.shape}"
        )
    # C_mq(s) = sum M(theta) Q(theta - s) <-> F_M conj(F_Q): peaks at s = -a.
    cross = np.einsum("mwk,wk->mw", db_spectra, np.conj(query_spectrum), optimize=True)
    corr = scipy.fft.irfft(cross, n=n_theta, axis=-1, workers=1)
    peak, shift = circular_peak(corr)
    yaw = np.mod(-shift * (np.pi / n_theta) + 0.5 * np.pi, np.pi) - 0.5 * np.pi
    return peak, yaw


def mutable_threshold_distance(
    auto_peak: float, cross_peaks: NDArray, n_elements: int
) -> NDArray[np.float64]:
    """RaPlace distance |max C_auto - max C_qi| divided by the descriptor size (see module doc)."""
    return np.abs(auto_peak - np.asarray(cross_peaks, dtype=np.float64)) / float(n_elements)


def score(
    query: NDArray, db_spectra: NDArray[np.complex64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mutable-threshold distances and rotations of a query descriptor against many entries.

    Args:
        query: (n_theta, n_freq) z-normalised descriptor.
        db_spectra: (n_entries, n_theta // 2 + 1, n_freq) theta-spectra of the entries
            (`theta_spectrum` of their descriptors).

    Returns:
        (distance (n_entries,), yaw (n_entries,) [rad], modulo pi, in [-pi/2, pi/2)).
    """
    query = np.asarray(query, dtype=np.float32)
    peak, yaw = correlate(theta_spectrum(query), db_spectra, query.shape[0])
    return mutable_threshold_distance(autocorrelation_peak(query), peak, query.size), yaw
