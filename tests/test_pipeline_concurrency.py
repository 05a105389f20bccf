"""The pipeline's reader and loop threads: same results as without them, errors and Ctrl-C."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import threading
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import radar_slam.pipeline.slam as slam_module
from odometry import Scan
from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.errors import DatasetFormatError
from radar_slam.loops import LoopClosureError, LoopConstraint, LoopDetector
from radar_slam.pipeline import Pipeline, PipelineConfig, Progress, Results, load_config
from radar_slam.pipeline.concurrency import ScanReader, usable_cpus

THREAD_NAMES = ("scan-reader", "loop-detector")
BAD_SCAN = 7
"""The scan at which the faulty sequence and detector below fail."""


def configured(threads: bool, lag: int = 8) -> PipelineConfig:
    config = load_config("synthetic")
    concurrency = dataclasses.replace(
        config.concurrency,
        loop_thread=threads,
        read_ahead_scans=4 if threads else 0,
        loop_lag_scans=lag,
    )
    return dataclasses.replace(config, concurrency=concurrency)


def our_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name in THREAD_NAMES and t.is_alive()]


class WrappedSequence:
    """A sequence that reads its scans from another (subclasses change `__getitem__`)."""

    def __init__(self, inner: RadarSequence) -> None:
        self.inner = inner

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def __len__(self) -> int:
        return len(self.inner)

    def __getitem__(self, index: int) -> RadarFrame:
        return self.inner[index]


class FaultySequence(WrappedSequence):
    """A sequence whose scan `BAD_SCAN` cannot be read."""

    def __getitem__(self, index: int) -> RadarFrame:
        if index == BAD_SCAN:
            raise DatasetFormatError(f"scan{index:04d}.png: truncated PNG")
        return self.inner[index]


class FaultyDetector(LoopDetector):
    """A loop detector that fails at scan `BAD_SCAN`."""

    def add(
        self, scan: Scan, pose: Any = None, key: int | None = None, polar: Any = None
    ) -> list[LoopConstraint]:
        if key == BAD_SCAN:
            raise LoopClosureError(f"scan {key}: pose must be 3 finite numbers")
        return super().add(scan, pose, key, polar)


@pytest.fixture(scope="module", autouse=True)
def two_cpus() -> Iterator[None]:
    """The threaded runs here thread on any machine: the pipeline sees two usable CPUs."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(slam_module, "usable_cpus", lambda: 2)
        yield


class ReadThreads(WrappedSequence):
    """A sequence that records the thread reading each scan."""

    def __init__(self, inner: RadarSequence) -> None:
        super().__init__(inner)
        self.readers: set[str] = set()

    def __getitem__(self, index: int) -> RadarFrame:
        self.readers.add(threading.current_thread().name)
        return self.inner[index]


@pytest.mark.parametrize(("cpus", "threaded"), [(1, False), (2, True)])
def test_threads_start_only_with_more_than_one_usable_cpu(
    tiny_loop: RadarSequence, monkeypatch: pytest.MonkeyPatch, cpus: int, threaded: bool
) -> None:
    """On one CPU the configured threads only contend: the run reads and detects loops in the
    main thread."""
    monkeypatch.setattr(slam_module, "usable_cpus", lambda: cpus)
    sequence = ReadThreads(tiny_loop)
    pipeline = Pipeline(sequence, configured(threads=True), max_frames=12)  # type: ignore[arg-type]
    detectors: set[str] = set()
    add = pipeline.loop_detector.add

    def recorded(*args: Any, **kwargs: Any) -> list[LoopConstraint]:
        detectors.add(threading.current_thread().name)
        return add(*args, **kwargs)

    pipeline.loop_detector.add = recorded  # type: ignore[method-assign]
    pipeline.run()
    expected = {True: ({"scan-reader"}, {"loop-detector"}), False: ({"MainThread"},) * 2}
    assert (sequence.readers, detectors) == expected[threaded]


def blas_threads() -> set[int]:
    return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}


@pytest.mark.parametrize("fails", [False, True])
def test_blas_runs_single_threaded_during_a_run_only(tiny_loop: RadarSequence, fails: bool):
    """BLAS threads would only spin beside the run's own threads: one BLAS thread while the loop
    detector works (on its thread), the caller's setting again afterwards, also after an error."""
    seen: set[int] = set()
    config = configured(threads=True)
    detector_class = FaultyDetector if fails else LoopDetector

    class Watching(detector_class):  # type: ignore[valid-type, misc]
        def add(self, *args: Any, **kwargs: Any) -> list[LoopConstraint]:
            seen.update(blas_threads())
            return super().add(*args, **kwargs)

    detector = Watching(config.loop_closure, scan_loader=lambda k: tiny_loop[k])
    with threadpool_limits(limits=2, user_api="blas"):
        pipeline = Pipeline(tiny_loop, config, max_frames=12, loop_detector=detector)
        with pytest.raises(LoopClosureError) if fails else contextlib.nullcontext():
            pipeline.run()
        assert blas_threads() == {2}
    assert seen == {1}


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity here")
def test_usable_cpus_follows_the_affinity() -> None:
    """`taskset -c 0 radar-slam run ...` is a one-CPU run."""
    allowed = os.sched_getaffinity(0)
    assert usable_cpus() == len(allowed)
    try:
        os.sched_setaffinity(0, {min(allowed)})
        assert usable_cpus() == 1
    finally:
        os.sched_setaffinity(0, allowed)


@pytest.fixture(scope="module")
def both_paths(tiny_loop: RadarSequence) -> tuple[Results, Results]:
    sequential = Pipeline(tiny_loop, configured(threads=False)).run()
    concurrent = Pipeline(tiny_loop, configured(threads=True)).run()
    return sequential, concurrent


def test_threads_give_the_same_trajectory_loops_and_metrics(
    both_paths: tuple[Results, Results],
) -> None:
    sequential, concurrent = both_paths
    assert sequential.metrics.loops_accepted >= 3  # there is something to compare
    np.testing.assert_array_equal(concurrent.odometry.poses, sequential.odometry.poses)
    np.testing.assert_allclose(concurrent.slam.poses, sequential.slam.poses, atol=1e-9, rtol=0)
    key = [(d.query_key, d.match_key, d.status, d.reason) for d in sequential.loops]
    assert [(d.query_key, d.match_key, d.status, d.reason) for d in concurrent.loops] == key
    same = dataclasses.replace(concurrent.metrics, seconds=0.0, frames_per_second=0.0)
    assert same == dataclasses.replace(sequential.metrics, seconds=0.0, frames_per_second=0.0)
    assert not our_threads()


def test_lag_keeps_the_accuracy(tiny_loop: RadarSequence, both_paths: tuple[Results, Results]):
    """Loops entering the graph 8 scans late cost no accuracy against adding them at once."""
    immediate = Pipeline(tiny_loop, configured(threads=False, lag=0)).run()
    lagged = both_paths[1]
    assert lagged.metrics.loops_accepted == immediate.metrics.loops_accepted
    assert lagged.metrics.ate_slam_m == pytest.approx(immediate.metrics.ate_slam_m, abs=0.01)


@pytest.mark.parametrize("threads", [False, True])
def test_a_read_error_reaches_the_caller_unchanged(tiny_loop: RadarSequence, threads: bool):
    seen: list[int] = []
    pipeline = Pipeline(
        FaultySequence(tiny_loop),  # type: ignore[arg-type]
        configured(threads),
        max_frames=20,
        progress=lambda p: seen.append(p.done),
    )
    with pytest.raises(DatasetFormatError, match=r"^scan0007\.png: truncated PNG$"):
        pipeline.run()
    assert seen == list(range(1, BAD_SCAN + 1))  # raised at the scan that failed
    assert not our_threads()


@pytest.mark.parametrize("threads", [False, True])
def test_a_loop_detector_error_reaches_the_caller_unchanged(
    tiny_loop: RadarSequence, threads: bool
) -> None:
    config = configured(threads)
    detector = FaultyDetector(config.loop_closure, scan_loader=lambda k: tiny_loop[k])
    pipeline = Pipeline(tiny_loop, config, max_frames=30, loop_detector=detector)
    with pytest.raises(LoopClosureError, match=r"^scan 7: pose must be 3 finite numbers$"):
        pipeline.run()
    assert not our_threads()


@pytest.mark.parametrize("threads", [False, True])
def test_an_interrupted_run_stops_its_threads(tiny_loop: RadarSequence, threads: bool) -> None:
    def interrupt(progress: Progress) -> None:
        if progress.done == BAD_SCAN:
            raise KeyboardInterrupt

    pipeline = Pipeline(tiny_loop, configured(threads), max_frames=30, progress=interrupt)
    with pytest.raises(KeyboardInterrupt):
        pipeline.run()
    assert not our_threads()


def test_reader_hands_out_scans_in_order_then_the_error(tiny_loop: RadarSequence) -> None:
    faulty = FaultySequence(tiny_loop)
    with ScanReader(faulty.__getitem__, 12, depth=3) as reader:
        stamps = [reader.next().timestamp_ns for _ in range(BAD_SCAN)]
        with pytest.raises(DatasetFormatError, match="scan0007"):
            reader.next()
    assert stamps == [int(t) for t in tiny_loop.timestamps_ns[:BAD_SCAN]]
    assert not our_threads()
