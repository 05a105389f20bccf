"""Geometric verification of a proposed loop: sinogram relative pose, refined by phase correlation.

a. the relative pose from the two sinogram spectra (`raplace.pose`), moved from the scans' mean
   acquisition times to their reference times (`motion_compensated`); rejected when the aligned
   correlation, the inlier fraction or the translation is implausible;
b. refinement by phase correlation (`odometry.registration`) of the query and the match turned by
   the sinogram rotation; rejected when its peak is weak or when it disagrees with the sinogram
   estimate by more than `MAX_DISAGREEMENT_M` / `_DEG`;
c. the covariance from the phase-correlation peak, inflated by the disagreement, floored
   (`loop_covariance`); rejected when its rotation is too uncertain (`MAX_SIGMA_YAW_DEG`).

The refinement registers with the run's odometry settings (`odometry.OdometryConfig`: the same
conditioning, cells and de-skew as the odometry).
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import (
    MotionEstimate,
    OdometryConfig,
    PolarScan,
    PreparedScan,
    Scan,
    motion_from_twist,
    preprocess_polar,
    register,
    searched_registration,
)
from radar_slam.loops.config import LOOP_RAPLACE, LoopClosureConfig, LoopCovarianceConfig
from radar_slam.loops.records import KeyScan, Verification, raplace_input
from raplace import (
    NS_PER_S,
    PoseEstimator,
    PoseSpectrum,
    RelativePose,
    between,
    compose,
    rotate_covariance,
    wrap_angle,
)

FloatArray = NDArray[np.float64]
MIN_SINOGRAM_QUALITY = 0.25
"""Minimum normalised correlation of the two images aligned by the sinogram estimate
(`RelativePose.quality`, about 1 for the same place, 0 unrelated)."""
MIN_INLIER_FRACTION = 0.2
"""Minimum fraction of sinogram angles whose shift fits the translation. It falls with the
distance between the scans, faster on real streets than in the simulator (real Oxford scans
12.5 m apart: 0.56 with the radial streaks removed, `raplace.config.PreprocessConfig.spoke_removal`,
0.31 without); this leaves margin for revisits whose scene changed, and the phase-correlation
checks decide."""
MAX_DISAGREEMENT_M = 1.5
"""The sinogram and phase-correlation translations may differ by this much [m]."""
MAX_DISAGREEMENT_DEG = 3.0
"""... and their rotations by this much [deg]."""
MAX_SIGMA_YAW_DEG = 1.0
"""The loop's rotation standard deviation (`loop_covariance`) may be at most this [deg]. It is
large when a scan was swept across a yaw-rate change (the steering into a junction turn, the end of
a turn), which no constant de-skew twist represents: such loops' rotations are off by degrees.
1 deg puts the 2 deg error bound of a true loop (`radar_slam.evaluation.truth`) at two sigmas."""
YAW_RATE_SEARCH = True
"""At low frame rates (a query twist interpolated between odometry steps far apart), the query's
de-skew yaw rate is searched by peak quality against the match (`odometry.searched_registration`):
in a turn at 1 Hz the interpolated yaw rate can be tens of deg/s off the sweep's."""
LOOP_COVARIANCE = LoopCovarianceConfig()
"""The covariance model of verified loops (see `LoopCovarianceConfig` for its terms and
docs/decisions.md for their calibration against the simulator's ground truth)."""


def loop_covariance(
    peak_covariance: ArrayLike,
    disagreement: ArrayLike,
    yaw_rad: float,
    cfg: LoopCovarianceConfig,
    deskew_variance: ArrayLike = (0.0, 0.0, 0.0),
    turn_variance: float = 0.0,
) -> FloatArray:
    """Covariance (3, 3) of a verified loop measurement in GTSAM's tangent space.

    Args:
        peak_covariance: (3, 3) covariance of the phase-correlation estimate, translation in the
            query frame (`MotionEstimate.covariance`) [m^2, m rad, rad^2].
        disagreement: (3,) sinogram estimate expressed relative to the refined one (dx, dy [m],
            dyaw [rad]).
        yaw_rad: the loop's rotation (the match frame is turned by it from the query frame);
            GTSAM perturbs a between-factor on the right, i.e. in the match frame.
        cfg: the covariance model (see `LoopCovarianceConfig`).
        deskew_variance: (3,) squared bends of the two scans' de-skew by their twists' changes
            (`deskew_variance`) [m^2, m^2, rad^2], scaled by `cfg.deskew_error_fraction`^2.
        turn_variance: the two scans' squared rotations over half a sweep
            (`swept_turn_variance`) [rad^2], scaled by `cfg.swept_turn_fraction`^2 (yaw).
    """
    d = np.asarray(disagreement, dtype=np.float64)
    d_xy = float(np.hypot(d[0], d[1]))
    d_yaw = abs(float(wrap_angle(d[2])))
    w = cfg.disagreement_weight
    floor_yaw = np.deg2rad(cfg.min_sigma_yaw_deg)
    cov = cfg.sigma_scale**2 * np.asarray(peak_covariance, dtype=np.float64)
    cov = cov + np.diag([(w * d_xy) ** 2, (w * d_xy) ** 2, (w * d_yaw) ** 2])
    cov = cov + cfg.deskew_error_fraction**2 * np.diag(np.asarray(deskew_variance, dtype=float))
    cov[2, 2] += cfg.swept_turn_fraction**2 * turn_variance
    cov = cov + np.diag([cfg.min_sigma_xy_m**2, cfg.min_sigma_xy_m**2, floor_yaw**2])
    return rotate_covariance(cov, -yaw_rad)  # the query frame is turned by -yaw in the match's


def deskew_variance(*scans: KeyScan) -> FloatArray:
    """(3,) sum over `scans` of the squared bend [m^2, m^2, rad^2] of de-skewing each with a
    twist off by its change across the scan (`KeyScan.twist_change`) over half its sweep: the
    translation isotropic (vx^2 + vy^2 on x and y), the rotation on yaw. A scan without a twist
    change or azimuth times adds nothing."""
    total = np.zeros(3)
    for key_scan in scans:
        half_sweep_s = _half_sweep_s(key_scan)
        if key_scan.twist_change is None or half_sweep_s is None:
            continue
        bend = half_sweep_s * np.abs(np.asarray(key_scan.twist_change, dtype=np.float64))
        xy = float(bend[0] ** 2 + bend[1] ** 2)
        total += np.array([xy, xy, float(bend[2] ** 2)])
    return total


def swept_turn_variance(*scans: KeyScan) -> float:
    """Sum over `scans` of the squared rotation [rad^2] each turns over half its sweep at its
    de-skew yaw rate (`KeyScan.twist`); scans without a twist or azimuth times add nothing."""
    total = 0.0
    for key_scan in scans:
        half_sweep_s = _half_sweep_s(key_scan)
        if key_scan.twist is None or half_sweep_s is None:
            continue
        total += (half_sweep_s * float(key_scan.twist[2])) ** 2
    return total


def sweep_s(scan: Scan) -> float | None:
    """How long a scan's sweep lasted [s] (None without azimuth times)."""
    times = scan.azimuth_times_ns
    if times is None or len(times) == 0:
        return None
    return float(np.max(times) - np.min(times)) / NS_PER_S


def _half_sweep_s(key_scan: KeyScan) -> float | None:
    sweep = sweep_s(key_scan.scan)
    sweep = key_scan.sweep_s if sweep is None else sweep
    return None if sweep is None else 0.5 * sweep


def turned_twist(twist: FloatArray | None, turn_rad: float) -> FloatArray | None:
    """A body twist (vx, vy, yaw rate) expressed in a frame whose x axis is turned by
    -`turn_rad` from the scan's (a point at azimuth a in the scan's frame lies at a + turn_rad
    in the new one)."""
    if twist is None:
        return None
    c, s = np.cos(turn_rad), np.sin(turn_rad)
    vx, vy, w = (float(v) for v in twist)
    return np.array([c * vx - s * vy, s * vx + c * vy, w])


def mean_acquisition_offset_s(scan: Scan) -> float | None:
    """Mean azimuth time minus the scan's reference time [s] (None without azimuth times)."""
    times = scan.azimuth_times_ns
    if times is None or len(times) == 0:
        return None
    return float(np.mean(np.asarray(times, dtype=np.float64) - float(scan.timestamp_ns))) / NS_PER_S


def motion_compensated(estimate: FloatArray, query: KeyScan, match: KeyScan) -> FloatArray:
    """A T_query_match estimated from images that are not de-skewed, moved to the scans'
    reference times.

    Without de-skewing, a scan's image is on average the scene seen from the pose at its mean
    acquisition time. With P = the pose at that time in the reference-time frame (constant body
    twist), the image estimate is P_q^-1 T_qm P_m, so T_qm = P_q * estimate * P_m^-1. For two
    scans driving in opposite directions the correction is about speed x sweep (2.5 m at 10 m/s
    over 250 ms); in the same direction at the same speed it cancels. Scans without twist or
    azimuth times are left as they are.
    """
    poses = []
    for scan in (query, match):
        offset = mean_acquisition_offset_s(scan.scan)
        if scan.twist is None or offset is None:
            poses.append(np.zeros(3))
        else:
            poses.append(motion_from_twist(scan.twist, offset))
    return compose(compose(poses[0], estimate), between(poses[1], np.zeros(3)))


class Verifier(Protocol):
    """Verifies a proposed loop between a query scan and a database (match) scan."""

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification: ...


class GeometricVerifier:
    """Sinogram relative pose, refined by phase correlation (see the module docstring).

    Caches the current query's pose spectrum and prepared scan for its several candidates. A
    database scan's pose spectrum is made each time it is a candidate (from its record in a run;
    keeping them saved nothing measurable on `synthetic/long`).

    Args:
        cfg: loop-closing settings (its `verification` section).
        odometry: the run's odometry settings, which the phase-correlation refinement uses
            (None: the defaults).

    A scan's one conditioned form (`KeyScan.polar`, the odometry's in a run; else made here) makes
    its sinogram pose image and its registration, de-skewed with its own twist (the odometry's
    images, de-skewed with the odometry's velocity, moved the SLAM ATE of `synthetic/loop` from
    0.130 to 0.138 m).
    """

    def __init__(self, cfg: LoopClosureConfig, odometry: OdometryConfig | None = None) -> None:
        self.cfg = cfg
        self.odometry = OdometryConfig() if odometry is None else odometry
        self.pose_estimator = PoseEstimator(LOOP_RAPLACE.pose)
        self._query_key: int | None = None
        self._query_spectrum: PoseSpectrum | None = None
        self._query_prepared: PreparedScan | None = None
        self._prepared_key: int | None = None

    def polar(self, scan: KeyScan) -> PolarScan:
        """The conditioned form of `scan`: its `KeyScan.polar`, else made here."""
        if scan.polar is not None:
            return scan.polar
        return preprocess_polar(scan.scan, self.odometry.preprocess)

    def prepared(self, scan: KeyScan, turn_rad: float = 0.0) -> PreparedScan:
        """The registration input of `scan` seen from a frame turned by -`turn_rad` (its
        azimuths offset by `turn_rad`, as `turned_twist`), de-skewed with its twist when the
        odometry de-skews."""
        polar = self.polar(scan)
        if turn_rad:
            polar = dataclasses.replace(polar, first_azimuth_rad=polar.first_azimuth_rad + turn_rad)
        twist = turned_twist(scan.twist, turn_rad) if self.odometry.deskew else None
        return PreparedScan(polar, twist, self.odometry)

    def _spectrum(self, scan: KeyScan) -> PoseSpectrum:
        image = self.pose_estimator.image(*raplace_input(self.polar(scan)))
        return self.pose_estimator.spectrum(image)

    def _query(self, query: KeyScan) -> PoseSpectrum:
        if self._query_key != query.key or self._query_spectrum is None:
            self._query_key = query.key
            self._query_spectrum = self._spectrum(query)
        return self._query_spectrum

    def _prepared_query(self, query: KeyScan) -> PreparedScan:
        if self._prepared_key != query.key or self._query_prepared is None:
            self._prepared_key = query.key  # `refine` may come without `_query`
            self._query_prepared = self.prepared(query)
        return self._query_prepared

    def _searched_query(
        self,
        query: KeyScan,
        prepared: PreparedScan,
        aligned: PreparedScan,
        estimate: MotionEstimate,
    ) -> MotionEstimate:
        """`estimate`, or the registration with the query de-skewed at a searched yaw rate when
        that correlates more strongly (`YAW_RATE_SEARCH`; low frame rates only;
        `odometry.searched_registration`)."""
        if not YAW_RATE_SEARCH:
            return estimate
        return searched_registration(prepared, aligned, estimate, self.odometry, query.twist_span_s)

    def __call__(self, query: KeyScan, match: KeyScan) -> Verification:
        """Verify T_query_match; never raises for a bad match (the reason says why)."""
        vcfg = self.cfg.verification
        match = dataclasses.replace(match, polar=self.polar(match))  # one conditioning
        rel: RelativePose = self.pose_estimator.estimate_spectra(
            self._query(query), self._spectrum(match)
        )
        sinogram = motion_compensated(rel.as_array(), query, match)
        nan33 = np.full((3, 3), np.nan)

        def failed(
            reason: str, measurement: FloatArray = sinogram, quality: float = 0.0
        ) -> Verification:
            return Verification(
                False, reason, measurement, nan33, sinogram, float(rel.quality), quality
            )

        if not np.isfinite(rel.quality) or rel.quality < MIN_SINOGRAM_QUALITY:
            return failed(
                f"weak sinogram alignment (correlation {rel.quality:.2f} < "
                f"{MIN_SINOGRAM_QUALITY:.2f})"
            )
        if rel.inlier_fraction < MIN_INLIER_FRACTION:
            return failed(
                f"sinogram shifts inconsistent (inliers {rel.inlier_fraction:.2f} < "
                f"{MIN_INLIER_FRACTION:.2f})"
            )
        distance_m = float(np.hypot(sinogram[0], sinogram[1]))
        if distance_m > vcfg.max_translation_m:
            return failed(
                f"scans {distance_m:.1f} m apart (more than {vcfg.max_translation_m:.1f} m)"
            )

        return self.refine(query, match, sinogram, float(rel.quality))

    def refine(
        self, query: KeyScan, match: KeyScan, initial: FloatArray, initial_quality: float
    ) -> Verification:
        """The phase-correlation half of the verification (b and c of the module docstring)
        from an initial T_query_match (3,): the sinogram estimate (`__call__`), or a prediction
        (`initial_quality` NaN; `radar_slam.loops.tracking`), which also seeds the registration
        (its coarse peak searched within `odometry.registration.HINT_RADIUS_M` of the
        prediction). Never raises for a bad match."""
        vcfg = self.cfg.verification
        nan3 = np.full(3, np.nan)
        nan33 = np.full((3, 3), np.nan)

        def failed(reason: str, measurement: FloatArray, quality: float) -> Verification:
            return Verification(
                False, reason, measurement, nan33, initial, initial_quality, quality
            )

        # Phase correlation of the query and the match turned by the initial rotation.
        turn = float(initial[2])
        aligned = self.prepared(match, turn)
        # A prediction also seeds the registration (its translation; the match is turned by its
        # rotation): one rotation and half-turn hypothesis instead of a global search.
        hint = None if np.isfinite(initial_quality) else np.array([initial[0], initial[1], 0.0])
        prepared_query = self._prepared_query(query)
        estimate = register(prepared_query, aligned, self.odometry, hint)
        estimate = self._searched_query(query, prepared_query, aligned, estimate)
        refined = compose(estimate.motion, np.array([0.0, 0.0, turn]))
        if not estimate.ok:
            return failed(f"phase correlation failed: {estimate.reason}", nan3, estimate.quality)
        if estimate.quality < vcfg.min_refined_quality:
            return failed(
                f"weak phase-correlation peak (quality {estimate.quality:.1f} < "
                f"{vcfg.min_refined_quality:.1f})",
                refined,
                estimate.quality,
            )
        disagreement = between(refined, initial)
        off_m = float(np.hypot(disagreement[0], disagreement[1]))
        off_deg = float(np.rad2deg(abs(wrap_angle(disagreement[2]))))
        if off_m > MAX_DISAGREEMENT_M or off_deg > MAX_DISAGREEMENT_DEG:
            source = "sinogram" if np.isfinite(initial_quality) else "prediction"
            return failed(
                f"{source} and phase correlation disagree by {off_m:.2f} m / {off_deg:.2f} deg "
                f"(max {MAX_DISAGREEMENT_M:.2f} m / {MAX_DISAGREEMENT_DEG:.2f} deg)",
                refined,
                estimate.quality,
            )
        covariance = loop_covariance(
            estimate.covariance,
            disagreement,
            float(refined[2]),
            LOOP_COVARIANCE,
            deskew_variance(query, match),
            swept_turn_variance(query, match),
        )
        sigma_yaw_deg = float(np.rad2deg(np.sqrt(covariance[2, 2])))
        if sigma_yaw_deg > MAX_SIGMA_YAW_DEG:
            return failed(
                f"rotation too uncertain (sigma {sigma_yaw_deg:.2f} deg > "
                f"{MAX_SIGMA_YAW_DEG:.2f} deg: a scan swept across a yaw-rate change)",
                refined,
                estimate.quality,
            )
        return Verification(
            True, "", refined, covariance, initial, initial_quality, float(estimate.quality)
        )
