"""`dataset.scan_rate_hz`: the sweep a MulRan-layout scan's azimuth times are spread over, for a
radar that does not turn at 4 Hz (the file names give only the end of each sweep)."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_odometry_sim import (  # noqa: F401
    MAX_ERROR_DEG,
    MAX_ERROR_M,
    SCENE_TIMES_S,
    errors,
    render,
    tiny_scene,
)

from odometry import estimate_motion
from odometry.preprocess import motion_from_twist
from radar_slam.datasets import MulRanSequence, open_sequence
from radar_slam.datasets.frame import RadarFrame
from radar_slam.datasets.registry import DatasetConfig
from radar_slam.errors import ConfigError, DatasetFormatError
from radar_slam.sim.family import open_synthetic
from radar_slam.sim.generate import Scene, generate_sequence
from radar_slam.sim.render import RenderTables, make_tables
from radar_slam.sim.scenarios import get_scenario
from raplace import se2
from raplace.units import NS_PER_S

SCAN_STAMP_NS = 1564718976161407002
SLOW_PERIOD_NS = 500_000_000  # a radar turning at 2 Hz
N_SCANS = 3


def sweep_ns(sequence: MulRanSequence, index: int = 1) -> int:
    times = sequence[index].azimuth_times_ns
    assert times is not None
    return int(times[-1] - times[0])


@pytest.fixture()
def slow_mulran(tmp_path: Path, mulran_raw_dir: Path) -> Path:
    """The real MulRan scan copied under stamps 0.5 s apart, one sweep each."""
    folder = tmp_path / "mulran" / "SLOW01"
    scans = folder / "sensor_data" / "radar" / "polar"
    scans.mkdir(parents=True)
    for k in range(N_SCANS):
        stamp = SCAN_STAMP_NS + k * SLOW_PERIOD_NS
        shutil.copyfile(mulran_raw_dir / f"polar/{SCAN_STAMP_NS}.png", scans / f"{stamp}.png")
    return folder


@pytest.mark.realdata
def test_scan_rate_spreads_the_azimuths_over_one_revolution(slow_mulran: Path) -> None:
    """At the default 4 Hz a 0.5 s gap is taken for a dropped sweep (250 ms sweeps); told the
    radar turns at 2 Hz, the loader spreads each scan over the 0.5 s it took, through the
    `dataset:` section too."""
    full = SLOW_PERIOD_NS * 399 // 400
    assert sweep_ns(MulRanSequence(slow_mulran)) == pytest.approx(full // 2, abs=2)
    assert sweep_ns(MulRanSequence(slow_mulran, scan_rate_hz=2.0)) == pytest.approx(full, abs=2)
    configured = open_sequence(
        "mulran/SLOW01",
        data_root=slow_mulran.parent.parent,
        options=DatasetConfig(scan_rate_hz=2.0),
    )
    assert isinstance(configured, MulRanSequence)
    assert sweep_ns(configured) == pytest.approx(full, abs=2)


def test_scan_rate_is_checked_and_refused_where_files_carry_times(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="scan_rate_hz"):
        DatasetConfig(scan_rate_hz=0.0)
    with pytest.raises(ValueError, match="scan_rate_hz"):
        MulRanSequence(tmp_path, scan_rate_hz=-4.0)
    folder = tmp_path / "oxford" / "drive"
    (folder / "radar").mkdir(parents=True)
    with pytest.raises(ConfigError, match="scan_rate_hz"):
        open_sequence("oxford/drive", data_root=tmp_path, options=DatasetConfig(scan_rate_hz=2.0))


def test_a_simulated_radar_turning_at_two_hertz_spreads_its_scans_over_half_a_second(
    tmp_path: Path,
) -> None:
    """The synthetic family reads the rate from world.json: each scan's azimuth times are the
    times the simulator rendered it at, over 0.5 s; `scan_rate_hz` 4 squeezes them into 0.25 s."""
    scenario = get_scenario("tiny_turn_around")
    slow = dataclasses.replace(
        scenario, sensor=dataclasses.replace(scenario.sensor, scan_rate_hz=2.0)
    )
    folder = tmp_path / "slow_turn_around"
    generate_sequence(slow, folder, frames=2, workers=0)
    for rate, sensor in ((None, slow.sensor), (4.0, scenario.sensor)):
        frame = open_synthetic(folder, scan_rate_hz=rate)[1]
        assert frame.azimuth_times_ns is not None
        offsets = frame.azimuth_times_ns - frame.timestamp_ns
        np.testing.assert_array_equal(offsets, sensor.azimuth_offsets_ns())
    assert -offsets[0] == pytest.approx(SLOW_PERIOD_NS / 2, rel=0.01)


def test_half_second_sweeps_are_de_skewed_over_their_own_times(
    tiny_scene: tuple[Scene, RenderTables],  # noqa: F811
) -> None:
    """Two scans of a 2 Hz radar in a turn (8 m/s, 30 deg/s: 15 deg within each sweep) 0.5 s
    apart: registered with the azimuth times they were rendered at, the motion is recovered
    within the known-motion bars; with the times of a 4 Hz sweep (what a wrong scan rate gives)
    half of each sweep's motion stays in the images and the error is several times the bars."""
    scene, tables = tiny_scene
    physics = scene.scenario.physics
    slow = make_tables(dataclasses.replace(tables.sensor, scan_rate_hz=2.0), physics)
    period_s = SLOW_PERIOD_NS / NS_PER_S
    twist = np.array([8.0, 0.0, np.deg2rad(30.0)])
    motion = motion_from_twist(twist, period_s)
    start_s = SCENE_TIMES_S[0]
    first = scene.trajectory.radar_poses(np.array([start_s]))[0]
    a = render(scene, slow, first, start_s, twist, seed=1)
    b = render(scene, slow, se2.compose(first, motion), start_s + period_s, twist, seed=2)
    estimate = estimate_motion(a, b)
    assert estimate.ok, estimate.reason
    right_m, right_deg = errors(estimate.motion, motion)
    assert right_m <= MAX_ERROR_M and right_deg <= MAX_ERROR_DEG, (right_m, right_deg)

    def quarter_second(frame: RadarFrame) -> RadarFrame:
        offsets = tables.sensor.azimuth_offsets_ns()
        return dataclasses.replace(frame, azimuth_times_ns=frame.timestamp_ns + offsets)

    squeezed = estimate_motion(quarter_second(a), quarter_second(b))
    wrong_m, wrong_deg = errors(squeezed.motion, motion)
    assert wrong_m > 2 * MAX_ERROR_M or wrong_deg > 2 * MAX_ERROR_DEG, (wrong_m, wrong_deg)


def test_a_bad_simulated_scan_rate_names_world_json(tmp_path: Path) -> None:
    """A world.json whose sensor.scan_rate_hz is not a positive number is refused naming the
    file and the key, before any scan is read."""
    folder = tmp_path / "tiny"
    generate_sequence(get_scenario("tiny"), folder)
    world_path = folder / "world.json"
    world = json.loads(world_path.read_text())
    assert open_synthetic(folder).scan_rate_hz == pytest.approx(world["sensor"]["scan_rate_hz"])
    world["sensor"]["scan_rate_hz"] = 0
    world_path.write_text(json.dumps(world))
    with pytest.raises(DatasetFormatError, match=r"world\.json: sensor\.scan_rate_hz"):
        open_synthetic(folder)
    world["sensor"]["scan_rate_hz"] = 4.0
    world["sensor"]["n_bins"] = 3360.5
    world_path.write_text(json.dumps(world))
    with pytest.raises(DatasetFormatError, match=r"sensor\.n_bins must be a positive whole number"):
        open_synthetic(folder)
