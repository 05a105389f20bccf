"""A run's map made from what the run holds: the same map as one rebuilt by reading the scans
again, and no scan decoded after the last one (library and `radar-slam run`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from radar_slam.cli import main
from radar_slam.commands import run as run_command
from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.datasets.stride import ScanSelection
from radar_slam.errors import RadarSlamError
from radar_slam.maps import Map, build_map
from radar_slam.maps.build import select_keyframes
from radar_slam.maps.keyframes import KeyframeSpacing
from radar_slam.pipeline import Pipeline, PipelineConfig, Results, load_config

FRAMES = 60
"""Scans of tiny_loop the runs use (1024 bins: a few seconds)."""


class CountedSequence(ScanSelection):
    """A sequence whose scan decodes are counted: `decodes` before `finished` is set, `late`
    after it."""

    def __init__(self, base: RadarSequence) -> None:
        super().__init__(base, np.arange(len(base)), base.name)
        self.decodes: list[int] = []
        self.late: list[int] = []
        self.finished = False

    def __getitem__(self, index: int) -> RadarFrame:
        (self.late if self.finished else self.decodes).append(int(index))
        return super().__getitem__(index)


def sequential(config: PipelineConfig) -> PipelineConfig:
    """`config` without the reader and loop threads."""
    concurrency = dataclasses.replace(config.concurrency, loop_thread=False, read_ahead_scans=0)
    return dataclasses.replace(config, concurrency=concurrency)


def assert_same_map(a: Map, b: Map) -> None:
    """Every field equal: arrays bit for bit (dtype and shape too), the rest by value."""
    for field in dataclasses.fields(Map):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, field.name
            assert x.tobytes() == y.tobytes(), field.name
        else:
            assert x == y, field.name


@pytest.fixture(scope="module", params=["threads", "sequential"])
def recorded_run(request: pytest.FixtureRequest, tiny_loop: RadarSequence) -> Results:
    config = load_config("synthetic")
    if request.param == "sequential":
        config = sequential(config)
    return Pipeline(tiny_loop, config, max_frames=FRAMES, record_map=True).run()


def test_recorded_map_equals_the_map_read_again(
    recorded_run: Results, tiny_loop: RadarSequence, tmp_path: Path
) -> None:
    recorded = recorded_run.map_keyframes
    assert recorded is not None and len(recorded.records) >= 10
    fast = build_map(recorded_run)
    again = build_map(dataclasses.replace(recorded_run, map_keyframes=None), tiny_loop)
    assert_same_map(fast, again)
    fast.save(tmp_path / "fast")
    again.save(tmp_path / "again")
    for path in sorted((tmp_path / "fast").iterdir()):
        assert path.read_bytes() == (tmp_path / "again" / path.name).read_bytes(), path.name


def test_keyframes_follow_the_odometry_path(recorded_run: Results) -> None:
    recorded = recorded_run.map_keyframes
    assert recorded is not None
    scans = [r.scan for r in recorded.records]
    spacing = recorded_run.config.maps.keyframe_spacing_m
    np.testing.assert_array_equal(scans, select_keyframes(recorded_run.odometry.poses, spacing))


def test_keyframe_spacing_one_pose_at_a_time() -> None:
    spacing = KeyframeSpacing(4.0)
    x = np.arange(0.0, 20.5, 0.5)
    chosen = [n for n, value in enumerate(x) if spacing.is_keyframe([value, 0.0, 0.0])]
    assert chosen == [0, 8, 16, 24, 32, 40]


def test_map_descriptors_are_the_loop_detectors(tiny_loop: RadarSequence) -> None:
    # Keyframes and database scans are both spaced 4 m along the odometry path: the recorder
    # takes the detector's descriptors instead of describing the scans again.
    pipeline = Pipeline(tiny_loop, load_config("synthetic"), max_frames=FRAMES, record_map=True)
    results = pipeline.run()
    assert results.map_keyframes is not None
    taken = pipeline.keyframes.descriptors_taken  # type: ignore[attr-defined]
    assert taken == len(results.map_keyframes.records)


def test_run_builds_its_map_without_decoding_a_scan_again(tiny_loop: RadarSequence) -> None:
    counted = CountedSequence(tiny_loop)
    results = Pipeline(counted, load_config("synthetic"), max_frames=FRAMES, record_map=True).run()
    assert sorted(counted.decodes) == list(range(FRAMES))  # each scan once
    counted.finished = True
    the_map = build_map(results, counted)
    assert counted.late == []
    assert len(the_map) == len(results.map_keyframes.records)  # type: ignore[union-attr]


def test_keyframes_kept_with_other_settings_are_made_again(
    recorded_run: Results, tiny_loop: RadarSequence
) -> None:
    # A map wanted with another keyframe spacing than the run kept: read from the sequence.
    sparser = dataclasses.replace(recorded_run.config.maps, keyframe_spacing_m=8.0)
    config = dataclasses.replace(recorded_run.config, maps=sparser)
    counted = CountedSequence(tiny_loop)
    the_map = build_map(dataclasses.replace(recorded_run, config=config), counted)
    assert sorted(counted.decodes) == list(the_map.keyframes["scan"])
    assert the_map.settings["keyframe_spacing_m"] == 8.0
    assert len(the_map) < len(recorded_run.map_keyframes.records)  # type: ignore[union-attr]


def test_a_run_without_records_needs_its_sequence(tiny_loop: RadarSequence) -> None:
    results = Pipeline(tiny_loop, load_config("synthetic"), max_frames=8).run()
    assert results.map_keyframes is None
    with pytest.raises(RadarSlamError, match="no sequence"):
        build_map(results)


def test_radar_slam_run_decodes_no_scan_after_the_last(
    tiny_loop: RadarSequence,
    synthetic_root: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    opened: list[CountedSequence] = []
    open_configured = run_command.open_configured

    def counted_open(*args: object, **kwargs: object) -> tuple[RadarSequence, PipelineConfig]:
        sequence, config = open_configured(*args, **kwargs)  # type: ignore[arg-type]
        opened.append(CountedSequence(sequence))
        return opened[-1], config

    class MarkedPipeline(Pipeline):
        def run(self) -> Results:
            results = super().run()
            opened[-1].finished = True  # the last scan is done: nothing is read from here on
            return results

    monkeypatch.setattr(run_command, "open_configured", counted_open)
    monkeypatch.setattr(run_command, "Pipeline", MarkedPipeline)
    out = tmp_path / "run"
    root = ["--data-root", str(synthetic_root)]
    frames = ["--max-frames", str(FRAMES)]
    assert main(["run", "synthetic/tiny_loop", "--out", str(out), *frames, *root]) == 0
    (counted,) = opened
    assert counted.finished and counted.late == []
    assert sorted(counted.decodes) == list(range(FRAMES))
    assert len(Map.load(out / "map")) >= 10
