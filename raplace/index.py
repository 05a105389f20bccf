"""Rotation-invariant index of RaPlace descriptors: the first stage of a place query.

A descriptor D(theta, k) (n_theta rows over theta in [0, pi), z-normalised) of a scan rotated
by a is D shifted circularly along theta by a (modulo pi, the descriptor's period). The
magnitudes |D^_w(k)| of its DFT along theta do not change under such a shift, so they describe
the place independently of the heading. They also bound the rotation search of
raplace.scoring: with n = n_theta, N = n_theta * n_freq and c_w the multiplicity of rfft bin w
in the full DFT (1 for w = 0 and w = n / 2, else 2),

    C_qm(s) / N = (1 / (n N)) sum_w sum_k Q^_w(k) conj(M^_w(k)) e^(2 pi i w s / n)
               <= sum_w sum_k u_q(w, k) u_m(w, k),     u(w, k) = sqrt(c_w / (n N)) |D^_w(k)|,

for every shift s (triangle inequality), and |u| = 1 for a z-normalised descriptor (Parseval).
So 1 - u_q . u_m is a lower bound of the mutable-threshold distance, exact for an unrotated
copy. Only the lowest `harmonics` theta harmonics are stored; the rest is bounded by
Cauchy-Schwarz with the norms of the dropped parts (`residual`), so the bound stays valid:

    u_q . u_m <= u_q[kept] . u_m[kept] + residual_q * residual_m.

The vectors of all entries are one contiguous float32 matrix: ranking the database is one
matrix-vector product, and only the best-bounded entries are scored with the rotation search.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from raplace import RaPlaceError
from raplace.growing import GrowingArray


def harmonic_weights(n_theta: int, n_harmonics: int) -> NDArray[np.float64]:
    """(n_harmonics,) multiplicity c_w of rfft bins w < n_harmonics of an n_theta-point DFT."""
    weights = np.full(n_harmonics, 2.0)
    weights[0] = 1.0
    if n_theta % 2 == 0 and n_harmonics > n_theta // 2:
        weights[n_theta // 2] = 1.0
    return weights


def invariant_vectors(
    spectra: NDArray[np.complex64], n_theta: int, harmonics: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Rotation-invariant vectors of descriptors from their theta-spectra.

    Args:
        spectra: (..., n_theta // 2 + 1, n_freq) rfft along theta of z-normalised descriptors
            (raplace.scoring.theta_spectrum).
        n_theta: descriptor rows.
        harmonics: lowest theta harmonics kept (clipped to n_theta // 2 + 1).

    Returns:
        (vectors (..., kept * n_freq) float32, residual (...,) float32): u of the module
        docstring for the kept harmonics, and the norm of the dropped part.
    """
    spectra = np.asarray(spectra)
    n_bins, n_freq = spectra.shape[-2:]
    if n_bins != n_theta // 2 + 1:
        raise RaPlaceError(f"theta-spectra have {n_bins} bins, expected {n_theta // 2 + 1}")
    if harmonics < 1:
        raise RaPlaceError(f"harmonics must be >= 1, got {harmonics}")
    scale = np.sqrt(harmonic_weights(n_theta, n_bins) / (n_theta * n_theta * n_freq))
    u = np.abs(spectra).astype(np.float64) * scale[:, None]
    kept = min(harmonics, n_bins)
    dropped = np.sqrt(np.sum(u[..., kept:, :] ** 2, axis=(-2, -1)))
    vectors = u[..., :kept, :].reshape(*u.shape[:-2], kept * n_freq)
    return vectors.astype(np.float32), dropped.astype(np.float32)


class InvariantIndex:
    """Rotation-invariant vectors of a database's entries, in insertion order."""

    def __init__(self, n_theta: int, n_freq: int, harmonics: int) -> None:
        self.n_theta = n_theta
        self.harmonics = min(harmonics, n_theta // 2 + 1)
        self._vectors = GrowingArray((self.harmonics * n_freq,), np.float32)
        self._residual = GrowingArray((), np.float32)

    def __len__(self) -> int:
        return len(self._vectors)

    def extend(self, spectra: NDArray[np.complex64]) -> None:
        """Append the entries with (n, n_theta // 2 + 1, n_freq) theta-spectra."""
        vectors, residual = invariant_vectors(spectra, self.n_theta, self.harmonics)
        self._vectors.extend(vectors)
        self._residual.extend(residual)

    def bound(self, spectrum: NDArray[np.complex64]) -> NDArray[np.float32]:
        """(n_entries,) upper bound of each entry's peak normalised correlation with the query.

        Args:
            spectrum: (n_theta // 2 + 1, n_freq) theta-spectrum of the query descriptor.
        """
        vector, residual = invariant_vectors(spectrum, self.n_theta, self.harmonics)
        bound = self._vectors.values @ vector
        bound += float(residual) * self._residual.values
        return bound

    def shortlist(
        self, spectrum: NDArray[np.complex64], allowed: NDArray[np.bool_], size: int
    ) -> NDArray[np.int64]:
        """Sorted indices of the `size` allowed entries of highest bound (all when fewer).

        Args:
            spectrum: (n_theta // 2 + 1, n_freq) theta-spectrum of the query descriptor.
            allowed: (n_entries,) True where the entry may match (raplace.retrieval
                `candidate_mask`); the others are never returned.
            size: entries wanted.
        """
        if allowed.shape != (len(self),):
            raise RaPlaceError(f"allowed mask shape {allowed.shape} != ({len(self)},)")
        n_allowed = int(np.count_nonzero(allowed))
        if n_allowed <= size:
            return np.flatnonzero(allowed)
        bound = self.bound(spectrum)
        bound[~allowed] = -np.inf
        best = np.argpartition(bound, len(bound) - size)[len(bound) - size :]
        return np.sort(best)
