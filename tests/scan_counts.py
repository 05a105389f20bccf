"""Counters of what a run does to its scans: reads of the sequence, conditionings, RaPlace
descriptors and pose images (keyed by the conditioned image they were made of), and scan records
read back (`counting`)."""

from __future__ import annotations

import hashlib
from collections import Counter
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from unittest import mock

import numpy as np

from odometry import PolarScan, PreprocessConfig, Scan, preprocess_polar
from radar_slam.datasets.frame import RadarFrame, RadarSequence
from radar_slam.maps.images import PSEUDO_SENSOR
from radar_slam.maps.keyframes import KeyframeRecorder
from raplace import DescriptorExtractor, PoseEstimator

CONDITIONING_SITES = (
    "odometry.odometry",
    "odometry.registration",
    "radar_slam.loops.detector",
    "radar_slam.loops.verification",
    "radar_slam.maps.keyframes",
    "radar_slam.pipeline.slam",
)
"""The modules that call the odometry's conditioning (`preprocess_polar`) on a scan."""


def content_key(image: np.ndarray) -> str:
    """An image's content as a key (the same pixels: the same key)."""
    return hashlib.sha1(np.ascontiguousarray(image).tobytes()).hexdigest()


@dataclass
class Counts:
    """What a run did to its scans.

    Attributes:
        decodes: scan index -> reads of the sequence.
        conditioned: scan timestamp [ns] -> odometry conditionings of the scan itself.
        record_conditioned: conditionings of database scans remade from their records.
        described: image -> RaPlace descriptors made of it.
        pose_images: image -> RaPlace pose images made of it.
        scan_images, record_images: the conditioned images made of the scans, of the records.
        records_read: database scans taken back from their records for verification.
    """

    decodes: Counter[int]
    conditioned: Counter[int]
    record_conditioned: int
    described: Counter[str]
    pose_images: Counter[str]
    records_read: int
    scan_images: set[str] = field(default_factory=set)
    record_images: set[str] = field(default_factory=set)

    @property
    def record_pose_images(self) -> int:
        """RaPlace pose images made of the records read back."""
        return sum(n for key, n in self.pose_images.items() if key in self.record_images)


@contextmanager
def counting(sequence: RadarSequence) -> Iterator[Counts]:
    """Count, while in the block, the reads of `sequence`'s scans, the odometry's conditionings,
    the RaPlace descriptors and pose images, and the records read back."""
    kind = type(sequence)
    conditionings: list[tuple[Scan, PolarScan]] = []

    def condition(scan: Scan, cfg: PreprocessConfig) -> PolarScan:
        conditionings.append((scan, preprocess_polar(scan, cfg)))
        return conditionings[-1][1]

    with ExitStack() as stack:
        read = stack.enter_context(
            mock.patch.object(kind, "__getitem__", autospec=True, side_effect=kind.__getitem__)
        )
        for site in CONDITIONING_SITES:
            stack.enter_context(mock.patch(f"{site}.preprocess_polar", condition))
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
        counts = Counts(Counter(), Counter(), 0, Counter(), Counter(), 0)
        yield counts
        counts.decodes.update(int(call.args[1]) for call in read.call_args_list)
        for scan, polar in conditionings:
            from_record = scan.sensor == PSEUDO_SENSOR
            images = counts.record_images if from_record else counts.scan_images
            images.add(content_key(polar.image))
            if from_record:
                counts.record_conditioned += 1
            else:
                counts.conditioned[int(scan.timestamp_ns)] += 1
        counts.described.update(content_key(call.args[1]) for call in describe.call_args_list)
        counts.pose_images.update(content_key(call.args[1]) for call in pose.call_args_list)
        counts.records_read = len(records)
