"""MulRan loader on the real polar scan, copied into every supported layout under tmp_path."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from radar_slam.datasets import MulRanSequence, RadarSequence
from radar_slam.datasets.mulran import (
    OXFORD_FORM_FOLDERS,
    POLAR_FOLDERS,
    gt_max_gap_ns,
    interpolate_poses,
    is_mulran_sequence,
)
from radar_slam.datasets.navtech import MULRAN_T_BASE_RADAR
from radar_slam.errors import DatasetFormatError, DatasetNotFoundError
from raplace import se2
from raplace.units import NS_PER_S

pytestmark = pytest.mark.realdata

SCAN_STAMP_NS = 1564718976161407002
SCAN_FILE = f"polar/{SCAN_STAMP_NS}.png"
PERIOD_NS = 250_000_000
N_SCANS = 4
STAMPS = [SCAN_STAMP_NS + k * PERIOD_NS for k in range(N_SCANS)]

# Synthetic base trajectory for global_pose.csv: linear in time, so interpolation is exact and
# nearest-neighbour lookup is visibly wrong (GT rows every 100 ms, offset from the scans).
GT_START_NS = SCAN_STAMP_NS - 137_000_000
GT_STEP_NS = 100_000_000
GT_ROWS = 11  # covers GT_START .. GT_START + 1.0 s
BASE_X0, BASE_Y0, BASE_YAW0 = 353_000.0, 4_026_000.0, 0.3
BASE_VX, BASE_VY, BASE_YAW_RATE = 8.0, -3.0, 0.4  # m/s, m/s, rad/s


def base_pose_at(t_ns: np.ndarray) -> np.ndarray:
    """Analytic base pose (N, 3) of the synthetic GT at times t_ns."""
    t = (np.asarray(t_ns, dtype=np.int64) - GT_START_NS) / NS_PER_S
    return np.stack(
        [BASE_X0 + BASE_VX * t, BASE_Y0 + BASE_VY * t, BASE_YAW0 + BASE_YAW_RATE * t], axis=-1
    )


def write_global_pose(path: Path, times_ns: list[int], poses: np.ndarray) -> None:
    """Write MulRan global_pose.csv rows: t_ns, 3x4 row-major [R|t] (rotation about z)."""
    lines = []
    for t, (x, y, yaw) in zip(times_ns, poses, strict=True):
        c, s = np.cos(yaw), np.sin(yaw)
        matrix = [c, -s, 0.0, x, s, c, 0.0, y, 0.0, 0.0, 1.0, 12.5]
        lines.append(",".join([str(t)] + [repr(float(v)) for v in matrix]))
    path.write_text("\n".join(lines) + "\n")


def gt_times() -> list[int]:
    return [GT_START_NS + k * GT_STEP_NS for k in range(GT_ROWS)]


def make_sequence(
    root: Path, mulran_raw_dir: Path, relative: str = "sensor_data/radar/polar", gt: bool = True
) -> Path:
    """A MulRan-layout sequence folder: the real scan copied under N_SCANS stamps."""
    seq = root / "KAIST01"
    scans = seq / relative
    scans.mkdir(parents=True)
    for stamp in STAMPS:
        shutil.copyfile(mulran_raw_dir / SCAN_FILE, scans / f"{stamp}.png")
    if gt:
        times = gt_times()
        write_global_pose(seq / "global_pose.csv", times, base_pose_at(np.array(times)))
    return seq


@pytest.fixture(scope="module")
def real_polar(mulran_raw_dir: Path) -> np.ndarray:
    return cv2.imread(str(mulran_raw_dir / SCAN_FILE), cv2.IMREAD_UNCHANGED)


@pytest.fixture(scope="module")
def raw_csv(mulran_raw_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """(t_ns (400,) int64, table (400, 3364) float64) of the raw scan."""
    path = mulran_raw_dir / f"{SCAN_STAMP_NS}.csv"
    times = np.loadtxt(path, delimiter=",", usecols=0, dtype=np.int64)
    return times, np.loadtxt(path, delimiter=",")


@pytest.mark.parametrize("relative", POLAR_FOLDERS)
def test_every_polar_layout_loads(tmp_path: Path, mulran_raw_dir: Path, relative: str) -> None:
    seq = MulRanSequence(make_sequence(tmp_path, mulran_raw_dir, relative))
    assert isinstance(seq, RadarSequence)
    assert is_mulran_sequence(seq.folder)
    assert (seq.name, seq.family, len(seq)) == ("KAIST01", "mulran", N_SCANS)
    assert seq.timestamps_ns.dtype == np.int64
    assert seq.timestamps_ns.tolist() == STAMPS
    frame = seq[1]
    assert frame.timestamp_ns == STAMPS[1]
    assert frame.polar.shape == (400, 3360) and frame.polar.dtype == np.uint8
    assert frame.range_resolution_m == pytest.approx(0.05952)
    assert frame.max_range_m == pytest.approx(199.99, abs=0.01)


def test_polar_matches_raw_csv_and_azimuths(
    tmp_path: Path, mulran_raw_dir: Path, raw_csv: tuple[np.ndarray, np.ndarray]
) -> None:
    raw_times, table = raw_csv
    frame = MulRanSequence(make_sequence(tmp_path, mulran_raw_dir, gt=False))[0]
    # Row j of our polar is the raw scan's azimuth j; columns are the 3360 range bins.
    np.testing.assert_array_equal(frame.polar, table[:, 4:].astype(np.uint8))
    # Column 0 is encoder 9 clockwise = 9/5600*360 = 0.5786 deg clockwise = -0.5786 deg CCW.
    assert np.rad2deg(frame.azimuths_rad[0]) == pytest.approx(-0.578571, abs=1e-5)
    np.testing.assert_allclose(-np.rad2deg(frame.azimuths_rad), table[:, 1], atol=1e-5)
    np.testing.assert_allclose(np.rad2deg(np.diff(frame.azimuths_rad)), -0.9, atol=1e-9)
    # File name = last azimuth; uniform times over 250 ms stay within 10 ms of the real ones.
    assert frame.azimuth_times_ns is not None
    assert raw_times[-1] == SCAN_STAMP_NS == frame.azimuth_times_ns[-1]
    assert np.all(np.diff(frame.azimuth_times_ns) > 0)
    assert np.abs(frame.azimuth_times_ns - raw_times).max() < 10_000_000


def test_azimuth_times_use_navtech_stamp_gaps(tmp_path: Path, mulran_raw_dir: Path) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir, gt=False)
    stamps = [STAMPS[0] - 248_000_000] + STAMPS
    (seq_dir / "sensor_data" / "navtech_top_stamp.csv").write_text(
        "\n".join(str(s) for s in stamps) + "\n"
    )
    frame = MulRanSequence(seq_dir)[0]
    assert frame.azimuth_times_ns is not None
    span = frame.azimuth_times_ns[-1] - frame.azimuth_times_ns[0]
    assert span == pytest.approx(248_000_000 * 399 / 400, abs=2)


def test_polar_oxford_form(tmp_path: Path, real_polar: np.ndarray) -> None:
    scans = tmp_path / "DCC01" / OXFORD_FORM_FOLDERS[0]
    scans.mkdir(parents=True)
    times = SCAN_STAMP_NS - (399 - np.arange(400, dtype=np.int64)) * 625_000
    encoders = (9 + 14 * np.arange(400)).astype("<u2")
    header = np.concatenate(
        [
            times.astype("<i8").view(np.uint8).reshape(400, 8),
            encoders.view(np.uint8).reshape(400, 2),
            np.full((400, 1), 255, np.uint8),
        ],
        axis=1,
    )
    image = np.concatenate([header, real_polar.T], axis=1)
    assert image.shape == (400, 3371)
    cv2.imwrite(str(scans / f"{SCAN_STAMP_NS}.png"), image)
    frame = MulRanSequence(tmp_path / "DCC01")[0]
    np.testing.assert_array_equal(frame.polar, real_polar.T)
    np.testing.assert_array_equal(frame.azimuth_times_ns, times)
    assert np.rad2deg(frame.azimuths_rad[0]) == pytest.approx(-0.578571, abs=1e-5)
    assert frame.timestamp_ns == SCAN_STAMP_NS


def test_ground_truth_interpolated_with_extrinsic(tmp_path: Path, mulran_raw_dir: Path) -> None:
    seq = MulRanSequence(make_sequence(tmp_path, mulran_raw_dir))
    gt = seq.ground_truth
    assert gt is not None and gt.shape == (N_SCANS, 3)
    base = base_pose_at(np.array(STAMPS))
    # T_world_radar = T_world_base * T_base_radar, by explicit matrices.
    expected = se2.from_matrix(se2.to_matrix(base) @ se2.to_matrix(MULRAN_T_BASE_RADAR))
    np.testing.assert_allclose(gt[:, :2], expected[:, :2], atol=1e-6)
    np.testing.assert_allclose(se2.wrap_angle(gt[:, 2] - expected[:, 2]), 0.0, atol=1e-9)
    # The radar is 1.50 m ahead of the base: about 1.5 m away, yaw +0.9 deg more.
    assert np.hypot(*(gt[0, :2] - base[0, :2])) == pytest.approx(np.hypot(1.5, 0.04), abs=1e-9)
    # Nearest-neighbour GT (37 ms before the scan) would be 0.30 m off in x: not what we do.
    nearest = base_pose_at(np.array([GT_START_NS + 100_000_000]))[0]
    assert abs(base[0, 0] - nearest[0]) > 0.25


def test_interpolation_wraps_yaw_and_never_holds_an_end() -> None:
    times = np.array([0, NS_PER_S], dtype=np.int64)
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 4.0, -np.pi + 0.1]])
    queries = np.array([500_000_000, -1, NS_PER_S + 1, NS_PER_S], dtype=np.int64)
    result = interpolate_poses(times, poses, queries)
    np.testing.assert_allclose(result[0, :2], [1.0, 2.0])
    assert abs(se2.wrap_angle(result[0, 2] - np.pi)) < 1e-12  # through +-pi, not through 0
    assert np.all(np.isnan(result[1:3]))  # just before or past the span: unknown, not held
    np.testing.assert_allclose(result[3], poses[1])  # at the end: exact


def test_interpolation_leaves_an_outage_without_poses() -> None:
    """Samples every 0.1 s with 1 s missing: queries inside the outage have no pose, however
    near its edges; those before and after it are interpolated."""
    times = np.concatenate([np.arange(0, 5), np.arange(15, 20)]) * 100_000_000
    poses = np.column_stack([times / 1e8, np.zeros(10), np.zeros(10)])
    queries = np.array([350_000_000, 410_000_000, 1_000_000_000, 1_550_000_000], dtype=np.int64)
    result = interpolate_poses(times, poses, queries, max_gap_ns=gt_max_gap_ns(times))
    assert np.isfinite(interpolate_poses(times, poses, queries)).all()  # no limit asked
    np.testing.assert_allclose(result[[0, 3], 0], [3.5, 15.5])
    assert np.all(np.isnan(result[1:3]))


def test_scans_outside_gt_are_nan_with_warning(
    tmp_path: Path, mulran_raw_dir: Path, caplog: pytest.LogCaptureFixture
) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir, gt=False)
    # GT rows every 0.1 s end at scan 0 + 0.063 s: scan 1 (0.187 s past the end, more than one
    # GT period) and later have no GT; nothing is stretched to them.
    times = gt_times()[:3]
    write_global_pose(seq_dir / "global_pose.csv", times, base_pose_at(np.array(times)))
    with caplog.at_level(logging.WARNING):
        gt = MulRanSequence(seq_dir).ground_truth
    assert gt is not None
    assert np.isfinite(gt[0]).all() and np.isnan(gt[1:]).all()
    assert "3 of 4 scans" in caplog.text and "global_pose.csv" in caplog.text


def test_no_gt_and_lazy_frames(tmp_path: Path, mulran_raw_dir: Path) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir, gt=False)
    scan_dir = seq_dir / POLAR_FOLDERS[0]
    (scan_dir / f"{STAMPS[2]}.png").write_bytes(b"not a png")  # only read when asked for
    seq = MulRanSequence(seq_dir)
    assert seq.ground_truth is None
    assert seq[-1].timestamp_ns == STAMPS[-1]
    with pytest.raises(IndexError):
        seq[N_SCANS]


def test_loader_never_writes(tmp_path: Path, mulran_raw_dir: Path) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir)
    before = sorted((p, p.stat().st_mtime_ns) for p in seq_dir.rglob("*"))
    seq = MulRanSequence(seq_dir)
    _ = [seq[k] for k in range(len(seq))], seq.ground_truth
    assert sorted((p, p.stat().st_mtime_ns) for p in seq_dir.rglob("*")) == before


# ---- bad input -------------------------------------------------------------------------------


def test_missing_folder_and_empty_folders(tmp_path: Path) -> None:
    with pytest.raises(DatasetNotFoundError, match="does not exist"):
        MulRanSequence(tmp_path / "nope")
    (tmp_path / "seq").mkdir()
    with pytest.raises(DatasetFormatError, match="no MulRan scan folder"):
        MulRanSequence(tmp_path / "seq")
    (tmp_path / "seq" / "polar").mkdir()
    with pytest.raises(DatasetFormatError, match=r"polar: no scans"):
        MulRanSequence(tmp_path / "seq")


@pytest.mark.parametrize("content", ["truncated", "garbage"])
def test_unreadable_png(tmp_path: Path, mulran_raw_dir: Path, content: str) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir, gt=False)
    bad = seq_dir / POLAR_FOLDERS[0] / f"{STAMPS[1]}.png"
    raw = bad.read_bytes()
    bad.write_bytes(raw[: len(raw) // 2] if content == "truncated" else b"\x89PNG garbage")
    seq = MulRanSequence(seq_dir)
    with pytest.raises(DatasetFormatError, match=rf"{STAMPS[1]}\.png: cannot decode PNG"):
        seq[1]


def test_wrong_shape(tmp_path: Path, real_polar: np.ndarray) -> None:
    scans = tmp_path / "seq" / "polar"
    scans.mkdir(parents=True)
    cv2.imwrite(str(scans / "1000.png"), real_polar.T)  # transposed: 400 x 3360
    cv2.imwrite(str(scans / "2000.png"), np.zeros((3360, 400, 3), np.uint8))  # colour
    seq = MulRanSequence(tmp_path / "seq")
    with pytest.raises(DatasetFormatError, match=r"1000\.png: scan has shape 400 x 3360"):
        seq[0]
    with pytest.raises(DatasetFormatError, match=r"2000\.png: expected an 8-bit single-channel"):
        seq[1]


def test_duplicated_scan_stamps(tmp_path: Path, mulran_raw_dir: Path) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir, gt=False)
    scans = seq_dir / POLAR_FOLDERS[0]
    shutil.copyfile(scans / f"{STAMPS[0]}.png", scans / f"0{STAMPS[0]}.png")
    with pytest.raises(DatasetFormatError, match="duplicated scan timestamp"):
        MulRanSequence(seq_dir)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda rows: rows[:2] + [rows[3], rows[2]] + rows[4:], "unsorted timestamp"),
        (lambda rows: rows[:3] + [rows[2]] + rows[3:], "duplicated timestamp"),
        (lambda rows: rows[:4] + [rows[4].replace(",1.0,", ",nan,")] + rows[5:], "NaN"),
        (lambda rows: [row.rsplit(",", 1)[0] for row in rows], "has 12 columns, expected 13"),
        (lambda rows: rows[:1] + ["1.5e18" + rows[1][19:]] + rows[2:], "not an integer"),
        (lambda rows: rows[:1] + [rows[1].replace(",1.0,", ",one,")] + rows[2:], "non-numeric"),
        (lambda rows: [], "no data rows"),
    ],
)
def test_bad_global_pose(tmp_path: Path, mulran_raw_dir: Path, mutate, message: str) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir)
    path = seq_dir / "global_pose.csv"
    path.write_text("\n".join(mutate(path.read_text().splitlines())) + "\n")
    seq = MulRanSequence(seq_dir)
    with pytest.raises(DatasetFormatError, match=message) as info:
        _ = seq.ground_truth
    assert "global_pose.csv" in str(info.value)


def test_bad_navtech_stamps(tmp_path: Path, mulran_raw_dir: Path) -> None:
    seq_dir = make_sequence(tmp_path, mulran_raw_dir, gt=False)
    (seq_dir / "sensor_data" / "navtech_top_stamp.csv").write_text(
        "\n".join(str(s) for s in reversed(STAMPS)) + "\n"
    )
    with pytest.raises(DatasetFormatError, match="navtech_top_stamp.csv: unsorted"):
        MulRanSequence(seq_dir)
