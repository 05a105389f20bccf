"""Counters of what a run does to its scans: reads of the sequence, conditionings,
descriptors, pose images and scan records read back (`counting`)."""

from __future__ import annotations

import hashlib
from collections import Counter
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from unittest import mock

import numpy as np

from odometry import preprocess_polar
from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.maps.images import PSEUDO_SENSOR
from radar_slam.maps.keyframes import KeyframeRecorder
from raplace import DescriptorExtractor, PoseEstimator

CONDITIONING_SITES = (
    "odometry.odometry",
    "odometry.registration",
    "radar_slam.maps.images",
    "radar_slam.maps.keyframes",
    "radar_slam.pipeline.slam",
)
"""The modules that call the odometry's conditioning (`preprocess_polar`) on a scan."""


def content_key(polar: np.ndarray) -> str:
    """A scan's polar image as a key (the same image: the same key)."""
    return hashlib.sha1(np.ascontiguousarray(polar).tobytes()).hexdigest()


@dataclass
class Counts:
    """What a run did to its scans.

    Attributes:
        decodes: scan index -> reads of the sequence.
        conditioned: scan timestamp [ns] -> odometry conditionings of the scan itself.
        record_conditioned: conditionings of database scans remade from their records.
        described: polar image -> RaPlace descriptors made of it.
        pose_images: polar image of a scan -> RaPlace pose images made of it.
        records_read: database scans taken back from their records for verification.
        record_pose_images: RaPlace pose images made of those.
    """

    decodes: Counter[int]
    conditioned: Counter[int]
    record_conditioned: int
    described: Counter[str]
    pose_images: Counter[str]
    records_read: int
    record_pose_images: int


@contextmanager
def counting(sequence: RadarSequence) -> Iterator[Counts]:
    """Count, while in the block, the reads of `sequence`'s scans, the odometry's conditionings,
    the RaPlace descriptors and pose images, and the records read back."""
    kind = type(sequence)
    with ExitStack() as stack:
        read = stack.enter_context(
            mock.patch.object(kind, "__getitem__", autospec=True, side_effect=kind.__getitem__)
        )
        conditionings = [
            stack.enter_context(mock.patch(f"{site}.preprocess_polar", wraps=preprocess_polar))
            for site in CONDITIONING_SITES
        ]
        describe = stack.enter_context(
            mock.patch.object(
                DescriptorExtractor,
                "__call__",
                autospec=True,
                side_effect=DescriptorExtractor.__call__,
            )
        )
        pose = stack.enter_context(
            mock.patch.object(
                PoseEstimator, "image", autospec=True, side_effect=PoseEstimator.image
            )
        )
        records: list[RadarFrame] = []
        scan_of_record = KeyframeRecorder.scan

        def read_record(recorder: KeyframeRecorder, scan_index: int) -> RadarFrame:
            records.append(scan_of_record(recorder, scan_index))
            return records[-1]

        stack.enter_context(mock.patch.object(KeyframeRecorder, "scan", read_record))
        counts = Counts(Counter(), Counter(), 0, Counter(), Counter(), 0, 0)
        yield counts
        counts.decodes.update(int(call.args[1]) for call in read.call_args_list)
        scans = [call.args[0] for m in conditionings for call in m.call_args_list]
        counts.conditioned.update(int(s.timestamp_ns) for s in scans if s.sensor != PSEUDO_SENSOR)
        counts.record_conditioned = sum(s.sensor == PSEUDO_SENSOR for s in scans)
        counts.described.update(content_key(call.args[1]) for call in describe.call_args_list)
        from_records = {content_key(frame.polar) for frame in records}
        imaged = [content_key(call.args[1]) for call in pose.call_args_list]
        counts.pose_images.update(key for key in imaged if key not in from_records)
        counts.record_pose_images = sum(key in from_records for key in imaged)
        counts.records_read = len(records)
