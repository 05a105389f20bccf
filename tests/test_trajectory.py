"""Trajectory type, TUM/KITTI round trips and bad files, and the trajectory/PR plots."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from radar_slam.errors import TrajectoryError
from radar_slam.plots import display_origin, plot_pr_curves, plot_trajectories
from radar_slam.trajectory import (
    Trajectory,
    detect_format,
    format_ns_as_seconds,
    parse_seconds_as_ns,
    read_kitti,
    read_trajectory,
    read_tum,
    write_kitti,
    write_tum,
)

ROUND_TRIP_TOL = 1e-9
T0_NS = 1_564_718_976_161_407_002  # a MulRan-like epoch time with full ns precision
PNG_MAGIC = b"\x89PNG"


def curved_trajectory(n: int = 50, seed: int = 0) -> Trajectory:
    """A smooth random drive: 1 m steps, yaw rate up to ~0.1 rad per step, 10 Hz stamps."""
    rng = np.random.default_rng(seed)
    motions = np.column_stack([np.ones(n - 1), np.zeros(n - 1), rng.uniform(-0.1, 0.1, n - 1)])
    stamps = T0_NS + np.arange(n, dtype=np.int64) * 100_000_000 + rng.integers(0, 999, n)
    return Trajectory.from_relative_motions(stamps, motions, start=(3.0, -2.0, 3.0))


# ---------------------------------------------------------------------- the type
def test_validation_errors() -> None:
    with pytest.raises(TrajectoryError, match="counts must match"):
        Trajectory(np.arange(3), np.zeros((2, 3)))
    with pytest.raises(TrajectoryError, match="not finite"):
        Trajectory(np.arange(2), [[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    with pytest.raises(TrajectoryError, match="strictly increasing"):
        Trajectory(np.array([0, 5, 5]), np.zeros((3, 3)))
    with pytest.raises(TrajectoryError, match=r"shape \(N, 3\)"):
        Trajectory(np.arange(2), np.zeros((2, 2)))
    with pytest.raises(TrajectoryError, match="integer nanoseconds"):
        Trajectory(np.array([0.5, 1.0]), np.zeros((2, 3)))


def test_yaw_wrapped_and_arrays_read_only() -> None:
    traj = Trajectory(np.array([1, 2]), [[0.0, 0.0, 3 * np.pi / 2], [1.0, 0.0, -np.pi / 2]])
    assert traj.poses[:, 2] == pytest.approx([-np.pi / 2, -np.pi / 2])
    assert traj.timestamps_ns.dtype == np.int64
    with pytest.raises(ValueError):
        traj.poses[0, 0] = 1.0


def test_from_arrays_drops_nonfinite_rows() -> None:
    poses = np.array([[np.nan] * 3, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [np.nan] * 3])
    traj = Trajectory.from_arrays(np.arange(4) * 10, poses, drop_nonfinite=True)
    assert traj.timestamps_ns.tolist() == [10, 20]
    with pytest.raises(TrajectoryError):
        Trajectory.from_arrays(np.arange(4), poses)


def test_length_selection_and_relative_motions() -> None:
    square = Trajectory.from_relative_motions(np.arange(5), [[2.0, 0.0, np.pi / 2]] * 4)
    assert square.length_m() == pytest.approx(8.0)
    assert square.path_distances_m() == pytest.approx([0, 2, 4, 6, 8])
    np.testing.assert_allclose(square.poses[-1, :2], [0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(square.relative_motions(), [[2.0, 0.0, np.pi / 2]] * 4, atol=1e-12)
    assert len(square[1:3]) == 2
    assert square[[0, 4]].timestamps_ns.tolist() == [0, 4]
    assert square[square.timestamps_ns % 2 == 0].timestamps_ns.tolist() == [0, 2, 4]
    assert square.between_times(1, 3).timestamps_ns.tolist() == [1, 2, 3]
    assert Trajectory(np.zeros(0, np.int64), np.zeros((0, 3))).length_m() == 0.0


# ---------------------------------------------------------------------- timestamps as text
@pytest.mark.parametrize(
    ("text", "ns"),
    [
        ("1564718976.161407002", 1_564_718_976_161_407_002),
        ("12", 12_000_000_000),
        ("1.5e9", 1_500_000_000_000_000_000),
        ("-0.000000001", -1),
        ("0.0000000014", 1),
    ],
)
def test_parse_seconds(text: str, ns: int) -> None:
    assert parse_seconds_as_ns(text) == ns


def test_format_seconds() -> None:
    assert format_ns_as_seconds(T0_NS) == "1564718976.161407002"
    assert format_ns_as_seconds(-1) == "-0.000000001"
    assert parse_seconds_as_ns(format_ns_as_seconds(-1_500_000_001)) == -1_500_000_001


# ---------------------------------------------------------------------- round trips
def test_tum_round_trip_exact(tmp_path: Path) -> None:
    traj = curved_trajectory()
    path = tmp_path / "est.tum"
    write_tum(path, traj)
    assert path.read_text().split()[0] == format_ns_as_seconds(traj.timestamps_ns[0])
    back = read_tum(path)
    np.testing.assert_array_equal(back.timestamps_ns, traj.timestamps_ns)
    np.testing.assert_allclose(back.poses, traj.poses, rtol=0, atol=ROUND_TRIP_TOL)
    assert detect_format(path) == "tum"


def test_kitti_round_trip_exact(tmp_path: Path) -> None:
    traj = curved_trajectory()
    path = tmp_path / "est.kitti"
    write_kitti(path, traj)
    back = read_kitti(path, traj.timestamps_ns)
    np.testing.assert_array_equal(back.timestamps_ns, traj.timestamps_ns)
    np.testing.assert_allclose(back.poses, traj.poses, rtol=0, atol=ROUND_TRIP_TOL)
    assert read_kitti(path).timestamps_ns.tolist() == list(range(len(traj)))
    assert detect_format(path) == "kitti"
    np.testing.assert_allclose(read_trajectory(path).poses, traj.poses, atol=ROUND_TRIP_TOL)


def test_3d_files_projected_to_se2(tmp_path: Path) -> None:
    yaw, pitch, roll = 0.7, 0.05, -0.03
    rot = Rotation.from_euler("ZYX", [yaw, pitch, roll])
    qx, qy, qz, qw = rot.as_quat()
    tum = tmp_path / "a.tum"
    tum.write_text(f"# header\n1.0 2.0 3.0 4.5 {qx} {qy} {qz} {qw}\n\n2.0 2.0 3.0 4.5 0 0 0 2\n")
    traj = read_tum(tum)
    np.testing.assert_allclose(traj.poses, [[2.0, 3.0, yaw], [2.0, 3.0, 0.0]], atol=1e-12)
    kitti = tmp_path / "a.txt"
    mat = np.hstack([rot.as_matrix(), [[2.0], [3.0], [4.5]]])
    kitti.write_text(" ".join(map(repr, mat.ravel().tolist())) + "\n")
    np.testing.assert_allclose(read_kitti(kitti).poses, [[2.0, 3.0, yaw]], atol=1e-12)


# ---------------------------------------------------------------------- bad files
GOOD_TUM = "1.0 0 0 0 0 0 0 1"


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", "empty"),
        ("# only a comment\n", "empty"),
        (f"{GOOD_TUM}\n2.0 0 0 0 0 0 1\n", r":2: expected 8 columns"),
        (f"{GOOD_TUM}\n2.0 0 0 zero 0 0 0 1\n", r":2: non-numeric"),
        (f"{GOOD_TUM}\n2.0 nan 0 0 0 0 0 1\n", r":2: NaN"),
        (f"{GOOD_TUM}\n# c\n0.5 0 0 0 0 0 0 1\n", r":3: timestamp 0.5 s does not increase"),
        (f"{GOOD_TUM}\n1.000000000 0 0 0 0 0 0 1\n", r":2: .*strictly increasing"),
        (f"{GOOD_TUM}\n2.0 0 0 0 0 0 0 0\n", r":2: zero quaternion"),
    ],
)
def test_bad_tum_files(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "bad.tum"
    path.write_text(content)
    with pytest.raises(TrajectoryError, match=message) as info:
        read_tum(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("1 0 0 0 0 1 0 0 0 0 1\n", r":1: expected 12 columns"),
        ("1 0 0 0 0 1 0 0 0 0 1 inf\n", r":1: NaN or infinite"),
    ],
)
def test_bad_kitti_files(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "bad.kitti"
    path.write_text(content)
    with pytest.raises(TrajectoryError, match=message):
        read_kitti(path)


def test_kitti_timestamp_count_and_unknown_layout(tmp_path: Path) -> None:
    path = tmp_path / "a.kitti"
    write_kitti(path, curved_trajectory(5))
    with pytest.raises(TrajectoryError, match="5 poses but 4 timestamps"):
        read_kitti(path, np.arange(4))
    odd = tmp_path / "odd.txt"
    odd.write_text("1 2 3\n")
    with pytest.raises(TrajectoryError, match="neither TUM"):
        detect_format(odd)
    with pytest.raises(TrajectoryError, match="cannot read"):
        read_tum(tmp_path / "missing.tum")


# ---------------------------------------------------------------------- plots
def test_plots_write_png(tmp_path: Path) -> None:
    gt = curved_trajectory(30)
    est = Trajectory(gt.timestamps_ns, gt.poses + [0.5, 0.0, 0.0])
    loops = np.array([[0.0, 0.0, 5.0, 5.0], [1.0, 1.0, 2.0, 2.0]])
    png = tmp_path / "trajectory.png"
    plot_trajectories(png, {"odometry": est, "gt": gt}, loops=loops, title="test")
    assert png.read_bytes()[:4] == PNG_MAGIC
    pr = tmp_path / "pr.png"
    plot_pr_curves(pr, {"raplace": (np.array([1.0, 0.8, 0.5]), np.array([0.1, 0.5, 0.9]))})
    assert pr.read_bytes()[:4] == PNG_MAGIC


def test_display_origin_is_the_first_gt_position() -> None:
    """UTM-like coordinates are drawn relative to the first GT pose (or the first trajectory)."""
    gt = curved_trajectory(10)
    utm = Trajectory(gt.timestamps_ns, gt.poses + [353000.0, 4026000.0, 0.0])
    est = Trajectory(gt.timestamps_ns, gt.poses)
    np.testing.assert_allclose(display_origin({"slam": est, "gt": utm}), utm.positions[0])
    np.testing.assert_allclose(display_origin({"slam": est}), est.positions[0])
    np.testing.assert_allclose(display_origin({}), [0.0, 0.0])
