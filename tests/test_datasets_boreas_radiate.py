"""Boreas and RADIATE loaders: a Boreas folder written to the published specification from the
real Oxford scans, and the real RADIATE fog frames with the dataset's own Cartesian images."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from real_layouts import MID_SCAN_ROW, write_boreas

from odometry import Odometry, OdometryConfig
from radar_slam.cli import main
from radar_slam.datasets import DatasetConfig, open_sequence
from radar_slam.datasets.boreas import (
    RANGE_RESOLUTION_AFTER_M,
    RANGE_RESOLUTION_BEFORE_M,
    BoreasSequence,
)
from radar_slam.datasets.radiate import RadiateSequence
from radar_slam.errors import DatasetFormatError
from raplace.warp import CartesianGrid, CartesianWarper

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def boreas_root(oxford_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("boreas_root")
    write_boreas(oxford_dir, root / "boreas" / "boreas-2021-08-05-13-34")
    return root


def test_boreas_reads_the_scans_times_and_gt_written_to_the_specification(
    oxford_dir: Path, tmp_path: Path
) -> None:
    oxford, poses = write_boreas(oxford_dir, tmp_path / "boreas-2021-08-05-13-34")
    boreas = open_sequence(tmp_path / "boreas-2021-08-05-13-34")
    assert isinstance(boreas, BoreasSequence) and boreas.family == "boreas"
    assert len(boreas) == len(oxford) == 7
    for index in range(len(oxford)):
        ours, theirs = boreas[index], oxford[index]
        np.testing.assert_array_equal(ours.polar, theirs.polar)
        np.testing.assert_array_equal(ours.azimuths_rad, theirs.azimuths_rad)
        np.testing.assert_array_equal(ours.azimuth_times_ns, theirs.azimuth_times_ns)
        assert ours.timestamp_ns == theirs.azimuth_times_ns[MID_SCAN_ROW]  # type: ignore[index]
        assert ours.polar.shape == (400, 3768)
    assert boreas.ground_truth is not None
    np.testing.assert_allclose(boreas.ground_truth, poses, atol=1e-9)
    # Before the 2021-09-21 firmware change the bins are 0.0596 m.
    assert boreas[0].range_resolution_m == RANGE_RESOLUTION_BEFORE_M


def test_boreas_range_resolution_follows_the_date_and_the_config(
    oxford_dir: Path, tmp_path: Path
) -> None:
    write_boreas(oxford_dir, tmp_path / "boreas-2021-11-02-11-16")
    after = open_sequence(tmp_path / "boreas-2021-11-02-11-16")
    assert after[0].range_resolution_m == RANGE_RESOLUTION_AFTER_M
    overridden = open_sequence(
        tmp_path / "boreas-2021-11-02-11-16", options=DatasetConfig(range_resolution_m=0.0438)
    )
    assert overridden[0].range_resolution_m == 0.0438
    (tmp_path / "boreas-2021-11-02-11-16").rename(tmp_path / "no-date")
    with pytest.raises(DatasetFormatError, match="range_resolution_m"):
        BoreasSequence(tmp_path / "no-date")
    assert BoreasSequence(tmp_path / "no-date", 0.05).range_resolution_m == 0.05


def test_radiate_polar_rendering_reproduces_the_datasets_cartesian_images(
    shared_data: Path,
) -> None:
    folder = shared_data / "radiate" / "fog_6_0-partial"
    sequence = open_sequence(folder)
    assert isinstance(sequence, RadiateSequence) and len(sequence) == 18
    warper = CartesianWarper(CartesianGrid(cell_m=0.175, size_px=1152))
    for index in (0, 9, 17):
        frame = sequence[index]
        assert frame.polar.shape == (400, 576)
        cartesian = warper(frame.polar, frame.azimuths_rad, frame.range_resolution_m)
        theirs = cv2.imread(
            str(folder / "Navtech_Cartesian" / f"{index + 1:06d}.png"), cv2.IMREAD_GRAYSCALE
        )
        correlation = np.corrcoef(cartesian.ravel(), theirs.ravel().astype(np.float32))[0, 1]
        assert correlation >= 0.9, (index, correlation)
        # Counter-clockwise columns, or another zero angle, would not reproduce them.
        for azimuths in (-frame.azimuths_rad, frame.azimuths_rad + np.pi / 2):
            wrong = warper(frame.polar, azimuths, frame.range_resolution_m)
            other = np.corrcoef(wrong.ravel(), theirs.ravel().astype(np.float32))[0, 1]
            assert other < 0.5


def test_radiate_odometry_over_the_fog_frames_is_smooth(shared_data: Path) -> None:
    sequence = open_sequence(shared_data / "radiate" / "fog_6_0-partial")
    odometry = Odometry(OdometryConfig())
    results = [odometry.register(sequence[index]) for index in range(len(sequence))]
    assert not any(result.gap for result in results)
    poses = np.array([result.pose for result in results])
    seconds = np.diff(sequence.timestamps_ns) / 1e9
    speeds = np.linalg.norm(np.diff(poses[:, :2], axis=0), axis=1) / seconds
    assert np.all(speeds > 5.0) and np.all(speeds < 20.0)  # driving forward through fog
    assert np.max(np.abs(np.diff(speeds))) < 2.0
    assert np.all(poses[1:, 0] > poses[:-1, 0])  # forward, not backward


def test_list_and_info_show_both_families(
    boreas_root: Path, shared_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    radiate = boreas_root / "radiate" / "fog_6_0"
    shutil.copytree(shared_data / "radiate" / "fog_6_0-partial", radiate)
    assert main(["list", "--data-root", str(boreas_root)]) == 0
    listing = capsys.readouterr().out
    assert "boreas/boreas-2021-08-05-13-34" in listing and "radiate/fog_6_0" in listing
    assert "  boreas " in listing and "  radiate " in listing
    assert main(["info", "boreas/boreas-2021-08-05-13-34", "--data-root", str(boreas_root)]) == 0
    info = capsys.readouterr().out
    assert "frames:            7" in info and "0.05960 m" in info
    assert "first scan check:  ok" in info
    assert main(["info", "radiate/fog_6_0", "--data-root", str(boreas_root)]) == 0
    info = capsys.readouterr().out
    assert "frames:            18" in info and "range bins:        576" in info
    assert "first scan check:  ok" in info
