"""Place recognition on real scans: revisits made from one real drive and its GNSS.

The RADIATE Edinburgh drive has no revisit of its own, but any two of its scans a few metres
apart see the same place. Turning one of them by pi is what a pass in the other direction sees
(RaPlace's own sensitivity study builds candidates this way). So, with GNSS positions read
through the clock offset estimated from the odometry:

- a query is scan k, as recorded ("same direction") or turned by pi ("reverse");
- its candidates are the other scans m != k of the drive, as recorded;
- real positives are candidates at a GNSS distance within the band (0-5 m or 5-10 m); real
  negatives are candidates more than 50 m away; candidates in between count as neither and are
  left out, as are scans without GNSS (outages);
- each query takes its best candidate; precision and recall over the distance threshold as in
  `radar_slam.placerec` (max F1, recall@1: the share of queries with a positive whose best
  candidate is one);
- "pairs": every positive and negative pair on its own, as a loop threshold sees them: does one
  distance separate all positive pairs from all negative ones? Neighbouring scans of one drive
  share their moving objects and their moment, so best-match retrieval is easy here; the pairs
  show how far apart places must be told.

- "near misses": the retrieval a straight road makes hard. Every scan more than 5 m away is a
  candidate and the best one is correct within 10 m, so scans 10-50 m along the same road
  compete with the true revisits (the descriptor ignores translation by design). RaPlace's own
  best candidate is compared with its best `RERANK_CANDIDATES` re-ranked by the relative pose
  the sinograms estimate (`PoseEstimator`): the one whose aligned images correlate best
  (`RelativePose.quality`) wins. The rows are scored by recall@1 and by max F1 with the chosen
  candidate's RaPlace distance. Turning a query by pi changes neither descriptor nor the pose
  quality, so this is measured in the recorded direction only; a true reverse revisit also
  sees the road from the other lane, a lateral shift one drive cannot provide.

GNSS without RTK is metre level, so the 0-5 m band's edge is soft. Methods: RaPlace and Radar
Scan Context with their default settings, and RaPlace as a SLAM run's loop closer makes it
("RaPlace, run": `LOOP_RAPLACE` on the odometry's conditioned scan, RaPlace's own clean-up
off). Last, the RaPlace distances of the real non-revisits
are compared with those of a simulated drive (`--simulated`, generated on first use under
`--sim-root`): the Kolmogorov-Smirnov distance between the two says how much easier the
simulator's places are to tell apart.

Usage: python scripts/pr_real.py [--data-root ../shared/data] [--simulated synthetic/loop]
       [--sim-root data] [--write-doc]
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
from bench_real import EDINBURGH, real_data_parser
from benchmark_doc import machine_line, update_section
from numpy.typing import NDArray
from scipy import stats

from odometry import PreprocessConfig, RadarFrame, preprocess_polar
from radar_slam.datasets import DatasetConfig, open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.evaluation.time_offset import estimate_time_offset
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.loops.records import raplace_input
from radar_slam.pipeline import load_config, run_odometry
from radar_slam.placerec import PRCurve, pr_curve
from raplace import DescriptorExtractor, PoseEstimator, RaPlaceConfig, ScanContextExtractor
from raplace.scancontext import column_shift_distance
from raplace.scoring import score, theta_spectrum

BANDS_M = ((0.0, 5.0), (5.0, 10.0))
SIMULATED = "synthetic/loop"
NEGATIVE_M = 50.0
NEAR_MISS_MIN_M = 5.0
"""Near misses: candidates closer than this are left out (the neighbouring scans) [m]."""
NEAR_MISS_CRITERION_M = 10.0
"""Near misses: the chosen candidate is correct within this distance [m]."""
RERANK_CANDIDATES = 5
"""RaPlace's best candidates re-ranked by the relative pose's quality."""


def gnss_positions(root: Path) -> tuple[RadarSequence, NDArray[np.float64], float]:
    """(the drive opened with the estimated GNSS clock offset, (N, 2) positions with NaN rows
    in outages, the offset [s])."""
    sequence = open_sequence(EDINBURGH, root)
    run = run_odometry(sequence, load_config(sequence.family))
    assert run.ground_truth is not None
    offset = estimate_time_offset(run.trajectory, run.ground_truth)
    assert offset is not None
    shifted = open_sequence(EDINBURGH, root, DatasetConfig(gt_time_offset_s=offset.offset_s))
    assert shifted.ground_truth is not None
    return shifted, shifted.ground_truth[:, :2], offset.offset_s


class RunExtractor:
    """RaPlace as a SLAM run describes a scan: the odometry's conditioning, then `LOOP_RAPLACE`."""

    def __init__(self, preprocess: PreprocessConfig) -> None:
        self.preprocess = preprocess
        self.describe = DescriptorExtractor(LOOP_RAPLACE.descriptor)

    def __call__(
        self, polar: NDArray, azimuths_rad: NDArray[np.float64], range_resolution_m: float
    ) -> NDArray[np.float32]:
        scan = RadarFrame(0, polar, azimuths_rad, range_resolution_m, "")
        return self.describe(*raplace_input(preprocess_polar(scan, self.preprocess)))


def descriptors(
    sequence: RadarSequence, cfg: RaPlaceConfig
) -> dict[str, dict[str, NDArray[np.float32]]]:
    """{method: {"same": (N, ...), "reverse": (N, ...)}} descriptors of every scan."""
    extractors = {
        "RaPlace": DescriptorExtractor(cfg.descriptor),
        "RaPlace, run": RunExtractor(load_config(sequence.family).odometry.preprocess),
        "Scan Context": ScanContextExtractor(cfg.scancontext),
    }
    out: dict[str, dict[str, list[NDArray[np.float32]]]] = {
        name: {"same": [], "reverse": []} for name in extractors
    }
    for index in range(len(sequence)):
        frame = sequence[index]
        turned = dataclasses.replace(frame, azimuths_rad=frame.azimuths_rad + np.pi)
        for name, extract in extractors.items():
            out[name]["same"].append(
                extract(frame.polar, frame.azimuths_rad, frame.range_resolution_m)
            )
            out[name]["reverse"].append(
                extract(turned.polar, turned.azimuths_rad, turned.range_resolution_m)
            )
    return {name: {k: np.stack(v) for k, v in d.items()} for name, d in out.items()}


def distance_matrix(method: str, queries: NDArray, database: NDArray) -> NDArray[np.float64]:
    """(n_q, n_db) distances of each query to every database entry."""
    rows = []
    if method.startswith("RaPlace"):
        spectra = theta_spectrum(database)
        for query in queries:
            rows.append(score(query, spectra)[0])
    else:
        for query in queries:
            rows.append(column_shift_distance(query, database)[0])
    return np.array(rows)


def band_curves(
    distances: NDArray[np.float64], gap_m: NDArray[np.float64], band: tuple[float, float]
) -> tuple[PRCurve, PRCurve]:
    """(best matches, all pairs): PR curves restricted to positives in `band` and far
    negatives. The first is the retrieval protocol (each query's best candidate); the second
    asks whether one distance threshold separates every positive pair from every negative one,
    which is what accepting a loop by its distance needs."""
    positive = (gap_m >= band[0]) & (gap_m <= band[1])
    negative = gap_m > NEGATIVE_M
    np.fill_diagonal(positive, False)
    d = np.where(positive | negative, distances, np.inf)
    best = np.argmin(d, axis=1)
    rows = np.arange(len(d))
    best_d = d[rows, best]
    correct = positive[rows, best] & np.isfinite(best_d)
    retrieval = pr_curve(best_d, correct, positive.any(axis=1))
    pairs = positive | negative
    pairwise = pr_curve(distances[pairs], positive[pairs], positive[pairs])
    return retrieval, pairwise


def near_misses(
    sequence: RadarSequence,
    known: NDArray[np.int64],
    distances: NDArray[np.float64],
    gap_m: NDArray[np.float64],
    cfg: RaPlaceConfig,
) -> list[str]:
    """Table rows of the near-miss retrieval (module docstring): RaPlace's best candidate, and
    its best `RERANK_CANDIDATES` re-ranked by the quality of the estimated relative pose.

    Args:
        known: (n,) indices of the scans with GNSS; distances, gap_m: (n, n) between them.
    """
    allowed = gap_m > NEAR_MISS_MIN_M
    d = np.where(allowed, distances, np.inf)
    top = np.argsort(d, axis=1)[:, :RERANK_CANDIDATES]
    estimator = PoseEstimator(cfg.pose)
    spectra = []
    for index in known:
        frame = sequence[int(index)]
        image = estimator.image(frame.polar, frame.azimuths_rad, frame.range_resolution_m)
        spectra.append(estimator.spectrum(image))
    reranked = np.empty(len(d), dtype=np.int64)
    for q, candidates in enumerate(top):
        quality = [estimator.estimate_spectra(spectra[q], spectra[m]).quality for m in candidates]
        reranked[q] = candidates[int(np.argmax(quality))]
    revisit = np.asarray((allowed & (gap_m <= NEAR_MISS_CRITERION_M)).any(axis=1), dtype=bool)
    rows = np.arange(len(d))
    band = f"{NEAR_MISS_MIN_M:.0f}-{NEAR_MISS_CRITERION_M:.0f} m, near misses"
    out = []
    for label, chosen in (("RaPlace", top[:, 0]), ("RaPlace, re-ranked by pose", reranked)):
        correct = gap_m[rows, chosen] <= NEAR_MISS_CRITERION_M
        curve = pr_curve(d[rows, chosen], correct & revisit, revisit)
        out.append(
            f"| {label} | same | {band} | {curve.true_revisits} | {curve.max_f1:.2f} | "
            f"{curve.recall_at_1:.2f} | | |"
        )
    return out


def non_revisit_distances(
    described: NDArray[np.float32], xy: NDArray[np.float64]
) -> NDArray[np.float64]:
    """RaPlace distances of every pair of scans more than `NEGATIVE_M` apart (each pair once)."""
    distances = distance_matrix("RaPlace", described, described)
    gap = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    upper = np.triu(gap > NEGATIVE_M, k=1)
    return distances[upper]


def confusability(real: NDArray[np.float64], root: Path, simulated: str) -> str:
    """How alike the RaPlace distances of real and simulated non-revisits are (two-sample
    Kolmogorov-Smirnov distance): a simulator whose places are easier to tell apart flatters."""
    sequence = open_sequence(simulated, root)
    assert sequence.ground_truth is not None
    cfg = RaPlaceConfig()
    extract = DescriptorExtractor(cfg.descriptor)
    known = np.flatnonzero(np.isfinite(sequence.ground_truth[:, 0]))
    frames = (sequence[int(i)] for i in known)
    described = np.stack([extract(f.polar, f.azimuths_rad, f.range_resolution_m) for f in frames])
    sim = non_revisit_distances(described, sequence.ground_truth[known, :2])
    ks = stats.ks_2samp(real, sim).statistic
    quantiles = (0.05, 0.5, 0.95)
    q_real = ", ".join(f"{v:.3f}" for v in np.quantile(real, quantiles))
    q_sim = ", ".join(f"{v:.3f}" for v in np.quantile(sim, quantiles))
    return (
        f"RaPlace distances of non-revisits (pairs more than {NEGATIVE_M:.0f} m apart), "
        f"5/50/95 %: real {q_real}; `{simulated}` {q_sim}; Kolmogorov-Smirnov distance "
        f"{ks:.2f}."
    )


def run(
    root: Path, simulated: str | None = None, sim_root: Path | None = None
) -> tuple[str, float]:
    """The Markdown table (and, with `simulated`, the confusability line) and the GNSS clock
    offset used."""
    sequence, xy, offset_s = gnss_positions(root)
    known = np.isfinite(xy[:, 0])
    cfg = RaPlaceConfig()
    start = time.perf_counter()
    described = descriptors(sequence, cfg)
    per_scan_ms = 1000 * (time.perf_counter() - start) / len(sequence) / 2
    k = np.flatnonzero(known)
    gap = np.hypot(*(xy[k][:, None, :] - xy[k][None, :, :]).transpose(2, 0, 1))
    lines = [
        "| method | direction | band | queries | max F1 | recall@1 | pairs: max F1 | pairs: AUC |",
        "|" + " --- |" * 8,
    ]
    near: list[str] = []
    for method, by_direction in described.items():
        database = by_direction["same"][k]
        for direction in ("same", "reverse"):
            distances = distance_matrix(method, by_direction[direction][k], database)
            if method == "RaPlace" and direction == "same":
                near = near_misses(sequence, k, distances, gap, cfg)
            for band in BANDS_M:
                curve, pairs = band_curves(distances, gap, band)
                lines.append(
                    f"| {method} | {direction} | {band[0]:.0f}-{band[1]:.0f} m | "
                    f"{curve.true_revisits} | {curve.max_f1:.2f} | {curve.recall_at_1:.2f} | "
                    f"{pairs.max_f1:.2f} | {pairs.auc:.2f} |"
                )
    lines += near
    head = (
        f"RADIATE Edinburgh drive, {int(known.sum())} scans with GNSS (of {len(sequence)}); "
        f"GNSS read through a clock offset of {offset_s:+.2f} s estimated from the odometry; "
        f"negatives more than {NEGATIVE_M:.0f} m apart; descriptors (every method, both "
        f"directions) {per_scan_ms:.0f} ms per scan and direction."
    )
    text = head + "\n\n" + "\n".join(lines)
    if simulated is not None:
        real = non_revisit_distances(described["RaPlace"]["same"][k], xy[k])
        text += "\n\n" + confusability(real, sim_root or root, simulated)
    return text, offset_s


def main(argv: list[str] | None = None) -> int:
    parser = real_data_parser(__doc__.splitlines()[0])
    parser.add_argument(
        "--simulated",
        default=SIMULATED,
        help="a simulated drive whose non-revisit distances are compared with the real ones",
    )
    parser.add_argument("--sim-root", type=Path, default=Path("data"), help="its data root")
    args = parser.parse_args(argv)
    text, _ = run(args.data_root, args.simulated, args.sim_root)
    print(f"{machine_line('scripts/pr_real.py')}\n\n{text}")
    if args.write_doc:
        update_section("Place recognition on real scans", text, script="scripts/pr_real.py")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
