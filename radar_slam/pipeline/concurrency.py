"""Concurrency of a run: scans read ahead on a reader thread, loops closed on a worker thread.

Both keep the results independent of timing:

- `ScanReader` reads the next scans of a sequence on a thread (PNG decoding releases the GIL;
  the SLAM run also conditions each scan there for the odometry) into a bounded queue; `next()`
  hands them out in order and raises a reading error in the caller's thread at the scan where it
  happened.
- `LoopRunner` feeds (scan, odometry pose, key) to a loop detector and hands out the loops found
  for scan k when the caller reaches scan k + `lag` (waiting for the detector when it is late).
  `InlineLoopRunner` runs the detector in the caller's thread, `ThreadedLoopRunner` on a worker
  thread; with the same lag both add the same loops at the same scans, so the graph, and every
  result, is the same. The detector needs only odometry poses, never the graph. A scan may come
  with its conditioned form from the odometry (`odometry.Odometry.prepared`), which the runner
  hands to the detector with the scan: the detector describes and verifies the scan from it, so
  a scan is conditioned once. The map keyframes, which need only the odometry
  too, are made in the same thread right after the detector has seen the scan
  (`radar_slam.maps.keyframes`): the conditioned form is the one the odometry made, and the
  descriptor the one the detector made, when it made one.

A run reads each scan once, on the reader thread (or the caller's): the loop detector verifies
database scans from their records (`radar_slam.maps.keyframes`), never reading them again.
"""

from __future__ import annotations

import os
import queue
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

from odometry import OdometryResult, PreparedScan
from radar_slam.datasets.frame import RadarFrame
from radar_slam.loops import LoopConstraint, LoopDecision, LoopDetectorProtocol
from radar_slam.maps.keyframes import KeyframeStage, NullKeyframeRecorder
from radar_slam.pipeline.steps import StepTimer

T = TypeVar("T")
_STOP_POLL_S = 0.1
"""How often a blocked thread checks whether it was asked to stop [s]."""


@dataclass(frozen=True)
class _Outcome(Generic[T]):
    """A value computed on a thread, or the exception computing it raised."""

    value: T | None = None
    error: BaseException | None = None

    def get(self) -> T:
        if self.error is not None:
            raise self.error
        return self.value  # type: ignore[return-value]


def _put(q: queue.Queue[T], item: T, stop: threading.Event) -> bool:
    """Put `item` into a bounded queue unless asked to stop first; False when stopped."""
    while not stop.is_set():
        try:
            q.put(item, timeout=_STOP_POLL_S)
            return True
        except queue.Full:
            continue
    return False


class ScanReader(Generic[T]):
    """Scans 0..frames-1 (what `read` returns for each) read ahead on a thread, at most `depth`
    of them waiting.

    Use as a context manager (the thread stops on exit, also on an error or Ctrl-C); `depth` 0
    reads in the caller's thread instead.
    """

    def __init__(self, read: Callable[[int], T], frames: int, depth: int) -> None:
        self.read = read
        self.frames = frames
        self.depth = depth
        self._next = 0
        self._stop = threading.Event()
        self._queue: queue.Queue[_Outcome[T]] = queue.Queue(maxsize=max(depth, 1))
        self._thread: threading.Thread | None = None
        if depth > 0 and frames > 0:
            self._thread = threading.Thread(target=self._work, name="scan-reader", daemon=True)
            self._thread.start()

    def _work(self) -> None:
        for index in range(self.frames):
            try:
                outcome: _Outcome[T] = _Outcome(self.read(index))
            except BaseException as exc:  # handed to the caller at this scan
                outcome = _Outcome(error=exc)
            if not _put(self._queue, outcome, self._stop) or outcome.error is not None:
                return

    def next(self) -> T:
        """The next scan (in order); raises the reading error of that scan."""
        index = self._next
        if index >= self.frames:
            raise IndexError(f"all {self.frames} scans were read")
        self._next += 1
        if self._thread is None:
            return self.read(index)
        return self._queue.get().get()

    def close(self) -> None:
        """Stop the thread (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def __enter__(self) -> ScanReader[T]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class LoopStep:
    """What the loop detector produced for one scan.

    Attributes:
        key: the scan's key.
        loops: the loops accepted by that scan.
        tally: (accepted, rejected) decisions after it.
        decisions: every decision after it (the same list object while nothing changed).
    """

    key: int
    loops: list[LoopConstraint]
    tally: tuple[int, int]
    decisions: list[LoopDecision]


class InlineLoopRunner:
    """Loop detection in the caller's thread, its loops handed out `lag` scans later.

    Args:
        detector: the loop detector (keys = scan indices).
        lag: scans between a scan and the moment its loops are handed out (>= 0).
        timer: accumulates the detector's time as "loop detection", the keyframes' as
            "map keyframes".
        keyframes: fed every scan after the detector (default: keeps nothing).
    """

    def __init__(
        self,
        detector: LoopDetectorProtocol,
        lag: int,
        timer: StepTimer,
        keyframes: KeyframeStage | None = None,
    ) -> None:
        self.detector = detector
        self.lag = lag
        self.timer = timer
        self.keyframes: KeyframeStage = NullKeyframeRecorder() if keyframes is None else keyframes
        self._done: deque[LoopStep] = deque()
        self._last = LoopStep(-1, [], (0, 0), [])
        self._state: tuple[int, tuple[int, int]] = (0, (0, 0))
        self._decisions: list[LoopDecision] = []

    # -- what the caller sees: the state as of the last loops handed out ----------------------
    def tally(self) -> tuple[int, int]:
        """(accepted, rejected) decisions as of the loops handed out so far."""
        return self._last.tally

    @property
    def decisions(self) -> list[LoopDecision]:
        """The decisions as of the loops handed out so far."""
        return list(self._last.decisions)

    # -- the per-scan calls -------------------------------------------------------------------
    def submit(
        self,
        frame: RadarFrame,
        result: OdometryResult,
        key: int,
        prepared: PreparedScan | None = None,
    ) -> None:
        """Offer a scan with its odometry result (its pose T_world_scan) and its conditioned form
        (if given) to the detector, then to the map keyframes."""
        self._done.append(self._step(frame, result, key, prepared))

    def due(self, key: int) -> list[LoopConstraint]:
        """The loops of the scans up to `key - lag` not handed out yet (call once per scan)."""
        loops: list[LoopConstraint] = []
        while self._done and self._done[0].key <= key - self.lag:
            loops += self._take().loops
        return loops

    def finish(self) -> list[LoopConstraint]:
        """Every loop not handed out yet, then the detector's final resolution."""
        loops: list[LoopConstraint] = []
        while self._pending():
            loops += self._take().loops
        with self.timer("loop detection"):
            loops += self.detector.finish()
        self._last = LoopStep(self._last.key, [], self.detector.tally(), self.detector.decisions)
        return loops

    def close(self) -> None:
        """Stop any thread (nothing to do inline)."""

    # -- helpers ------------------------------------------------------------------------------
    def _pending(self) -> bool:
        return bool(self._done)

    def _take(self) -> LoopStep:
        self._last = self._done.popleft()
        return self._last

    def _step(
        self,
        frame: RadarFrame,
        result: OdometryResult,
        key: int,
        prepared: PreparedScan | None = None,
    ) -> LoopStep:
        polar = None if prepared is None else prepared.polar
        with self.timer("loop detection"):
            loops = self.detector.add(frame, np.array(result.pose, dtype=np.float64), key, polar)
        with self.timer("map keyframes"):
            self.keyframes.add(frame, polar, result)
        tally = self.detector.tally()
        # New decisions come with new proposals, status changes change the tally: copy the
        # decisions only then.
        state = (self.detector.proposed, tally)
        if state != self._state:
            self._state = state
            self._decisions = self.detector.decisions
        return LoopStep(key, loops, tally, self._decisions)


class ThreadedLoopRunner(InlineLoopRunner):
    """`InlineLoopRunner` with the detector on a worker thread: same loops at the same scans.

    An error of the detector is raised in the caller's thread when that scan's loops are due.
    """

    def __init__(
        self,
        detector: LoopDetectorProtocol,
        lag: int,
        timer: StepTimer,
        keyframes: KeyframeStage | None = None,
    ) -> None:
        super().__init__(detector, lag, timer, keyframes)
        self._inbox: queue.Queue[
            tuple[RadarFrame, OdometryResult, int, PreparedScan | None] | None
        ] = queue.Queue()
        self._outbox: queue.Queue[_Outcome[LoopStep]] = queue.Queue()
        self._submitted: deque[int] = deque()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = threading.Thread(
            target=self._work, name="loop-detector", daemon=True
        )
        self._thread.start()

    def _work(self) -> None:
        while not self._stop.is_set():
            try:
                item = self._inbox.get(timeout=_STOP_POLL_S)
            except queue.Empty:
                continue
            if item is None:
                return
            try:
                outcome: _Outcome[LoopStep] = _Outcome(self._step(*item))
            except BaseException as exc:  # handed to the caller when this scan is due
                outcome = _Outcome(error=exc)
            self._outbox.put(outcome)
            if outcome.error is not None:
                return

    def submit(
        self,
        frame: RadarFrame,
        result: OdometryResult,
        key: int,
        prepared: PreparedScan | None = None,
    ) -> None:
        self._submitted.append(key)
        self._inbox.put((frame, result, key, prepared))

    def due(self, key: int) -> list[LoopConstraint]:
        loops: list[LoopConstraint] = []
        while self._submitted and self._submitted[0] <= key - self.lag:
            loops += self._take().loops
        return loops

    def finish(self) -> list[LoopConstraint]:
        loops: list[LoopConstraint] = []
        while self._submitted:
            loops += self._take().loops
        self.close()
        return loops + super().finish()

    def close(self) -> None:
        self._stop.set()
        self._inbox.put(None)  # wakes the worker now, not at its next poll
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def _pending(self) -> bool:
        return False

    def _take(self) -> LoopStep:
        self._submitted.popleft()
        with self.timer("loop wait"):
            step = self._outbox.get().get()
        self._last = step
        return step


def usable_cpus() -> int:
    """How many CPUs this process may run on (its affinity, e.g. under `taskset`), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # no affinity on this platform
        return max(1, os.cpu_count() or 1)


def make_loop_runner(
    detector: LoopDetectorProtocol,
    lag: int,
    threaded: bool,
    timer: StepTimer,
    keyframes: KeyframeStage | None = None,
) -> InlineLoopRunner:
    """A `ThreadedLoopRunner` when `threaded`, else an `InlineLoopRunner`."""
    runner = ThreadedLoopRunner if threaded else InlineLoopRunner
    return runner(detector, lag, timer, keyframes)
