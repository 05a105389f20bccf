"""RADIATE in full: its time format, its GNSS/INS ground truth, and de-skew without azimuth
times; checked on the real 1.5 km Edinburgh drive where the data is needed."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray
from point_scenes import N_AZIMUTHS, moving_poses, point_scene, render_polar, static_poses
from pyproj import Geod

from odometry.config import PreprocessConfig
from odometry.preprocess import cartesian_level, preprocess_polar, render_cartesian
from radar_slam.datasets import open_sequence
from radar_slam.datasets.radiate import RADIATE_RANGE_RESOLUTION_M, radiate_azimuths_rad
from radar_slam.datasets.radiate_gnss import (
    MAX_FIX_GAP_NS,
    GnssTrack,
    heading_bias_rad,
    radiate_time_ns,
    read_gnss_track,
    read_time_list,
)
from radar_slam.errors import DatasetFormatError
from raplace import se2
from raplace.units import NS_PER_S

EDINBURGH = "radiate/edinburgh_2019-02-12-15-33"


@pytest.fixture(scope="module")
def drive(shared_data: Path) -> Path:
    folder = shared_data / EDINBURGH
    if not folder.is_dir():
        pytest.skip(f"{folder} not found")
    return folder


@pytest.fixture(scope="module")
def track(drive: Path) -> GnssTrack:
    return read_gnss_track(drive)


def test_the_part_after_the_dot_counts_nanoseconds() -> None:
    assert radiate_time_ns("1549985636", "25327499") == 1_549_985_636_025_327_499
    assert radiate_time_ns("1549985636", "789496005") == 1_549_985_636_789_496_005
    assert radiate_time_ns("12", None) == 12 * NS_PER_S
    with pytest.raises(ValueError, match="nine digits"):
        radiate_time_ns("1", "1234567890")


@pytest.mark.realdata
def test_real_time_lists_increase_once_read_as_radiate_writes_them(drive: Path) -> None:
    frames, stamps = read_time_list(drive / "Navtech_Polar.txt")
    assert len(frames) == 714 and frames[1] == "000002"
    assert stamps[1] == 1_549_985_636_025_327_499  # written "1549985636.25327499"
    assert stamps[5] == 1_549_985_637_003_881_464  # written "1549985637.3881464"
    gaps = np.diff(stamps) / NS_PER_S
    assert np.all(gaps > 0.2) and np.all(gaps < 0.35)  # 4 Hz throughout, with jitter
    assert np.median(gaps) == pytest.approx(0.25, abs=0.005)
    _, gnss = read_time_list(drive / "GPS_IMU_Twist.txt", strictly_increasing=False)
    assert len(gnss) == 5787 and np.all(np.diff(gnss) >= 0)


def test_a_malformed_time_line_names_the_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "Navtech_Polar.txt"
    path.write_text("Frame: 000001 Time: 1.5\nFrame: 000002 Time: 1.x\n")
    with pytest.raises(DatasetFormatError, match=r"Navtech_Polar.txt: line 2"):
        read_time_list(path)


@pytest.mark.realdata
def test_real_gnss_log_drops_repeated_fixes_and_finds_its_outages(track: GnssTrack) -> None:
    assert track.repeated_fixes == 2901
    assert len(track.times_ns) == 5787 - 2901
    outage_s = (track.outages[:, 1] - track.outages[:, 0]) / NS_PER_S
    assert len(outage_s) == 15
    assert outage_s.sum() == pytest.approx(34.35, abs=0.01)
    assert outage_s.max() == pytest.approx(5.75, abs=0.01)
    assert track.epsg == 32630  # UTM zone 30 N: Edinburgh
    path = np.hypot(*np.diff(track.poses[:, :2], axis=0).T).sum()
    assert 1450.0 < path < 1570.0  # the 1.5 km drive


def _write_log(
    folder: Path, fixes: list[tuple[float, float, float]], dt_s: float = 0.1, speed: float = 0.0
) -> None:
    """A GPS_IMU_Twist log of (latitude, longitude, yaw [rad]) fixes `dt_s` apart, the INS
    saying it drives at `speed` [m/s]."""
    (folder / "GPS_IMU_Twist").mkdir(parents=True)
    lines = []
    zeros = "0.0,0.0,0.0"
    for k, (lat, lon, yaw) in enumerate(fixes, start=1):
        quat = f"0.0,0.0,{np.sin(yaw / 2):.12f},{np.cos(yaw / 2):.12f}"
        twist = f"{speed},0.0,0.0"
        record = [f"{lat:.12f},{lon:.12f},100.0", zeros, zeros, zeros, quat] + [zeros] * 11
        record += [twist, zeros]
        (folder / "GPS_IMU_Twist" / f"{k:06d}.txt").write_text("\n".join(record) + "\n")
        t = int(round(1000 * NS_PER_S + k * dt_s * NS_PER_S))
        lines.append(f"Frame: {k:06d} Time: {t // NS_PER_S}.{t % NS_PER_S}")
    (folder / "GPS_IMU_Twist.txt").write_text("\n".join(lines) + "\n")


def test_fixes_become_utm_metres_and_the_quaternion_a_heading(tmp_path: Path) -> None:
    lat, lon = 55.91, -3.32
    _write_log(tmp_path, [(lat, lon, 0.5), (lat, lon, 0.5), (lat + 0.001, lon + 0.002, 0.6)])
    track = read_gnss_track(tmp_path)
    assert track.repeated_fixes == 1 and len(track.times_ns) == 2
    forward, _, metres = Geod(ellps="WGS84").inv(lon, lat, lon + 0.002, lat + 0.001)
    step = track.poses[1, :2] - track.poses[0, :2]
    # UTM's scale factor near the zone's central meridian is 0.9996: within 0.1 %.
    assert np.hypot(*step) == pytest.approx(metres, rel=1e-3)
    # Grid north is within a degree of true north this close to the central meridian.
    assert np.degrees(np.arctan2(step[0], step[1])) == pytest.approx(forward, abs=1.0)
    assert track.poses[:, 2] == pytest.approx([0.5, 0.6])


@pytest.mark.parametrize("standing", [True, False])
def test_a_held_fix_is_an_outage_while_driving_and_a_stop_while_standing(
    tmp_path: Path, standing: bool
) -> None:
    lat, lon = 55.91, -3.32
    step = 0.0 if standing else 0.0002  # about 22 m after the hold while driving
    fixes = [(lat, lon, 0.0)] * 21 + [(lat + step, lon, 0.0), (lat + 2 * step + 1e-6, lon, 0.0)]
    _write_log(tmp_path, fixes, speed=0.0 if standing else 11.0)
    track = read_gnss_track(tmp_path)
    assert len(track.outages) == (0 if standing else 1)
    assert track.repeated_fixes == (0 if standing else 20)
    during = track.times_ns[0] + NS_PER_S
    pose = track.radar_poses([during])[0]
    assert np.isfinite(pose[0]) == standing


def test_a_log_without_two_distinct_fixes_is_refused(tmp_path: Path) -> None:
    _write_log(tmp_path, [(55.9, -3.3, 0.0), (55.9, -3.3, 0.0)])
    with pytest.raises(DatasetFormatError, match="GPS_IMU_Twist.txt: fewer than two distinct"):
        read_gnss_track(tmp_path)


def _turning_track(bias_rad: float = 0.0) -> GnssTrack:
    """An antenna driving a quarter circle of 20 m radius at 10 m/s, heading = course + bias."""
    t = np.arange(0.0, np.pi * 20.0 / 2 / 10.0, 0.1)
    angle = t * 10.0 / 20.0
    poses = np.stack([20 * np.sin(angle), 20 * (1 - np.cos(angle)), angle + bias_rad], axis=-1)
    times = np.round(t * NS_PER_S).astype(np.int64)
    bias, steps = heading_bias_rad(times, poses)
    empty = np.zeros((0, 2), dtype=np.int64)
    return GnssTrack(times, poses, 32630, 0, empty, bias, steps)


def test_the_lever_arm_moves_the_radar_by_the_vector_turned_with_the_vehicle() -> None:
    track = _turning_track()
    query = track.times_ns[[0, len(track.times_ns) - 1]]
    antenna = track.radar_poses(query)
    radar = track.radar_poses(query, lever_arm_m=(1.5, 0.4))
    for pose_a, pose_r in zip(antenna, radar, strict=True):
        c, s = np.cos(pose_a[2]), np.sin(pose_a[2])
        assert pose_r[:2] - pose_a[:2] == pytest.approx([1.5 * c - 0.4 * s, 1.5 * s + 0.4 * c])
        assert pose_r[2] == pytest.approx(pose_a[2])
    # A quarter turn later the same arm points 90 deg further round.
    assert antenna[-1, 2] - antenna[0, 2] == pytest.approx(np.pi / 2, abs=0.06)


def test_the_heading_bias_against_the_course_is_found() -> None:
    assert np.degrees(_turning_track(np.radians(2.0)).heading_bias_rad) == pytest.approx(
        2.0, abs=0.1
    )
    assert np.degrees(_turning_track().heading_bias_rad) == pytest.approx(0.0, abs=0.1)


@pytest.mark.realdata
def test_real_ins_heading_follows_the_course_within_a_degree_or_two(
    drive: Path, track: GnssTrack
) -> None:
    assert track.course_steps > 1000
    assert -3.0 < np.degrees(track.heading_bias_rad) < 1.0
    source = open_sequence(drive).ground_truth_source
    assert source is not None and source.accuracy_m >= 1.0  # no RTK: metre level
    assert source.notes["ins_heading_minus_course_deg"] == pytest.approx(
        np.degrees(track.heading_bias_rad), abs=0.01
    )


def test_a_time_inside_an_outage_or_off_the_log_has_no_pose() -> None:
    base = _turning_track()
    times = base.times_ns.copy()
    times[10:] += 2 * MAX_FIX_GAP_NS  # an outage after fix 9
    outages = np.array([[times[9], times[10]]], dtype=np.int64)
    track = GnssTrack(times, base.poses, 32630, 0, outages, 0.0, 0)
    inside = (times[9] + times[10]) // 2
    poses = track.radar_poses([times[0] - 1, times[5], inside, times[-1], times[-1] + 1])
    assert np.isnan(poses[[0, 2, 4], 0]).all()
    assert np.isfinite(poses[[1, 3]]).all()
    assert track.scans_in_outages([inside, times[5]]) == 1


@pytest.mark.realdata
def test_the_shipped_drive_loads_with_sweep_times_and_gnss_ground_truth(drive: Path) -> None:
    sequence = open_sequence(drive)
    assert len(sequence) == 714
    frame = sequence[1]
    times = frame.azimuth_times_ns
    assert times is not None and times[-1] == frame.timestamp_ns  # the stamp ends the sweep
    assert (times[-1] - times[0]) / NS_PER_S == pytest.approx(0.25 * 399 / 400, abs=0.02)
    gt = sequence.ground_truth
    source = sequence.ground_truth_source
    assert gt is not None and source is not None
    missing = int(np.isnan(gt[:, 0]).sum())
    notes = source.notes
    assert missing == notes["scans_in_gnss_outages"] + notes["scans_outside_gnss_span"]
    assert 100 < missing < 160  # 34 s of outages at 4 Hz


@pytest.mark.realdata
def test_a_configured_offset_reads_the_gnss_later(drive: Path) -> None:
    from radar_slam.datasets import DatasetConfig

    plain = open_sequence(drive).ground_truth
    later = open_sequence(drive, options=DatasetConfig(gt_time_offset_s=0.5)).ground_truth
    assert plain is not None and later is not None
    both = np.isfinite(plain[:, 0]) & np.isfinite(later[:, 0])
    ahead = np.hypot(*(later[both, :2] - plain[both, :2]).T)
    assert np.median(ahead) == pytest.approx(0.5 * 8.5, rel=0.4)  # half a second at ~8.5 m/s


def _write_radiate(folder: Path, scans: list[NDArray[np.uint8]], dt_ns: int) -> None:
    (folder / "Navtech_Polar").mkdir(parents=True)
    lines = []
    for k, polar in enumerate(scans, start=1):
        cv2.imwrite(str(folder / "Navtech_Polar" / f"{k:06d}.png"), np.ascontiguousarray(polar.T))
        t = 1000 * NS_PER_S + k * dt_ns
        lines.append(f"Frame: {k:06d} Time: {t // NS_PER_S}.{t % NS_PER_S}")
    (folder / "Navtech_Polar.txt").write_text("\n".join(lines) + "\n")


def _correlation(a: NDArray[np.float32], b: NDArray[np.float32]) -> float:
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


def test_a_rotating_scan_without_azimuth_times_is_de_skewed_back_to_the_still_one(
    tmp_path: Path,
) -> None:
    targets = point_scene(np.random.default_rng(7))
    end = np.array([0.0, 0.0, 0.0])
    twist = np.array([0.0, 0.0, np.radians(40.0)])  # turning at 40 deg/s: 10 deg per sweep
    geometry = {"n_bins": 576, "bin_m": RADIATE_RANGE_RESOLUTION_M}
    azimuths = radiate_azimuths_rad(N_AZIMUTHS)
    still = render_polar(targets, static_poses(end), azimuths=azimuths, **geometry)
    turning = render_polar(targets, moving_poses(end, twist), azimuths=azimuths, **geometry)
    _write_radiate(tmp_path / "seq", [still, turning], 250_000_000)
    sequence = open_sequence(tmp_path / "seq")
    preprocess = PreprocessConfig(bin_size_m=RADIATE_RANGE_RESOLUTION_M, max_range_m=100.0)
    level = cartesian_level(0.4, 400)
    reference = render_cartesian(preprocess_polar(sequence[0], preprocess), level)
    skewed = preprocess_polar(sequence[1], preprocess)
    raw = render_cartesian(skewed, level)
    corrected = render_cartesian(skewed, level, twist=twist)
    assert _correlation(corrected, reference) > 0.9
    assert _correlation(corrected, reference) > _correlation(raw, reference) + 0.3
    # Without times, the same scan cannot be de-skewed: the twist changes nothing.
    import dataclasses

    timeless = preprocess_polar(dataclasses.replace(sequence[1], azimuth_times_ns=None), preprocess)
    assert _correlation(render_cartesian(timeless, level, twist=twist), raw) > 0.999


def test_se2_turn_is_what_the_lever_arm_uses() -> None:
    assert se2.compose([0.0, 0.0, np.pi / 2], [1.0, 0.0, 0.0]) == pytest.approx([0, 1, np.pi / 2])
