"""The Boreas localisation benchmark's form of localisation results: round trip, the covariance
moved to a left perturbation, bad files named in one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from radar_slam.maps.boreas import (
    COLUMNS,
    BoreasFormatError,
    left_covariance,
    read_boreas,
    write_boreas,
)
from radar_slam.maps.localizer import Localization
from raplace import compose, rotate_covariance

KEYFRAME_NS = np.array([1_000_000_123, 1_250_000_456, 1_500_000_789], dtype=np.int64)


def placed(t_ns: int, key: int, relative: list[float], sigmas: list[float]) -> Localization:
    covariance = np.diag(np.square(sigmas))
    return Localization(t_ns, "tracked", np.zeros(3), key, 12.0, np.array(relative), covariance)


def test_left_covariance_known_answer() -> None:
    """A scan 2 m ahead of its keyframe, turned by +90 deg: its own x is the keyframe's y, and a
    yaw error about the scan moves it along the keyframe's y by -2 m per radian."""
    a, b, c = 0.04, 0.09, 0.01
    left = left_covariance(np.array([2.0, 0.0, np.pi / 2]), np.diag([a, b, c]))
    expected = np.array([[b, 0.0, 0.0], [0.0, a + 4 * c, -2 * c], [0.0, -2 * c, c]])
    np.testing.assert_allclose(left, expected, atol=1e-12)


def test_left_covariance_matches_sampled_poses() -> None:
    """Right-perturbed samples of a pose, seen as left perturbations, have the covariance it
    gives (to the sampling error), and not the right one rotated only."""
    rng = np.random.default_rng(4)
    relative = np.array([6.0, -3.0, 0.7])
    right = np.array([[0.09, 0.02, 0.001], [0.02, 0.04, 0.0], [0.001, 0.0, 0.002]])
    xi = rng.multivariate_normal(np.zeros(3), right, size=40_000)
    samples = compose(relative, xi)  # T Exp(xi), xi small
    delta = samples - relative
    # Left perturbation: T' = Exp(xi_l) T, so xi_l's translation is t' - R(d yaw) t.
    d_yaw = delta[:, 2]
    c, s = np.cos(d_yaw), np.sin(d_yaw)
    moved = np.column_stack([c * relative[0] - s * relative[1], s * relative[0] + c * relative[1]])
    xi_left = np.column_stack([samples[:, :2] - moved, d_yaw])
    sampled = np.cov(xi_left.T)
    np.testing.assert_allclose(left_covariance(relative, right), sampled, rtol=0.05, atol=2e-4)
    rotated_only = rotate_covariance(right, float(relative[2]))
    assert abs(rotated_only[1, 1] - sampled[1, 1]) > 0.1 * sampled[1, 1]


def test_round_trip(tmp_path: Path) -> None:
    fixes = [
        placed(2_000_000_999, 0, [1.5, -0.25, 0.1], [0.2, 0.1, 0.01]),
        Localization(2_250_000_000, "lost", np.full(3, np.nan), -1, 0.0),
        placed(2_500_001_500, 2, [-3.0, 0.5, np.pi - 0.02], [0.3, 0.3, 0.02]),
    ]
    path = tmp_path / "loc.txt"
    write_boreas(path, fixes, KEYFRAME_NS)
    rows = path.read_text().splitlines()
    assert len(rows) == 2 and all(len(r.split()) == COLUMNS for r in rows)  # lost: no line
    read = read_boreas(path)
    np.testing.assert_array_equal(read.scan_us, [2_000_000, 2_500_001])
    np.testing.assert_array_equal(read.reference_us, [1_000_000, 1_500_000])
    np.testing.assert_allclose(read.relative, [fixes[0].relative, fixes[2].relative], atol=1e-12)
    assert read.information is not None
    for info, f in zip(read.information, (fixes[0], fixes[2]), strict=True):
        planar = info[np.ix_((0, 1, 5), (0, 1, 5))]
        np.testing.assert_allclose(
            np.linalg.inv(planar), left_covariance(f.relative, f.covariance), rtol=1e-9
        )
        assert not info[(2, 3, 4), :].any() and not info[:, (2, 3, 4)].any()


def test_pose_only_files_are_read(tmp_path: Path) -> None:
    path = tmp_path / "poses.txt"
    path.write_text("10 5 0 -1 0 2.0 1 0 0 3.0 0 0 1 0\n")
    read = read_boreas(path)
    assert read.information is None
    np.testing.assert_allclose(read.relative, [[2.0, 3.0, np.pi / 2]])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("10 5 1 0 0\n", "poses.txt:1: expected 14 or 50 columns"),
        ("10 5 0 -1 0 2.0 1 0 0 3.0 0 0 1 0\n10 5 0 -1 0\n", "poses.txt:2: expected"),
        ("10 5 0 -1 0 2.0 1 0 0 x 0 0 1 0\n", "poses.txt:1: not a number"),
    ],
)
def test_bad_files_name_the_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "poses.txt"
    path.write_text(text)
    with pytest.raises(BoreasFormatError, match=message):
        read_boreas(path)
