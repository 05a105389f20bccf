"""Rotation-invariant bound of the RaPlace rotation search: the first stage of a place query.

A descriptor D(theta, k) (n_theta rows over theta in [0, pi), z-normalised) of a scan rotated
by a is D shifted circularly along theta by a (modulo pi, the descriptor's period). Its DFT
along theta, D^_w(k), only changes phase, by -2 pi w a / pi for every k. Hence, for a query Q and
an entry M, the per-harmonic products X_w = sum_k Q^_w(k) conj(M^_w(k)) have rotation-invariant
magnitudes, and they bound the rotation search of raplace.scoring: with n = n_theta,
N = n_theta * n_freq and c_w the multiplicity of rfft bin w in the full DFT (1 for w = 0 and
w = n / 2, else 2),

    C_qm(s) / N = sum_w c_w Re(X_w e^(2 pi i w s / n)) / (n N) <= sum_w c_w |X_w| / (n N)

for every shift s (triangle inequality; the shift is common to all k, so the phases along k
stay aligned). Only the lowest `harmonics` w are kept; the rest is bounded by Cauchy-Schwarz
with the norms of the dropped parts (`residual`), so the bound stays valid:

    sum_(w >= H) c_w |X_w| / (n N) <= residual_q * residual_m,
    residual^2 = sum_(w >= H) sum_k c_w |D^_w(k)|^2 / (n N)   (1 in all for a z-normalised D).

So 1 - bound is a lower bound of the mutable-threshold distance, exact for an unrotated copy
with every harmonic kept. The magnitudes |D^_w(k)| alone (`invariant_vectors`) are the
rotation-invariant global vector of a descriptor, but their dot product, which also bounds the
correlation, is a much looser bound than the one above (it drops the phases along k). The kept
harmonics of all entries are stored as one contiguous complex64 array per harmonic: ranking the
database is `harmonics` matrix-vector products, and only the best-bounded entries are scored
with the rotation search.
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


def scaled_harmonics(
    spectra: NDArray[np.complex64], n_theta: int, harmonics: int
) -> tuple[NDArray[np.complex64], NDArray[np.float32]]:
    """The lowest theta harmonics of descriptors, scaled for the bound, and the dropped norm.

    Args:
        spectra: (..., n_theta // 2 + 1, n_freq) rfft along theta of z-normalised descriptors
            (raplace.scoring.theta_spectrum).
        n_theta: descriptor rows.
        harmonics: lowest theta harmonics kept (clipped to n_theta // 2 + 1).

    Returns:
        (kept (..., kept, n_freq) complex64: D^_w(k) sqrt(c_w / (n N)); residual (...,)
        float32: the norm of the dropped harmonics, see the module docstring).
    """
    spectra = np.asarray(spectra)
    n_bins, n_freq = spectra.shape[-2:]
    if n_bins != n_theta // 2 + 1:
        raise RaPlaceError(f"theta-spectra have {n_bins} bins, expected {n_theta // 2 + 1}")
    if harmonics < 1:
        raise RaPlaceError(f"harmonics must be >= 1, got {harmonics}")
    scale = np.sqrt(harmonic_weights(n_theta, n_bins) / (n_theta * n_theta * n_freq))
    scaled = spectra.astype(np.complex128) * scale[:, None]
    kept = min(harmonics, n_bins)
    dropped = np.sqrt(np.sum(np.abs(scaled[..., kept:, :]) ** 2, axis=(-2, -1)))
    return scaled[..., :kept, :].astype(np.complex64), dropped.astype(np.float32)


def invariant_vectors(spectra: NDArray[np.complex64], n_theta: int) -> NDArray[np.float32]:
    """Rotation-invariant global vectors |D^_w(k)| sqrt(c_w / (n N)) of descriptors.

    Args:
        spectra: (..., n_theta // 2 + 1, n_freq) theta-spectra of z-normalised descriptors.
        n_theta: descriptor rows.

    Returns:
        (..., (n_theta // 2 + 1) * n_freq) float32 of unit norm (Parseval): the same for a
        descriptor and any circular shift of it along theta.
    """
    kept, _ = scaled_harmonics(spectra, n_theta, n_theta // 2 + 1)
    return np.abs(kept).reshape(*kept.shape[:-2], -1).astype(np.float32)


class InvariantIndex:
    """The kept theta harmonics of a database's entries (one contiguous array per harmonic)."""

    def __init__(self, n_theta: int, n_freq: int, harmonics: int) -> None:
        self.n_theta = n_theta
        self.harmonics = min(harmonics, n_theta // 2 + 1)
        self._kept = [GrowingArray((n_freq,), np.complex64) for _ in range(self.harmonics)]
        self._residual = GrowingArray((), np.float32)

    def __len__(self) -> int:
        return len(self._residual)

    def extend(self, spectra: NDArray[np.complex64]) -> None:
        """Append the entries with (n, n_theta // 2 + 1, n_freq) theta-spectra."""
        kept, residual = scaled_harmonics(spectra, self.n_theta, self.harmonics)
        for w, store in enumerate(self._kept):
            store.extend(kept[:, w])
        self._residual.extend(residual)

    def bound(self, spectrum: NDArray[np.complex64]) -> NDArray[np.float32]:
        """(n_entries,) upper bound of each entry's peak normalised correlation with the query.

        Args:
            spectrum: (n_theta // 2 + 1, n_freq) theta-spectrum of the query descriptor.
        """
        kept, residual = scaled_harmonics(spectrum, self.n_theta, self.harmonics)
        conj = np.conj(kept)
        products = np.empty((self.harmonics, len(self)), dtype=np.complex64)
        for w, store in enumerate(self._kept):
            np.matmul(store.values, conj[w], out=products[w])
        # Both spectra carry sqrt(c_w / (n N)): |products[w]| is c_w |X_w| / (n N).
        bound = np.abs(products).sum(axis=0)
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
