"""One pass per scan: a SLAM run decodes each scan once, conditions it once (the odometry's
conditioning, which the RaPlace descriptor and pose image are made of too) and describes it
once (joined to a map with `radar-slam run --map` too); the loop verifier takes a database scan
back from its record (in `radar-slam loops` too), and what a run keeps per scan, on a
10,000-scan drive, stays within the memory budget (`GROWTH_BUDGET_BYTES`). (Config files and
openings of the sequence per command: tests/test_one_pass_open.py.)"""

from __future__ import annotations

import dataclasses
import json
import tracemalloc
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from scan_counts import Counts, counting

from radar_slam.cli import main
from radar_slam.datasets import open_sequence
from radar_slam.datasets.frame import RadarSequence
from radar_slam.g2o import G2oEdge, G2oGraph
from radar_slam.pipeline import (
    MEMORY_BUDGET_SCANS,
    Pipeline,
    PipelineConfig,
    Progress,
    Results,
    close_loops_on_graph,
    load_config,
)
from raplace import between

DRIVE_SCANS = MEMORY_BUDGET_SCANS
"""The drive the memory budget is stated for (MulRan resolution, default config)."""
GROWTH_BUDGET_BYTES = 600 * 2**20
"""What a run may keep per scan, times `DRIVE_SCANS` (docs/benchmarks.md, Memory budget)."""
WARM_SCANS = 40
"""Scans after which the run's fixed working memory is allocated (odometry images, caches)."""


@dataclass(frozen=True)
class CountedRun:
    results: Results
    pipeline: Pipeline
    counts: Counts


@pytest.fixture(scope="module")
def counted_run(tiny_loop: RadarSequence) -> CountedRun:
    """The whole of tiny_loop (it comes back to its start: loops are verified), with its map."""
    with counting(tiny_loop) as counts:
        pipeline = Pipeline(tiny_loop, load_config("synthetic"), record_map=True)
        results = pipeline.run()
    return CountedRun(results, pipeline, counts)


def test_each_scan_is_decoded_once(counted_run: CountedRun) -> None:
    frames = counted_run.results.metrics.frames
    assert frames == 177
    assert counted_run.counts.decodes == Counter(range(frames))


def test_database_scans_are_verified_from_their_records(counted_run: CountedRun) -> None:
    metrics = counted_run.results.metrics
    assert metrics.loops_accepted >= 4
    assert metrics.loops_accepted_true == metrics.loops_accepted
    counts = counted_run.counts
    assert counts.records_read >= metrics.loops_proposed
    # each record read back is conditioned once (the scan itself never again), and that
    # conditioned form imaged for the sinogram pose unless the loop was checked from a prediction
    assert counts.record_conditioned == counts.records_read
    assert 0 < counts.record_pose_images <= counts.records_read


def test_each_scan_is_conditioned_once(tiny_loop: RadarSequence, counted_run: CountedRun) -> None:
    """One conditioning per scan, and every RaPlace descriptor and pose image is made of a
    conditioned image (a scan's or a record's): RaPlace conditions nothing of its own."""
    counts = counted_run.counts
    stamps = np.asarray(tiny_loop.timestamps_ns)[: counted_run.results.metrics.frames]
    assert counts.conditioned == Counter(int(t) for t in stamps)
    assert len(counts.scan_images) == len(stamps)
    assert set(counts.described) <= counts.scan_images
    assert set(counts.pose_images) <= counts.scan_images | counts.record_images
    assert set(counts.pose_images) & counts.scan_images  # the queries' own


def test_each_scan_is_described_once(counted_run: CountedRun) -> None:
    counts, pipeline = counted_run.counts, counted_run.pipeline
    database = len(pipeline.loop_detector)  # type: ignore[arg-type]
    assert database >= 40
    assert max(counts.described.values()) == 1
    assert sum(counts.described.values()) == database  # the map took the detector's
    recorded = counted_run.results.map_keyframes
    assert recorded is not None
    taken = pipeline.keyframes.descriptors_taken  # type: ignore[attr-defined]
    assert taken == len(recorded.records)
    assert max(n for key, n in counts.pose_images.items() if key in counts.scan_images) == 1


VERTEX_BASE = 1000
"""Vertex ids of the graph given to `radar-slam loops` start here (not the scan indices)."""


def test_loops_on_another_graph_read_each_scan_once(
    tiny_loop: RadarSequence, counted_run: CountedRun
) -> None:
    """`radar-slam loops`: candidates are verified from their records, keyed by vertex id."""
    poses = counted_run.results.odometry.poses
    info = np.eye(3)
    vertices = {VERTEX_BASE + k: pose for k, pose in enumerate(poses)}
    edges = [
        G2oEdge(VERTEX_BASE + k, VERTEX_BASE + k + 1, between(poses[k], poses[k + 1]), info)
        for k in range(len(poses) - 1)
    ]
    with counting(tiny_loop) as counts:
        run = close_loops_on_graph(
            G2oGraph(vertices, edges, [VERTEX_BASE]), tiny_loop, load_config("synthetic")
        )
    assert run.n_accepted >= 4
    assert all(d.query_key >= VERTEX_BASE and d.match_key >= VERTEX_BASE for d in run.loops)
    assert counts.decodes == Counter(range(len(tiny_loop)))
    assert counts.records_read >= len(run.loops)


def test_a_session_joined_to_a_map_is_read_and_described_once(
    synthetic_root: Path, tmp_path: Path
) -> None:
    """`run --map`: the session's keyframes are looked up in the map as the run makes them; no
    scan is read or described again to join the map or to extend it."""
    stride = 4
    root = ["--data-root", str(synthetic_root), "--stride", str(stride)]
    assert main(["run", "synthetic/tiny_reverse_a", "--out", str(tmp_path / "a"), *root]) == 0
    session = open_sequence("synthetic/tiny_reverse_b", synthetic_root)
    args = ["run", "synthetic/tiny_reverse_b", "--map", str(tmp_path / "a" / "map")]
    with counting(session) as counts:
        assert main([*args, "--out", str(tmp_path / "ab"), *root]) == 0
    joined = json.loads((tmp_path / "ab" / "multisession.json").read_text())
    assert joined["met_map"] and joined["intersession_accepted"] >= 10
    scans = range(0, len(session), stride)
    assert joined["map_keyframes"] > len(scans)  # the map's and every scan of the session
    assert counts.decodes == Counter(scans)
    assert max(counts.described.values()) == 1
    assert sum(counts.described.values()) == len(scans)  # every scan, once (at this stride)


def sequential(config: PipelineConfig) -> PipelineConfig:
    """`config` without the reader and loop threads."""
    concurrency = dataclasses.replace(config.concurrency, loop_thread=False, read_ahead_scans=0)
    return dataclasses.replace(config, concurrency=concurrency)


def test_what_a_run_keeps_per_scan_fits_the_budget(tiny_loop: RadarSequence) -> None:
    """The memory a run still holds after each scan grows by what it keeps per scan (records,
    database descriptors, odometry results, cached pose spectra): measured between scan
    `WARM_SCANS` and the last, times `DRIVE_SCANS`, within the budget."""
    held: dict[int, int] = {}

    def measure(progress: Progress) -> None:
        if not progress.step and progress.done in (WARM_SCANS, len(tiny_loop)):
            held[progress.done] = tracemalloc.get_traced_memory()[0]

    config = sequential(load_config("synthetic"))
    tracemalloc.start()
    try:
        Pipeline(tiny_loop, config, progress=measure, record_map=True).run()
    finally:
        tracemalloc.stop()
    per_scan = (held[len(tiny_loop)] - held[WARM_SCANS]) / (len(tiny_loop) - WARM_SCANS)
    assert 5_000 < per_scan, f"{per_scan:.0f} bytes per scan"  # records, descriptors, results
    assert per_scan * DRIVE_SCANS <= GROWTH_BUDGET_BYTES, f"{per_scan:.0f} bytes per scan"
