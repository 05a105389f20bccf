"""Live viewer: streams a SLAM run to Rerun (`radar-slam run SEQ --viewer [FILE.rrd]`).

Optional: needs the `viewer` extra (`pip install 'radar-slam[viewer]'`, i.e. rerun-sdk); without
it `--viewer` fails before any work with one line saying so, and nothing else changes.

`--viewer` alone spawns the Rerun viewer (on Linux it needs a display: without one it fails
before any work, saying how to save a recording instead); `--viewer FILE.rrd` saves a recording
(open it later with `rerun FILE.rrd`, or `rerun --web-viewer FILE.rrd` on a machine without a
display). The recording is written under a hidden temporary name (`.FILE.rrd.partial-<pid>`) and
renamed once the run is complete, so a killed run never leaves a broken recording under the
final name; the next run that records next to it removes such leftovers. Entities, on the
timeline `scan` (scan index) and `time` (scan timestamp):

    radar/scan              the scan as a Cartesian image in the vehicle frame (+x forward up,
                            +y left to the left), 512 x 512, JPEG
    world/odometry          odometry trajectory so far (LineStrips2D, metres; each pose revised
                            once the next scan has registered, as the pose graph takes it)
    world/gt                ground truth so far, moved so its first pose is the odometry's first
    world/slam              the optimised trajectory, re-logged whenever loops are accepted
    world/pose              the current odometry pose (Points2D)
    world/keyframes         odometry keyframes (Points2D)
    world/loops/accepted    accepted loop closures as segments between the two scans' poses
    world/loops/rejected    rejected proposals, likewise

After the run the final odometry, SLAM and GT trajectories and loops are logged once more at the
last scan, so the end of each entity's timeline is the final result.
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import RadarSlamError
from radar_slam.results import PARTIAL_SUFFIX, remove_stale_partials
from raplace import CartesianGrid, CartesianWarper, compose, inverse

if TYPE_CHECKING:
    from odometry import OdometryResult
    from radar_slam.datasets.frame import RadarFrame
    from radar_slam.loops import LoopDecision
    from radar_slam.pipeline import Pipeline, Results

logger = logging.getLogger(__name__)

INSTALL_HINT = "--viewer needs rerun-sdk, which is not installed: pip install 'radar-slam[viewer]'"
NO_DISPLAY_HINT = (
    "--viewer: no display (DISPLAY and WAYLAND_DISPLAY are unset), so the Rerun viewer cannot "
    "open; save a recording instead with --viewer out.rrd and open it where there is a display "
    "(rerun out.rrd) or in a browser (rerun --web-viewer out.rrd)"
)
DISPLAY_VARIABLES = ("DISPLAY", "WAYLAND_DISPLAY")
SPAWN = "spawn"
"""`--viewer` without a file: spawn the Rerun viewer."""
RECORDING_SUFFIX = ".rrd"
APPLICATION_ID = "radar-slam"
IMAGE_HALF_SIZE_PX = 256
"""The Cartesian scan image is 2 x this many pixels wide, covering the scan's full range."""
JPEG_QUALITY = 90
"""Scan images are stored as JPEG (about 50 kB instead of 260 kB raw per scan)."""
ACCEPTED_COLOUR = (40, 200, 40)
REJECTED_COLOUR = (220, 60, 60)
COLOURS = {"odometry": (60, 120, 230), "slam": (240, 150, 30), "gt": (120, 120, 120)}


def import_rerun() -> Any:
    """The `rerun` module, or a RadarSlamError with the one-line install hint."""
    try:
        import rerun
    except ImportError as exc:
        raise RadarSlamError(INSTALL_HINT) from exc
    return rerun


def check_viewer_target(target: str) -> None:
    """Fail before any work when `--viewer TARGET` could not work.

    Spawning needs a display on Linux; a recording needs an existing, writable folder and a file
    name that is free (recordings are never overwritten).

    Raises:
        RadarSlamError: one line naming the problem (and the file).
    """
    if target == SPAWN:
        headless = not any(os.environ.get(name) for name in DISPLAY_VARIABLES)
        if sys.platform.startswith("linux") and headless:
            raise RadarSlamError(NO_DISPLAY_HINT)
        return
    path = Path(target)
    folder = path.parent
    if path.exists() or path.is_symlink():
        raise RadarSlamError(f"{path}: recording exists already; choose another --viewer file")
    if not folder.exists():
        raise RadarSlamError(f"{path}: folder {folder} does not exist (--viewer)")
    if not folder.is_dir():
        raise RadarSlamError(f"{path}: {folder} is not a folder (--viewer)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise RadarSlamError(f"{path}: folder {folder} is not writable (--viewer)")


def viewer_argv(argv: list[str]) -> list[str]:
    """Command-line arguments with a bare `--viewer` written as `--viewer=spawn`.

    `--viewer` takes a value only when the next argument ends in `.rrd`, so `run --viewer SEQ`
    and `run SEQ --viewer` both mean "spawn the viewer".
    """
    result: list[str] = []
    for position, argument in enumerate(argv):
        following = argv[position + 1] if position + 1 < len(argv) else ""
        if argument == "--viewer" and not following.endswith(RECORDING_SUFFIX):
            result.append(f"--viewer={SPAWN}")
        else:
            result.append(argument)
    return result


def to_image(cartesian: NDArray[np.float32]) -> NDArray[np.uint8]:
    """A float Cartesian scan as uint8 for display."""
    return np.clip(cartesian, 0, 255).astype(np.uint8)


class RerunViewer:
    """A `PipelineObserver` logging the run to a Rerun recording stream.

    Args:
        target: `SPAWN` to spawn a viewer, or a `.rrd` file to save the recording to (it must
            not exist: recordings are never overwritten).
        name: recording name, e.g. "synthetic/tiny_loop".

    A recording is written to a hidden temporary sibling and renamed to `target` by `on_finish`;
    `abandon` removes it when the run does not complete.

    Raises:
        RadarSlamError: rerun-sdk is not installed, no display to spawn on, or the recording
            file exists or its folder is unusable.
    """

    def __init__(self, target: str, name: str) -> None:
        self.rr = import_rerun()
        check_viewer_target(target)
        self.target = target
        self.stream = self.rr.RecordingStream(APPLICATION_ID)
        self.stream.send_recording_name(name)
        self.staging: Path | None = None
        if target == SPAWN:
            self.stream.spawn()
        else:
            final = Path(target)
            remove_stale_partials(final.parent, final.name)  # a killed run's recording
            self.staging = final.parent / f".{final.name}{PARTIAL_SUFFIX}{os.getpid()}"
            self.stream.save(str(self.staging))
        self._warper: CartesianWarper | None = None
        self._odometry: list[NDArray[np.float64]] = []
        self._keyframes: list[NDArray[np.float64]] = []
        self._tally: tuple[int, int] = (0, 0)
        self._gt_anchor: NDArray[np.float64] | None = None

    # -- per scan -----------------------------------------------------------------------------
    def on_scan(self, pipeline: Pipeline, frame: RadarFrame, result: OdometryResult) -> None:
        self._set_time(result.index, frame.timestamp_ns)
        self._log_image(frame)
        if self._odometry:  # the previous scan's pose is revised now (as the graph takes it)
            self._odometry[-1] = pipeline.odometry.result(result.index - 1).pose
        self._odometry.append(np.asarray(result.pose, dtype=np.float64))
        if result.is_keyframe:
            self._keyframes.append(self._odometry[-1])
            self.stream.log("world/keyframes", self._points(np.array(self._keyframes), 0.6))
        odometry = np.array(self._odometry)
        self.stream.log("world/odometry", self._strip(odometry, "odometry"))
        self.stream.log("world/pose", self._points(odometry[-1:], 1.5))
        gt = self._gt(pipeline, result.index)
        if gt is not None:
            self.stream.log("world/gt", self._strip(gt, "gt"))
        tally = pipeline.loops.tally()  # as the graph has seen it
        if tally != self._tally:
            self._tally = tally
            slam = pipeline.graph.estimates()
            self.stream.log("world/slam", self._strip(slam, "slam"))
            self._log_loops(pipeline.loops.decisions, slam)

    def on_finish(self, results: Results) -> None:
        last = results.odometry
        self._set_time(len(last) - 1, int(last.timestamps_ns[-1]))
        self.stream.log("world/odometry", self._strip(last.poses, "odometry"))
        self.stream.log("world/slam", self._strip(results.slam.poses, "slam"))
        if results.ground_truth_poses is not None:
            gt = self._anchor_gt(results.ground_truth_poses)
            self.stream.log("world/gt", self._strip(gt, "gt"))
        self._log_loops(results.loops, results.slam.poses)
        if self.staging is None:
            try:
                self.stream.flush()
            except RuntimeError as exc:  # the spawned viewer is gone; the results still count
                logger.warning("the Rerun viewer did not take the run (%s)", exc)
            return
        self.stream.flush()
        if self.staging is not None:
            self.stream.disconnect()
            os.link(self.staging, self.target)  # fails rather than replace a file made meanwhile
            self.staging.unlink()
            self.staging = None
            logger.info("viewer recording written to %s", self.target)

    def abandon(self) -> None:
        """The run did not complete: remove the temporary recording (nothing else was made)."""
        if self.staging is not None:
            try:
                self.stream.disconnect()
            finally:
                self.staging.unlink(missing_ok=True)
                self.staging = None

    # -- helpers ------------------------------------------------------------------------------
    def _set_time(self, index: int, timestamp_ns: int) -> None:
        self.stream.set_time("scan", sequence=int(index))
        self.stream.set_time("time", timestamp=np.datetime64(int(timestamp_ns), "ns"))

    def _log_image(self, frame: RadarFrame) -> None:
        if self._warper is None:
            grid = CartesianGrid(frame.max_range_m / IMAGE_HALF_SIZE_PX, 2 * IMAGE_HALF_SIZE_PX)
            self._warper = CartesianWarper(grid)
        cartesian = self._warper(frame.polar, frame.azimuths_rad, frame.range_resolution_m)
        image = self.rr.Image(to_image(cartesian)).compress(jpeg_quality=JPEG_QUALITY)
        self.stream.log("radar/scan", image)

    def _anchor_gt(self, gt: NDArray[np.float64]) -> NDArray[np.float64]:
        """GT moved so that its first finite pose coincides with the first odometry pose."""
        finite = np.flatnonzero(np.isfinite(gt).all(axis=1))
        if not finite.size or not self._odometry:
            return gt[finite]
        if self._gt_anchor is None:
            first = int(finite[0])
            self._gt_anchor = compose(self._odometry[first], inverse(gt[first]))
        return compose(self._gt_anchor, gt[finite])

    def _gt(self, pipeline: Pipeline, index: int) -> NDArray[np.float64] | None:
        gt = pipeline.sequence.ground_truth
        return None if gt is None else self._anchor_gt(gt[: index + 1])

    def _strip(self, poses: NDArray[np.float64], name: str) -> Any:
        return self.rr.LineStrips2D([np.asarray(poses)[:, :2]], colors=[COLOURS[name]])

    def _points(self, poses: NDArray[np.float64], radius: float) -> Any:
        return self.rr.Points2D(np.asarray(poses)[:, :2], radii=radius)

    def _log_loops(self, decisions: list[LoopDecision], poses: NDArray[np.float64]) -> None:
        for status, colour in (("accepted", ACCEPTED_COLOUR), ("rejected", REJECTED_COLOUR)):
            pairs = [
                (d.query_key, d.match_key)
                for d in decisions
                if d.status == status and max(d.query_key, d.match_key) < len(poses)
            ]
            segments = [poses[[i, j], :2] for i, j in pairs]
            lines = self.rr.LineStrips2D(segments, colors=[colour])
            self.stream.log(f"world/loops/{status}", lines)
