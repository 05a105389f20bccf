"""Building a map from a SLAM run: keyframes, descriptors, images, the reduced pose graph.

`build_map(results)` takes a keyframe every `maps.keyframe_spacing_m` of the odometry path
(`KeyframeSpacing`, the rule the run applies as it goes) with its RaPlace descriptor (as the
loop detector describes scans) and its de-skewed Cartesian image (`radar_slam.maps.images`). A
run made with `Pipeline(record_map=True)` already holds them (`radar_slam.maps.keyframes`), so no
scan is read again; for another run, `build_map(results, sequence)` reads the keyframe scans
again and makes the same content. The pose graph is the run's graph reduced to the keyframes,
at their optimised poses: an odometry edge between consecutive keyframes (the optimised relative
pose, the chained odometry covariance) and each accepted loop moved onto the keyframes at or
before its two scans. With ground truth, the map stores the SE(2) Umeyama alignment of the
optimised trajectory to it (T_gt_map) and each keyframe's GT pose.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from odometry import OdometryConfig, OdometryResult, Velocity
from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import RadarSlamError, TrajectoryError
from radar_slam.evaluation.metrics import associate, umeyama_alignment_se2
from radar_slam.loops import LoopDecision
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.loops.sweep_twist import scan_sweep_twist, step_velocities
from radar_slam.maps.config import MapsConfig
from radar_slam.maps.format import EDGE_DTYPE, EDGE_KINDS, KEYFRAME_DTYPE, Map, Session
from radar_slam.maps.images import KEYFRAME_IMAGE, ImageGeometry, KeyframeImager
from radar_slam.maps.keyframes import (
    DESCRIPTOR_DTYPE,
    KeyframeRecord,
    KeyframeSpacing,
    describe_keyframe,
)
from radar_slam.trajectory import Trajectory
from raplace import DescriptorConfig, DescriptorExtractor, between, compose, rotate_covariance

if TYPE_CHECKING:
    from radar_slam.pipeline import Results

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
_UPPER = np.triu_indices(3)


def select_keyframes(poses: FloatArray, spacing_m: float) -> NDArray[np.int64]:
    """Indices of the poses (N, 3) that become keyframes: the first, then one each time the
    path since the previous keyframe reaches `spacing_m` [m] (`KeyframeSpacing`)."""
    spacing = KeyframeSpacing(spacing_m)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    chosen = [n for n, pose in enumerate(poses) if spacing.is_keyframe(pose)]
    return np.asarray(chosen, dtype=np.int64)


def information_upper(covariance: FloatArray) -> FloatArray:
    """(6,) upper triangle of the inverse of a (3, 3) covariance (g2o order)."""
    info = np.linalg.inv(np.asarray(covariance, dtype=np.float64))
    return (0.5 * (info + info.T))[_UPPER]


def edge_rows(
    keyframe_scans: NDArray[np.int64],
    poses: FloatArray,
    odometry: list[OdometryResult],
    loops: list[LoopDecision],
    index_offset: int = 0,
) -> NDArray[Any]:
    """The run's pose graph reduced to its keyframes (`EDGE_DTYPE` rows).

    Args:
        keyframe_scans: (K,) increasing scan indices of the keyframes.
        poses: (N, 3) optimised poses of every scan.
        odometry: the per-scan odometry results (factor covariances).
        loops: the loop decisions; the accepted ones become loop edges.
        index_offset: added to the keyframe indices (for a session appended to a map).
    """
    rows = []
    for n in range(1, len(keyframe_scans)):
        a, b = int(keyframe_scans[n - 1]), int(keyframe_scans[n])
        covariance = np.zeros((3, 3))
        for s in range(a + 1, b + 1):
            yaw_to_b = float(between(poses[s], poses[b])[2])
            covariance += rotate_covariance(odometry[s].covariance, -yaw_to_b)
        measurement = between(poses[a], poses[b])
        odometry_kind = EDGE_KINDS.index("odometry")
        rows.append((n - 1, n, odometry_kind, measurement, information_upper(covariance)))
    owner = np.searchsorted(keyframe_scans, np.arange(len(poses)), side="right") - 1
    for loop in loops:
        if not loop.accepted:
            continue
        kq, km = int(owner[loop.query_key]), int(owner[loop.match_key])
        if kq == km:
            continue
        lead = between(poses[keyframe_scans[kq]], poses[loop.query_key])
        tail = between(poses[loop.match_key], poses[keyframe_scans[km]])
        measurement = compose(compose(lead, loop.measurement), tail)
        covariance = rotate_covariance(loop.covariance, -float(tail[2]))
        rows.append((kq, km, EDGE_KINDS.index("loop"), measurement, information_upper(covariance)))
    edges = np.array(rows, dtype=EDGE_DTYPE) if rows else np.zeros(0, dtype=EDGE_DTYPE)
    edges["i"] += index_offset
    edges["j"] += index_offset
    return edges


def gt_alignment(slam: Trajectory, gt: Trajectory | None) -> FloatArray | None:
    """SE(2) T_gt_slam by Umeyama over the associated poses, or None."""
    if gt is None:
        return None
    try:
        return np.asarray(umeyama_alignment_se2(*associate(slam, gt)), dtype=np.float64)
    except TrajectoryError as exc:
        log.warning("map without GT alignment: %s", exc)
        return None


def map_settings(cfg: MapsConfig, descriptor: DescriptorConfig) -> dict[str, Any]:
    """The settings recorded in map.json (plain JSON)."""
    return {
        "keyframe_spacing_m": cfg.keyframe_spacing_m,
        "image": asdict(KEYFRAME_IMAGE),
        "descriptor": asdict(descriptor),
    }


def describe_keyframes(
    sequence: RadarSequence,
    scans: NDArray[np.int64],
    velocities: list[Velocity | None],
    image: ImageGeometry,
    odometry: OdometryConfig,
    descriptor: DescriptorConfig,
) -> tuple[NDArray[np.float16], list[bytes], NDArray[np.float32]]:
    """Read the keyframe scans again: (K, n_theta, n_freq) float16 descriptors, PNG images
    (de-skewed with each scan's sweep twist from the run's `step_velocities`) and their
    intensity scales (`describe_keyframe`, as a recording run makes them)."""
    describe = DescriptorExtractor(descriptor)
    imager = KeyframeImager(image, odometry)
    records = []
    for scan in scans:
        frame = sequence[int(scan)]
        twist = scan_sweep_twist(velocities, int(scan), frame)
        records.append(describe_keyframe(int(scan), frame, twist, imager, describe))
    return stacked(records, describe.shape)


def stacked(
    records: Sequence[KeyframeRecord], shape: tuple[int, int]
) -> tuple[NDArray[np.float16], list[bytes], NDArray[np.float32]]:
    """(K, n_theta, n_freq) descriptors, PNG images and (K,) scales of keyframe records
    (`shape`: one descriptor's, for none)."""
    descriptors = np.zeros((len(records), *shape), dtype=DESCRIPTOR_DTYPE)
    for n, record in enumerate(records):
        descriptors[n] = record.descriptor
    images = [r.png for r in records]
    return descriptors, images, np.asarray([r.image_scale for r in records], dtype=np.float32)


def keyframe_content(
    results: Results,
    sequence: RadarSequence | None,
    image: ImageGeometry,
    descriptor: DescriptorConfig,
) -> tuple[NDArray[np.int64], NDArray[np.float16], list[bytes], NDArray[np.float32]]:
    """(scans, descriptors, images, scales) of a run's keyframes: those it recorded when they
    were made with these settings, else read from `sequence` again.

    Raises:
        RadarSlamError: the run recorded no such keyframes and no sequence is given.
    """
    cfg = results.config
    spacing_m = cfg.maps.keyframe_spacing_m
    recorded = results.map_keyframes
    if recorded is not None and recorded.made_with(spacing_m, image, descriptor, cfg.odometry):
        scans = np.asarray([r.scan for r in recorded.records], dtype=np.int64)
        return (scans, *stacked(recorded.records, (descriptor.n_theta, descriptor.n_freq)))
    if sequence is None:
        raise RadarSlamError(
            f"no map of {results.sequence}: the run kept no keyframes with these settings "
            "(Pipeline(record_map=True)) and no sequence was given to read them from"
        )
    scans = select_keyframes(results.odometry.poses, spacing_m)
    log.info("map of %s: reading %d keyframe scans again", results.sequence, len(scans))
    velocities = step_velocities(results.odometry_results, cfg.odometry)
    content = describe_keyframes(sequence, scans, velocities, image, cfg.odometry, descriptor)
    return (scans, *content)


def keyframe_rows(
    session: int,
    scans: NDArray[np.int64],
    timestamps_ns: NDArray[np.int64],
    poses: FloatArray,
    gt_poses: FloatArray | None,
    scales: NDArray[np.float32],
) -> NDArray[Any]:
    """`KEYFRAME_DTYPE` rows of one session's keyframes (image offsets filled in on writing)."""
    rows = np.zeros(len(scans), dtype=KEYFRAME_DTYPE)
    rows["session"] = session
    rows["scan"] = scans
    rows["timestamp_ns"] = timestamps_ns[scans]
    rows["pose"] = poses[scans]
    rows["gt_pose"] = np.nan if gt_poses is None else gt_poses[scans]
    rows["image_scale"] = scales
    return rows


def build_map(
    results: Results, sequence: RadarSequence | None = None, poses: FloatArray | None = None
) -> Map:
    """A one-session map of a SLAM run (keyframes at their poses in `results.slam`, or `poses`).

    Args:
        results: the run.
        sequence: the sequence it ran on, read again only when the run kept no keyframes
            (`Pipeline(record_map=True)` keeps them).
        poses: (N, 3) poses to use instead of `results.slam` (e.g. already in another frame).

    Raises:
        RadarSlamError: no recorded keyframes and no sequence.
    """
    cfg = results.config.maps
    descriptor_cfg = LOOP_RAPLACE.descriptor
    slam = results.slam if poses is None else Trajectory(results.slam.timestamps_ns, poses)
    scans, descriptors, images, scales = keyframe_content(
        results, sequence, KEYFRAME_IMAGE, descriptor_cfg
    )
    stamps = slam.timestamps_ns
    keyframes = keyframe_rows(0, scans, stamps, slam.poses, results.ground_truth_poses, scales)
    edges = edge_rows(scans, slam.poses, results.odometry_results, results.loops)
    session = Session(results.sequence, len(slam), int(stamps[0]), int(stamps[-1]))
    log.info("map of %s: %d keyframes, %d edges", results.sequence, len(scans), len(edges))
    return Map(
        keyframes=keyframes,
        descriptors=descriptors,
        images=tuple(images),
        edges=edges,
        sessions=(session,),
        settings=map_settings(cfg, descriptor_cfg),
        gt_alignment=gt_alignment(slam, results.ground_truth),
    )
