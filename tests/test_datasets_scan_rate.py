"""`dataset.scan_rate_hz`: the sweep a MulRan-layout scan's azimuth times are spread over, for a
radar that does not turn at 4 Hz (the file names give only the end of each sweep)."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest

from radar_slam.datasets import MulRanSequence, open_sequence
from radar_slam.datasets.registry import DatasetConfig
from radar_slam.errors import ConfigError, DatasetFormatError
from radar_slam.pipeline import Pipeline, PipelineConfig
from radar_slam.sim.family import open_synthetic
from radar_slam.sim.generate import generate_sequence
from radar_slam.sim.scenarios import get_scenario

SCAN_STAMP_NS = 1564718976161407002
SLOW_PERIOD_NS = 500_000_000  # a radar turning at 2 Hz
N_SCANS = 3
DRIFT_PCT_MAX = 1.0


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


def test_a_radar_turning_at_two_hertz_is_de_skewed_over_its_half_second_sweeps(
    tmp_path: Path,
) -> None:
    """`tiny_turn_around` simulated with a radar turning at 2 Hz: the synthetic family reads the
    rate from world.json and the odometry stays under 1 % drift; forced to 4 Hz, each sweep's
    de-skew covers half of it and the drift is several times larger."""
    scenario = get_scenario("tiny_turn_around")
    slow = dataclasses.replace(
        scenario, sensor=dataclasses.replace(scenario.sensor, scan_rate_hz=2.0)
    )
    folder = tmp_path / "slow_turn_around"
    generate_sequence(slow, folder)
    config = PipelineConfig()
    right = Pipeline(open_synthetic(folder), config).run().odometry_metrics
    wrong = Pipeline(open_synthetic(folder, scan_rate_hz=4.0), config).run().odometry_metrics
    assert right.drift_trans_pct <= DRIFT_PCT_MAX
    assert wrong.drift_trans_pct > 3 * right.drift_trans_pct


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
