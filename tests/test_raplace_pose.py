"""Known-answer tests of the relative pose from sinogram spectra (rotation, pi ambiguity, shift)."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest
from raplace_scenes import angle_error, relative, render_cart, synthetic_world

from raplace import RaPlaceError
from raplace.config import ImageConfig, PoseConfig, PreprocessConfig
from raplace.pose import PoseEstimator, fit_translation, relative_pose
from raplace.preprocess import CartesianImager
from raplace.se2 import compose

WORLD_CELL_M = 0.25
CFG = PoseConfig()
ROTATION_TOLERANCE_DEG = 1.0
TRANSLATION_TOLERANCE_M = 0.5

# (query pose, map pose) in the world: rotations including 0 and 180 deg, shifts up to 10 m.
POSE_PAIRS = [
    ((0.0, 0.0, 0.0), (10.0, 0.0, 0.0)),
    ((3.0, -2.0, 0.5), (3.0, -2.0, 0.5 + np.pi)),
    ((-4.0, 6.0, -1.2), (2.0, 14.0, -1.2 + np.pi)),
    ((1.0, 1.0, 2.0), (-5.0, 8.0, 2.0 + np.deg2rad(37.0))),
    ((0.0, 0.0, 0.3), (7.07, -7.07, 0.3 - np.deg2rad(123.4))),
    ((12.0, 3.0, -2.5), (12.5, 3.0, -2.5 + np.deg2rad(179.3))),
]


def _check(estimate, truth) -> None:
    assert abs(estimate.dx_m - truth[0]) < TRANSLATION_TOLERANCE_M
    assert abs(estimate.dy_m - truth[1]) < TRANSLATION_TOLERANCE_M
    assert np.rad2deg(angle_error(estimate.dyaw_rad, truth[2])) < ROTATION_TOLERANCE_DEG


@pytest.fixture(scope="module")
def world() -> np.ndarray:
    return synthetic_world(1200, seed=2)  # 300 m x 300 m


@pytest.fixture(scope="module")
def oxford_world(oxford_polar_scans) -> np.ndarray:
    """A cleaned 150 m-radius Cartesian image of the first Oxford scan, used as a world."""
    imager = CartesianImager(
        PreprocessConfig(), ImageConfig(cell_m=WORLD_CELL_M, max_range_m=150.0, taper_fraction=0.0)
    )
    return imager(*oxford_polar_scans[0])


def _crop(world: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
    return render_cart(world, WORLD_CELL_M, pose, CFG.image.cell_m, CFG.image.max_range_m)


@pytest.mark.parametrize(("pose_q", "pose_m"), POSE_PAIRS)
def test_synthetic_rotation_and_translation(world, pose_q, pose_m) -> None:
    estimate = relative_pose(_crop(world, pose_q), _crop(world, pose_m), CFG.image.cell_m, CFG)
    _check(estimate, relative(pose_q, pose_m))
    assert estimate.quality > 0.8
    assert estimate.residual_m < 0.1
    assert estimate.alternative_residual_m > 3 * estimate.residual_m


@pytest.mark.realdata
@pytest.mark.parametrize(("pose_q", "pose_m"), POSE_PAIRS)
def test_oxford_crops_rotation_and_translation(oxford_world, pose_q, pose_m) -> None:
    estimate = relative_pose(
        _crop(oxford_world, pose_q), _crop(oxford_world, pose_m), CFG.image.cell_m, CFG
    )
    _check(estimate, relative(pose_q, pose_m))
    assert estimate.quality > 0.8


@pytest.mark.realdata
def test_oxford_consecutive_scans_match_ground_truth(oxford_dir, oxford_polar_scans) -> None:
    """Real scan pairs about 2 m apart against the dataset's radar odometry (x-fwd, y-right)."""
    stems = sorted(p.stem for p in (oxford_dir / "radar").glob("*.png"))
    with open(oxford_dir / "gt" / "radar_odometry.csv") as handle:
        rows = {r["destination_radar_timestamp"]: r for r in csv.DictReader(handle)}
    estimator = PoseEstimator(CFG)
    images = [estimator.image(*scan) for scan in oxford_polar_scans]
    for i in range(len(oxford_polar_scans) - 1):
        row = rows[stems[i]]
        assert row["source_radar_timestamp"] == stems[i + 1]
        # Later scan in the earlier scan's frame; y-left, CCW yaw flip the signs of y and yaw.
        truth = (float(row["x"]), -float(row["y"]), -float(row["yaw"]))
        _check(estimator.estimate(images[i], images[i + 1]), truth)
        # The same pair with the map scan turned around: yaw + pi, same translation.
        turned = np.rot90(images[i + 1], 2).copy()
        _check(estimator.estimate(images[i], turned), (truth[0], truth[1], truth[2] + np.pi))


@pytest.mark.realdata
def test_oxford_scans_far_apart_keep_their_inliers(oxford_dir, oxford_polar_scans) -> None:
    """Real scans 12.5 m apart: with the radial streaks removed (the default) most angles'
    shifts fit the translation; with them kept, the streaks, which stay with the sensor, pull
    the angles along the road to zero shift."""
    first, last = oxford_polar_scans[0], oxford_polar_scans[-1]
    stems = sorted(p.stem for p in (oxford_dir / "radar").glob("*.png"))
    with open(oxford_dir / "gt" / "radar_odometry.csv") as handle:
        rows = {r["destination_radar_timestamp"]: r for r in csv.DictReader(handle)}
    truth = np.zeros(3)  # the last scan in the first one's frame (x-fwd, y-left, CCW)
    for stem in stems[:-1]:
        row = rows[stem]
        truth = compose(truth, np.array([float(row["x"]), -float(row["y"]), -float(row["yaw"])]))
    assert np.hypot(truth[0], truth[1]) > 12.0
    inliers = {}
    for spokes in (True, False):
        cfg = dataclasses.replace(
            CFG, preprocess=dataclasses.replace(CFG.preprocess, spoke_removal=spokes)
        )
        estimator = PoseEstimator(cfg)
        estimate = estimator.estimate(estimator.image(*first), estimator.image(*last))
        _check(estimate, truth)
        inliers[spokes] = estimate.inlier_fraction
    assert inliers[True] > 0.4
    assert inliers[False] < 0.35


@pytest.mark.realdata
def test_quality_separates_same_and_other_place(oxford_polar_scans, world) -> None:
    estimator = PoseEstimator(CFG)
    same = estimator.estimate(
        estimator.image(*oxford_polar_scans[0]), estimator.image(*oxford_polar_scans[2])
    )
    other = relative_pose(
        estimator.image(*oxford_polar_scans[0]),
        _crop(world, (0.0, 0.0, 0.0)),
        CFG.image.cell_m,
        CFG,
    )
    assert same.quality > 0.5
    assert other.quality < 0.2
    assert other.residual_m > 2 * same.residual_m


def test_fit_translation_rejects_outliers() -> None:
    thetas = np.arange(180) * np.pi / 180
    shifts = 3.0 * np.cos(thetas) - 7.5 * np.sin(thetas)
    rng = np.random.default_rng(0)
    bad = rng.choice(180, 50, replace=False)
    shifts[bad] += rng.choice([-1.0, 1.0], 50) * rng.uniform(5, 60, 50)  # far from the truth
    xy, residual, inliers = fit_translation(thetas, shifts, threshold_m=1.0)
    np.testing.assert_allclose(xy, [3.0, -7.5], atol=1e-9)
    assert inliers.sum() == 130
    assert residual == pytest.approx(np.sqrt(50 / 180), rel=0.05)


def test_relative_pose_rejects_mismatched_images() -> None:
    with pytest.raises(RaPlaceError):
        relative_pose(np.zeros((64, 64)), np.zeros((32, 32)), 0.5, CFG)


def test_prepared_query_spectrum_gives_the_plain_pose(world) -> None:
    """One query spectrum reused against several maps gives exactly the two-image result."""
    estimator = PoseEstimator(CFG)
    query_image = _crop(world, POSE_PAIRS[3][0])
    query = estimator.spectrum(query_image)
    for _, pose_m in POSE_PAIRS[3:]:
        map_image = _crop(world, pose_m)
        reused = estimator.estimate_spectra(query, estimator.spectrum(map_image))
        assert reused == estimator.estimate(query_image, map_image)
        _check(reused, relative(POSE_PAIRS[3][0], pose_m))
    with pytest.raises(RaPlaceError, match="spectra differ"):
        small = estimator.spectrum(query_image[:-2, :-2])
        estimator.estimate_spectra(query, small)
