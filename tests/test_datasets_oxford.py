"""Oxford Radar RobotCar loader on the 7 real scans and their radar odometry GT."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from radar_slam.datasets import OxfordSequence, RadarSequence
from radar_slam.datasets.oxford import is_oxford_sequence
from radar_slam.errors import DatasetFormatError
from raplace import se2

pytestmark = pytest.mark.realdata

N_FRAMES = 7
ODOMETRY_CSV = "gt/radar_odometry.csv"


def copy_sequence(oxford_dir: Path, target: Path, n_scans: int = 3, gt: bool = True) -> Path:
    """A writable copy of the first `n_scans` scans (plus radar.timestamps and GT)."""
    (target / "radar").mkdir(parents=True)
    lines = (oxford_dir / "radar.timestamps").read_text().splitlines()[:n_scans]
    (target / "radar.timestamps").write_text("\n".join(lines) + "\n")
    for line in lines:
        name = f"{line.split()[0]}.png"
        shutil.copyfile(oxford_dir / "radar" / name, target / "radar" / name)
    if gt:
        (target / "gt").mkdir()
        shutil.copyfile(oxford_dir / ODOMETRY_CSV, target / ODOMETRY_CSV)
    return target


def test_frames(oxford: OxfordSequence) -> None:
    assert isinstance(oxford, RadarSequence)
    assert is_oxford_sequence(oxford.folder)
    assert (len(oxford), oxford.family, oxford.name) == (
        N_FRAMES,
        "oxford",
        "2019-01-10-14-36-48-partial",
    )
    frame = oxford[0]
    assert frame.polar.shape == (400, 3768) and frame.polar.dtype == np.uint8
    assert frame.range_resolution_m == pytest.approx(0.0438)
    # Encoder 13, 27, ... clockwise -> CCW azimuths decreasing by 0.9 deg per row.
    assert np.rad2deg(frame.azimuths_rad[0]) == pytest.approx(-13 / 5600 * 360)
    np.testing.assert_allclose(np.rad2deg(np.diff(frame.azimuths_rad)), -0.9, atol=1e-9)
    assert frame.azimuth_times_ns is not None
    assert frame.azimuth_times_ns[0] == 1547131046353776 * 1000  # file name = first azimuth
    sweep_ms = (frame.azimuth_times_ns[-1] - frame.azimuth_times_ns[0]) / 1e6
    assert 245 < sweep_ms < 256


def test_timestamps_are_mid_scan(oxford: OxfordSequence) -> None:
    stamps = oxford.timestamps_ns
    assert stamps.dtype == np.int64 and len(stamps) == N_FRAMES
    gaps_ms = np.diff(stamps) / 1e6
    assert np.all((gaps_ms > 240) & (gaps_ms < 260))
    for index in (0, 3, 6):
        frame = oxford[index]
        assert frame.timestamp_ns == stamps[index]
        assert frame.azimuth_times_ns is not None
        middle = (int(frame.azimuth_times_ns[0]) + int(frame.azimuth_times_ns[-1])) // 2
        assert abs(frame.timestamp_ns - middle) <= 1000  # GT source_timestamp, us precision


def test_ground_truth_composed(oxford: OxfordSequence, oxford_dir: Path) -> None:
    gt = oxford.ground_truth
    assert gt is not None and gt.shape == (N_FRAMES, 3)
    np.testing.assert_array_equal(gt[0], 0.0)
    motion = se2.relative_motions(gt)
    assert np.all((motion[:, 0] > 1.8) & (motion[:, 0] < 2.5))  # about +2 m forward per scan
    assert np.all(np.abs(motion[:, 1]) < 0.1)
    assert np.all(np.abs(motion[:, 2]) < np.deg2rad(1.0))
    assert 12.0 < np.sum(np.hypot(motion[:, 0], motion[:, 1])) < 13.0
    # One raw row: later scan (source) in the earlier scan's y-right frame -> (x, -y, -yaw).
    table = np.loadtxt(oxford_dir / ODOMETRY_CSV, delimiter=",", skiprows=1)
    stamps_us = np.loadtxt(oxford_dir / "radar.timestamps", usecols=0, dtype=np.int64)
    row = table[(table[:, 8] == stamps_us[3]) & (table[:, 9] == stamps_us[2])][0]
    np.testing.assert_allclose(motion[2], [row[2], -row[3], -row[7]], atol=1e-12)
    assert row[3] < 0 < motion[2, 1]  # a real sign flip is exercised


def test_range_resolution_is_configurable(oxford_dir: Path) -> None:
    assert OxfordSequence(oxford_dir, range_resolution_m=0.0432)[0].range_resolution_m == 0.0432


def test_without_gt(oxford_dir: Path, tmp_path: Path) -> None:
    seq = OxfordSequence(copy_sequence(oxford_dir, tmp_path / "s", gt=False))
    assert seq.ground_truth is None and len(seq) == 3
    # File time + half the median gap between scans: (252.810 + 251.974) / 2 / 2 ms ...
    assert int(seq.timestamps_ns[0]) == (1547131046353776 + 126196) * 1000
    # ... within 0.1 ms of the true mid-scan time given by the GT file.
    assert abs(int(seq.timestamps_ns[0]) - 1547131046480034 * 1000) < 100_000


def test_scan_list_from_folder_when_timestamps_absent(oxford_dir: Path, tmp_path: Path) -> None:
    seq_dir = copy_sequence(oxford_dir, tmp_path / "s")
    (seq_dir / "radar.timestamps").unlink()
    seq = OxfordSequence(seq_dir)
    assert len(seq) == 3 and seq.ground_truth is not None


# ---- bad input -------------------------------------------------------------------------------


def test_listed_scan_missing(oxford_dir: Path, tmp_path: Path) -> None:
    seq_dir = copy_sequence(oxford_dir, tmp_path / "s")
    next(iter((seq_dir / "radar").glob("*.png"))).unlink()
    with pytest.raises(DatasetFormatError, match="radar.timestamps: 1 of 3 listed scans"):
        OxfordSequence(seq_dir)


def test_empty(tmp_path: Path) -> None:
    (tmp_path / "s" / "radar").mkdir(parents=True)
    (tmp_path / "s" / "radar.timestamps").write_text("")
    with pytest.raises(DatasetFormatError, match="radar.timestamps: no data rows"):
        OxfordSequence(tmp_path / "s")
    (tmp_path / "s" / "radar.timestamps").unlink()
    with pytest.raises(DatasetFormatError, match="no scans"):
        OxfordSequence(tmp_path / "s")


@pytest.mark.parametrize(("order", "message"), [((1, 0, 2), "unsorted"), ((0, 0, 1), "duplicated")])
def test_bad_timestamps(oxford_dir: Path, tmp_path: Path, order: tuple, message: str) -> None:
    seq_dir = copy_sequence(oxford_dir, tmp_path / "s")
    lines = (seq_dir / "radar.timestamps").read_text().splitlines()
    (seq_dir / "radar.timestamps").write_text("\n".join(lines[i] for i in order) + "\n")
    with pytest.raises(DatasetFormatError, match=f"radar.timestamps: {message} timestamp"):
        OxfordSequence(seq_dir)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda line: ",".join(["nan" if i == 2 else f for i, f in enumerate(line.split(","))]),
            "NaN",
        ),
        (lambda line: line.rsplit(",", 1)[0], "has 9 columns, expected 10"),
        (lambda line: line.replace(",", ",x", 1), "non-numeric"),
    ],
)
def test_bad_odometry_csv(oxford_dir: Path, tmp_path: Path, edit, message: str) -> None:
    seq_dir = copy_sequence(oxford_dir, tmp_path / "s")
    path = seq_dir / ODOMETRY_CSV
    lines = path.read_text().splitlines()
    lines[5] = edit(lines[5])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetFormatError, match=message) as info:
        OxfordSequence(seq_dir)
    assert "radar_odometry.csv" in str(info.value)


def test_bad_scans(oxford_dir: Path, tmp_path: Path) -> None:
    seq_dir = copy_sequence(oxford_dir, tmp_path / "s")
    paths = sorted((seq_dir / "radar").glob("*.png"))
    raw = paths[0].read_bytes()
    paths[0].write_bytes(raw[: len(raw) // 3])
    image = cv2.imread(str(oxford_dir / "radar" / paths[1].name), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(paths[1]), image[:, 11:])  # header stripped
    image[7, 8:10] = 0xFF  # encoder 65535
    cv2.imwrite(str(paths[2]), image)
    seq = OxfordSequence(seq_dir)
    with pytest.raises(DatasetFormatError, match=f"{paths[0].name}: cannot decode PNG"):
        seq[0]
    with pytest.raises(DatasetFormatError, match=f"{paths[1].name}: scan has shape 400 x 3768"):
        seq[1]
    with pytest.raises(DatasetFormatError, match=f"{paths[2].name}: row 7 has encoder count"):
        seq[2]


def test_loader_never_writes(oxford_dir: Path, tmp_path: Path) -> None:
    seq_dir = copy_sequence(oxford_dir, tmp_path / "s")
    before = sorted((p, p.stat().st_mtime_ns) for p in seq_dir.rglob("*"))
    seq = OxfordSequence(seq_dir)
    _ = [seq[k] for k in range(len(seq))], seq.ground_truth
    assert sorted((p, p.stat().st_mtime_ns) for p in seq_dir.rglob("*")) == before
