"""Scan records made as a run goes: each kept scan's descriptor and image, made once.

A map stores, per keyframe, its RaPlace descriptor and its de-skewed Cartesian image
(`radar_slam.maps.images`). `KeyframeRecorder` receives every scan of a run once the odometry has
registered the scan after it: the raw scan, its conditioned form (`odometry.Odometry.prepared`)
and its odometry result. It makes a record of the map keyframes along the odometry path
(`KeyframeSpacing`, when the run keeps a map) and of every scan the loop detector enters into its
place database (`offer_descriptor`), as soon as the step after the scan is known (the image is
de-skewed with the scan's sweep twist, `radar_slam.loops.sweep_twist`); the descriptor is the one
the loop detector made of the scan when it made one. A `KeyframeListener` given to the recorder
receives each map keyframe as its record is made, with the raw scan, its sweep twist and its
descriptor (`radar-slam run --map` looks it up in the map then, `radar_slam.maps.session`). It
keeps the records (about 30 kB per scan at the default image geometry), never the scans: the
loop verifier takes a database scan back from its record (`scan`), and
`radar_slam.maps.build.build_map` writes the map from them, so that no scan is read twice.

`describe_keyframe` is the one recipe of a keyframe's content, used by the recorder and by the
rebuild from a sequence (`radar_slam.maps.build.describe_keyframes`): a map made either way is
the same.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from odometry import (
    OdometryConfig,
    OdometryResult,
    PolarScan,
    RadarFrame,
    Scan,
    Velocity,
    preprocess_polar,
)
from radar_slam.errors import RadarSlamError
from radar_slam.loops.records import raplace_input
from radar_slam.loops.sweep_twist import mean_acquisition_time_ns, step_velocity, sweep_twist
from radar_slam.maps.config import MapsConfig
from radar_slam.maps.images import KEYFRAME_IMAGE, ImageGeometry, KeyframeImager
from raplace import DescriptorConfig, DescriptorExtractor

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
DESCRIPTOR_DTYPE = np.float16
"""How a map stores its descriptors (half precision: half the bytes, ample for retrieval)."""
KeyframeListener = Callable[[int, Scan, PolarScan, "FloatArray | None", NDArray[np.float32]], None]
"""Takes a map keyframe as its record is made: its scan index, the raw scan, its conditioned
form (`preprocess_polar` with the run's odometry settings), its sweep twist (3,) (vx, vy [m/s],
yaw rate [rad/s]) or None, and its RaPlace descriptor (n_theta, n_freq) float32 (neither to be
changed)."""


class KeyframeSpacing:
    """The keyframe rule, one pose at a time: the first pose, then one each time the path since
    the previous keyframe reaches `spacing_m` [m] (`radar_slam.maps.build.select_keyframes` applies
    it to a whole trajectory)."""

    def __init__(self, spacing_m: float) -> None:
        self.spacing_m = spacing_m
        self._travelled = 0.0
        self._last: FloatArray | None = None

    def is_keyframe(self, pose: ArrayLike) -> bool:
        """Whether the next pose (x, y [m], yaw) is a keyframe."""
        position = np.asarray(pose, dtype=np.float64).reshape(-1)[:2]
        if self._last is None:
            self._last = position
            return True
        step = np.hypot(*(position - self._last))
        self._last = position
        self._travelled += float(step)
        if self._travelled >= self.spacing_m:
            self._travelled = 0.0
            return True
        return False


@dataclass(frozen=True)
class KeyframeRecord:
    """What a map stores of one keyframe.

    Attributes:
        scan: the scan's index in the run.
        descriptor: (n_theta, n_freq) RaPlace descriptor, `DESCRIPTOR_DTYPE`.
        png: the PNG bytes of its de-skewed Cartesian image (`KeyframeImager.encode`).
        image_scale: the image's intensity scale (`KeyframeImager.encode`).
    """

    scan: int
    descriptor: NDArray[np.float16]
    png: bytes
    image_scale: float


@dataclass(frozen=True)
class RecordedKeyframes:
    """A run's map keyframes and the settings they were made with.

    Attributes:
        records: one per keyframe, in scan order.
        spacing_m: the keyframe spacing along the odometry path [m].
        image: the image geometry.
        descriptor: the RaPlace descriptor settings.
        odometry: the odometry settings (the images' conditioning and de-skew limits).
    """

    records: tuple[KeyframeRecord, ...]
    spacing_m: float
    image: ImageGeometry
    descriptor: DescriptorConfig
    odometry: OdometryConfig

    def made_with(
        self,
        spacing_m: float,
        image: ImageGeometry,
        descriptor: DescriptorConfig,
        odometry: OdometryConfig,
    ) -> bool:
        """Whether these keyframes are what those settings make."""
        made = (self.spacing_m, self.image, self.descriptor, self.odometry)
        return made == (spacing_m, image, descriptor, odometry)


def describe_keyframe(
    scan_index: int,
    frame: Scan,
    twist: FloatArray | None,
    imager: KeyframeImager,
    describe: DescriptorExtractor,
    polar: PolarScan | None = None,
    descriptor: NDArray[np.floating] | None = None,
) -> KeyframeRecord:
    """A keyframe's record: its descriptor and its image de-skewed with `twist`.

    Args:
        scan_index: the scan's index in the run.
        frame: the raw scan.
        twist: (3,) its sweep twist (vx, vy [m/s], yaw rate [rad/s]), or None.
        imager: renders and encodes the image.
        describe: the RaPlace descriptor extractor (of conditioned scans, `LOOP_RAPLACE`).
        polar: the scan's conditioned form (`preprocess_polar` with the imager's odometry
            settings), when already made.
        descriptor: the descriptor `describe` makes of `polar`, when already made.
    """
    if polar is None:
        polar = preprocess_polar(frame, imager.odometry.preprocess)
    if descriptor is None:
        descriptor = describe(*raplace_input(polar))
    png, scale = imager.encode(imager.render(polar, twist))
    return KeyframeRecord(scan_index, np.asarray(descriptor, dtype=DESCRIPTOR_DTYPE), png, scale)


@dataclass(frozen=True)
class _Held:
    """The last scan received, kept until the step after it is known.

    Attributes:
        result: its odometry result.
        before: the velocity of the step into it (None: first scan, or not plausible).
        frame, polar: the scan and its conditioned form (None: made when it is recorded).
        keyframe: whether it is a map keyframe.
    """

    result: OdometryResult
    before: Velocity | None
    frame: Scan
    polar: PolarScan | None
    keyframe: bool


class KeyframeRecorder:
    """Picks a run's map keyframes and makes their records as the scans come (see the module doc).

    Call `add` for every scan in order, `offer_descriptor` (optional) between the `add` of a scan
    and the `add` of the next, and `finish` once after the last; all from one thread (`scan` too).

    Args:
        maps: the keyframe spacing (the image geometry is `KEYFRAME_IMAGE`).
        odometry: the odometry settings (conditioning, the vehicle's limits).
        descriptor: the RaPlace descriptor settings.
        keep_map: record the map keyframes (else only the scans offered a descriptor).
        on_keyframe: receives each map keyframe as its record is made (in the thread of the
            call that makes it: `add` or `finish`).
    """

    def __init__(
        self,
        maps: MapsConfig,
        odometry: OdometryConfig,
        descriptor: DescriptorConfig,
        keep_map: bool = True,
        on_keyframe: KeyframeListener | None = None,
    ) -> None:
        self.maps = maps
        self.odometry = odometry
        self.descriptor_config = descriptor
        self.keep_map = keep_map
        self.on_keyframe = on_keyframe
        self.imager = KeyframeImager(KEYFRAME_IMAGE, odometry)
        self.describe = DescriptorExtractor(descriptor)
        self.spacing = KeyframeSpacing(maps.keyframe_spacing_m)
        self._keyframes: list[int] = []
        self.records: dict[int, tuple[KeyframeRecord, int]] = {}
        """Scan index -> (its record, its timestamp [ns]): the map keyframes and the scans
        offered a descriptor."""
        self._held: _Held | None = None
        self._offered: tuple[int, NDArray[np.float32]] | None = None
        self.descriptors_taken = 0
        """Keyframes whose descriptor came from `offer_descriptor` (not made here)."""

    def add(self, frame: Scan, polar: PolarScan | None, result: OdometryResult) -> None:
        """Receive the next scan: the raw scan, its conditioned form (None: made here when it is
        recorded) and its odometry result (final: the next scan has registered)."""
        held = self._held
        before = None if held is None else step_velocity(held.result, result, self.odometry)
        if held is not None:
            self._make(held, after=before)
        keyframe = self.spacing.is_keyframe(result.pose) and self.keep_map
        self._held = _Held(result, before, frame, polar, keyframe)

    def offer_descriptor(self, scan_index: int, descriptor: NDArray[np.floating]) -> None:
        """The descriptor of the last scan received, made elsewhere (the loop detector, with the
        same settings, as the scan enters its database): the scan is recorded with it."""
        held = self._held
        if held is not None and held.result.index == scan_index:
            self._offered = (scan_index, np.asarray(descriptor, dtype=np.float32))

    def scan(self, scan_index: int) -> RadarFrame:
        """A recorded scan as its image sampled back onto a polar grid
        (`KeyframeImager.pseudo_scan`): what the loop verifier takes of a database scan.

        Raises:
            RadarSlamError: scan `scan_index` has no record (not offered a descriptor).
        """
        recorded = self.records.get(int(scan_index))
        if recorded is None:
            raise RadarSlamError(f"scan {scan_index} has no record (not in the loop database)")
        record, timestamp_ns = recorded
        return self.imager.pseudo_scan(record.png, timestamp_ns)

    @property
    def nbytes(self) -> int:
        """Bytes the records take (images and descriptors)."""
        return sum(len(r.png) + r.descriptor.nbytes for r, _ in self.records.values())

    def finish(self) -> RecordedKeyframes:
        """Make the last scan's record (no step after it) and return every keyframe's."""
        if self._held is not None:
            self._make(self._held, after=None)
            self._held = None
        log.info(
            "map keyframes: %d made during the run, %d with the loop detector's descriptor",
            len(self._keyframes),
            self.descriptors_taken,
        )
        return RecordedKeyframes(
            tuple(self.records[scan][0] for scan in self._keyframes),
            self.maps.keyframe_spacing_m,
            KEYFRAME_IMAGE,
            self.descriptor_config,
            self.odometry,
        )

    def _make(self, held: _Held, after: Velocity | None) -> None:
        index = held.result.index
        offered = self._offered
        self._offered = None
        descriptor = offered[1] if offered is not None and offered[0] == index else None
        if descriptor is None and not held.keyframe:
            return
        self.descriptors_taken += descriptor is not None and held.keyframe
        if held.keyframe:
            self._keyframes.append(index)
        frame = held.frame
        twist = sweep_twist(held.before, after, mean_acquisition_time_ns(frame))
        polar = held.polar
        if polar is None:
            polar = preprocess_polar(frame, self.odometry.preprocess)
        if descriptor is None:
            descriptor = self.describe(*raplace_input(polar))
        record = describe_keyframe(
            index, frame, twist, self.imager, self.describe, polar, descriptor
        )
        self.records[index] = (record, int(frame.timestamp_ns))
        if held.keyframe and self.on_keyframe is not None:
            self.on_keyframe(index, frame, polar, twist, descriptor)


class KeyframeStage(Protocol):
    """What a run feeds its map keyframes with (`KeyframeRecorder` or `NullKeyframeRecorder`)."""

    def add(self, frame: Scan, polar: PolarScan | None, result: OdometryResult) -> None: ...

    def offer_descriptor(self, scan_index: int, descriptor: NDArray[np.floating]) -> None: ...

    def scan(self, scan_index: int) -> RadarFrame: ...

    def finish(self) -> RecordedKeyframes | None: ...


class NullKeyframeRecorder:
    """A recorder that keeps nothing (a run that writes no map)."""

    def add(self, frame: Scan, polar: PolarScan | None, result: OdometryResult) -> None:
        """Ignore the scan."""

    def offer_descriptor(self, scan_index: int, descriptor: NDArray[np.floating]) -> None:
        """Ignore the descriptor."""

    def scan(self, scan_index: int) -> RadarFrame:
        """No scan is recorded.

        Raises:
            RadarSlamError: always.
        """
        raise RadarSlamError(f"scan {scan_index} has no record (the run keeps none)")

    def finish(self) -> None:
        """Nothing was recorded."""
