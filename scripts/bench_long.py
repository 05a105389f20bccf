"""Long-drive benchmark: throughput, memory and place-query time over `synthetic/long_city`.

Runs `radar_slam.pipeline.Pipeline` over the long scenario (10,000 scans, about 24 km, several
revisits in both directions; generated on first use) and records, every `--every` scans: the
scans/s of that window (wall clock, the probes' own time taken out) and per CPU second of this
process (what a shared, busy machine distorts least), each pipeline step's seconds, the loops
verified and accepted and the queries the loop throttle skipped, the process's peak RSS
(`resource.getrusage`), the loop detector's database size and the time of one RaPlace query at
that size (median of a few, on the live database, with the descriptor of the window's last scan
at its time: a real query). A standalone query benchmark over `--keyframes` (20,000)
entries made of real descriptors (1,000 scans spread over the run, each repeated, turned and
perturbed to reach the count), queried with the run's last scan (a revisit), with the invariant
shortlist (new) and without it (old, every entry scored at low resolution), timed before the run
(in a fresh child process) and after it (in this process, as the run leaves it). Then the
accepted loops that are false on the ground truth, listed; and a plot of scans/s and memory
against scans processed.

The run is one core, sequential (`bench_pipeline.with_workers(config, 1)`). A shared VM's speed
drifts by tens of per cent within a run, so every window also times a fixed reference workload
(the odometry registering one pair of the drive's scans, `ReferenceWork`, in CPU time), and the
throughput bar is printed three ways: on the wall clock, per CPU second of this process, and per
CPU second at the first windows' machine speed (each window's CPU time scaled by the reference
workload's CPU time then over its CPU time at that window: both in CPU time, so that other
processes' load, which stretches the wall clock but not this process's CPU time, is not counted
as the machine's speed). Each window also records the CPU time of every pipeline step and the
calls and CPU time of the loop detector's parts (`LoopMeter`).

Bars: scans/s of the last window within 20 % of the first; peak memory <= 1.5 GiB (the
memory budget, `radar_slam.pipeline.MEMORY_BUDGET_BYTES`); place query over 20,000 keyframes
after the run <= 5 ms in CPU time (which other processes' load does not stretch; the wall
clock beside it).

`--frames N` runs on the first N scans only (of the whole sequence when it is generated, else
generated separately into `<data root>/synthetic_prefix/long_city_<N>`), e.g. to check the script:
`--frames 600 --every 100`.
Sequences are generated (first use) in a child process so that the simulator's memory is not
counted in the peak.

Usage: python scripts/bench_long.py [--frames N] [--every 1000] [--keyframes 20000]
                                    [--plot docs/long_drive.png] [--json OUT] [--g2o OUT]
                                    [--data-root DIR] [--config FILE] [--write-doc]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
from bench_pipeline import with_workers
from bench_raplace import DATABASE_NOISE, median_ms, pin_to_one_core, timings_ms
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from odometry import OdometryConfig, prepare, preprocess_polar, register
from radar_slam.datasets import open_sequence, registry
from radar_slam.datasets.frame import RadarSequence
from radar_slam.g2o import write_pose_graph
from radar_slam.loops import LoopClosureConfig, LoopDetector, verification
from radar_slam.loops.config import LOOP_RAPLACE
from radar_slam.loops.records import raplace_input
from radar_slam.loops.verification import GeometricVerifier
from radar_slam.pipeline import MEMORY_BUDGET_BYTES, Pipeline, Progress, Results, load_config
from radar_slam.sim.family import is_complete
from radar_slam.sim.scenarios import SCENARIOS
from raplace import NS_PER_S, PlaceRecognizer, RetrievalConfig, between
from raplace.descriptor import DescriptorExtractor, z_normalise

SCENARIO = "long_city"
PREFIX_FOLDER = "synthetic_prefix"
THROUGHPUT_TOLERANCE = 0.20
BAR_SPAN_SCANS = 1000
"""The throughput bar compares the first and the last this many scans."""
MEMORY_BAR_MB = MEMORY_BUDGET_BYTES / 2**20
"""The memory budget of a run (`radar_slam.pipeline.MEMORY_BUDGET_BYTES`) [MiB]."""
QUERY_BAR_MS = 5.0
PROBE_QUERIES = 5
QUERY_REPEATS = 50
REFERENCE_SCANS = (100, 101)
"""The scan pair of the reference workload (`ReferenceWork`)."""
REFERENCE_REPEATS = 5
PROBE_SOURCE_SCANS = 1000
"""Scans of the sequence whose descriptors make the standalone query database."""
KIB_PER_MIB = 1024.0


@dataclass
class Window:
    """Figures at the end of a window of scans."""

    scans: int
    """Scans processed by the end of the window."""
    window_scans: int
    """Scans within the window."""
    seconds: float
    """Wall-clock seconds of the window (the probes' own time taken out)."""
    scans_per_s: float
    scans_per_cpu_s: float
    """Scans per CPU second of this process (the probes' own time taken out)."""
    rss_mb: float
    peak_rss_mb: float
    database: int
    query_ms: float | None
    steps_s: dict[str, float]
    """Seconds each pipeline step took within the window (`Pipeline.timer`)."""
    verified: int
    """Loop candidates verified within the window."""
    accepted: int
    """... of which accepted (by the end of the window)."""
    skipped: int
    """Queries the loop throttle left unverified within the window."""
    reference_ms: float = float("nan")
    """CPU time of the fixed reference workload at the window's end (`ReferenceWork`) [ms]."""
    steps_cpu_s: dict[str, float] = field(default_factory=dict)
    """CPU seconds each pipeline step's thread spent within the window (`StepTimer`)."""
    loop_work: dict[str, tuple[int, float]] = field(default_factory=dict)
    """The loop detector's work within the window: calls and CPU seconds of each of its parts
    (`LoopMeter`)."""


def long_sequence(frames: int | None, data_root: Path | None) -> RadarSequence:
    """The whole scenario (synthetic/long_city), or its first `frames` scans in a folder of
    their own. Generation runs in a child process, so that its memory is not counted here."""
    root = registry.data_root(data_root)
    full = SCENARIOS[SCENARIO].max_frames
    whole = root / "synthetic" / SCENARIO
    if frames is None or (full is not None and frames >= full) or is_complete(whole, SCENARIO):
        # The whole sequence once generated (the run stops after `frames` scans).
        folder = whole
        command = ["info", f"synthetic/{SCENARIO}", "--data-root", str(root)]
    else:
        folder = root / PREFIX_FOLDER / f"{SCENARIO}_{frames}"
        command = ["simulate", SCENARIO, "--out", str(folder), "--frames", str(frames)]
    if not is_complete(folder, SCENARIO):
        if folder.exists() and any(folder.iterdir()):
            raise SystemExit(f"{folder}: incomplete sequence; remove it to regenerate")
        print(f"generating {SCENARIO} into {folder} (a child process)", flush=True)
        subprocess.run([sys.executable, "-m", "radar_slam.cli", *command], check=True)
    return open_sequence(folder)


def current_rss_mb() -> float:
    """Resident memory of this process now [MiB] (Linux /proc)."""
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / (KIB_PER_MIB * KIB_PER_MIB)


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far [MiB] (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KIB_PER_MIB


def probe_query_ms(detector: object, sequence: RadarSequence, index: int) -> float | None:
    """Median time of a query on the detector's live database [ms] (None while it is empty):
    the descriptor of scan `index` at its time, asking for the detector's own candidate count."""
    if not isinstance(detector, LoopDetector) or len(detector.recognizer) == 0:
        return None
    recognizer = detector.recognizer
    if not isinstance(recognizer, PlaceRecognizer):
        return None
    scan = sequence[index]
    polar = preprocess_polar(scan, detector.odometry.preprocess)
    query = detector.describe(*raplace_input(polar))
    time_s = int(scan.timestamp_ns) / NS_PER_S
    k = detector.config.candidates
    return median_ms(lambda: recognizer.query(query, k, time_s), PROBE_QUERIES)


def span_scans_per_s(windows: list[Window]) -> float:
    """Wall-clock scans/s over consecutive windows (total scans over total time)."""
    return sum(w.window_scans for w in windows) / sum(w.seconds for w in windows)


def span_cpu_scans_per_s(windows: list[Window], reference_ms: float | None = None) -> float:
    """Scans per CPU second of this process over consecutive windows; with `reference_ms`, at
    the machine speed of that reference time: each window's CPU time scaled by `reference_ms`
    over its own reference time (both CPU times; a busy machine slows CPU work too)."""
    seconds = [w.window_scans / w.scans_per_cpu_s for w in windows]
    if reference_ms is not None:
        seconds = [t * reference_ms / w.reference_ms for t, w in zip(seconds, windows, strict=True)]
    return sum(w.window_scans for w in windows) / sum(seconds)


class ReferenceWork:
    """A fixed workload timed at every window's end: the odometry registering one pair of the
    drive's scans, prepared afresh (what the pipeline spends most of its time on). Its time
    tracks the machine's speed, which on a shared VM drifts by tens of per cent within a run."""

    def __init__(self, sequence: RadarSequence, config: OdometryConfig) -> None:
        self._scans = (sequence[REFERENCE_SCANS[0]], sequence[REFERENCE_SCANS[1]])
        self._config = config

    def ms(self) -> float:
        """Median CPU time of the workload [ms]."""
        times = []
        for _ in range(REFERENCE_REPEATS):
            start = time.process_time()
            first, second = (prepare(scan, self._config) for scan in self._scans)
            register(first, second, self._config)
            times.append(1e3 * (time.process_time() - start))
        return float(np.median(times))


class LoopMeter:
    """Calls and CPU seconds (the calling thread's) of the loop detector's parts: descriptors,
    place queries, verifications, and within verifications the sinogram pose images, their
    spectra and estimates, the refinement's conditioning and registration, and the scans read
    again. Installed on a live detector by wrapping its callables (`install`)."""

    def __init__(self) -> None:
        self.calls: dict[str, int] = {}
        self.cpu_s: dict[str, float] = {}

    def wrap(self, name: str, function: Callable[..., object]) -> Callable[..., object]:
        """`function`, counted under `name`."""
        self.calls.setdefault(name, 0)
        self.cpu_s.setdefault(name, 0.0)

        def counted(*args: object, **kwargs: object) -> object:
            start = time.thread_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.calls[name] += 1
                self.cpu_s[name] += time.thread_time() - start

        return counted

    def install(self, detector: object) -> None:
        """Count `detector`'s parts (a `LoopDetector` with a `GeometricVerifier`; else none)."""
        if not isinstance(detector, LoopDetector):
            return
        detector.describe = self.wrap("descriptor", detector.describe)  # type: ignore[method-assign]
        recognizer = detector.recognizer
        recognizer.query = self.wrap("query", recognizer.query)  # type: ignore[method-assign]
        if detector.scan_loader is not None:
            detector.scan_loader = self.wrap("record read", detector.scan_loader)
        verifier = detector.verifier
        if isinstance(verifier, GeometricVerifier):
            pose = verifier.pose_estimator
            for part in ("image", "spectrum", "estimate_spectra"):
                setattr(pose, part, self.wrap(f"sinogram {part}", getattr(pose, part)))
            verification.preprocess_polar = self.wrap(
                "record conditioning", verification.preprocess_polar
            )
            verification.register = self.wrap("refinement register", verification.register)
        counted = _CountedVerifier(verifier, self.wrap("verification", verifier))
        refine = getattr(verifier, "refine", None)
        if refine is not None:  # the checks from a prediction (`radar_slam.loops.tracking`)
            setattr(counted, "refine", self.wrap("predicted check", refine))  # noqa: B010
        detector.verifier = counted

    def snapshot(self) -> dict[str, tuple[int, float]]:
        return {name: (self.calls[name], self.cpu_s[name]) for name in self.calls}


class _CountedVerifier:
    """A verifier whose calls are counted; everything else is the verifier's own."""

    def __init__(self, verifier: object, counted: Callable[..., object]) -> None:
        self._verifier = verifier
        self._counted = counted

    def __call__(self, *args: object) -> object:
        return self._counted(*args)

    def __getattr__(self, name: str) -> object:
        return getattr(self._verifier, name)


class Recorder:
    """A `Pipeline` progress callback that records a `Window` every `every` scans."""

    def __init__(self, every: int) -> None:
        self.every = every
        self.windows: list[Window] = []
        self.pipeline: Pipeline | None = None
        self._last_scans = 0
        self._last_time = time.perf_counter()
        self._last_cpu = time.process_time()
        self._probe_s = 0.0
        self._probe_cpu_s = 0.0
        self._last_steps: dict[str, float] = {}
        self._last_steps_cpu: dict[str, float] = {}
        self.meter = LoopMeter()
        self._last_work: dict[str, tuple[int, float]] = {}
        self._last_loops = (0, 0, 0)  # verified, accepted, skipped before the window
        self.reference: ReferenceWork | None = None

    def start(self) -> None:
        """Start the first window now (what ran before, e.g. the probes, is not counted)."""
        self._last_time = time.perf_counter()
        self._last_cpu = time.process_time()

    def __call__(self, progress: Progress) -> None:
        if progress.step:  # after the last scan: no new window
            return
        if progress.done % self.every and progress.done != progress.total:
            return
        now, now_cpu = time.perf_counter(), time.process_time()
        elapsed = now - self._last_time - self._probe_s
        elapsed_cpu = now_cpu - self._last_cpu - self._probe_cpu_s
        work = self.meter.snapshot()  # before the probes, which query the database too
        pipeline = self.pipeline
        detector = None if pipeline is None else pipeline.loop_detector
        query_ms = None
        if pipeline is not None:
            query_ms = probe_query_ms(detector, pipeline.sequence, progress.done - 1)
        size = len(detector) if isinstance(detector, LoopDetector) else 0
        loops = loop_counts(detector)
        scans = progress.done - self._last_scans
        steps = {} if pipeline is None else dict(pipeline.timer.seconds)
        window = Window(
            progress.done,
            scans,
            elapsed,
            scans / elapsed,
            scans / elapsed_cpu,
            current_rss_mb(),
            peak_rss_mb(),
            size,
            query_ms,
            {step: t - self._last_steps.get(step, 0.0) for step, t in steps.items()},
            *(count - before for count, before in zip(loops, self._last_loops, strict=True)),
        )
        steps_cpu = {} if pipeline is None else dict(pipeline.timer.cpu_seconds)
        window.steps_cpu_s = {
            step: t - self._last_steps_cpu.get(step, 0.0) for step, t in steps_cpu.items()
        }
        window.loop_work = {
            part: (
                calls - self._last_work.get(part, (0, 0.0))[0],
                cpu - self._last_work.get(part, (0, 0.0))[1],
            )
            for part, (calls, cpu) in work.items()
        }
        if self.reference is not None:
            window.reference_ms = self.reference.ms()
        self._last_steps = steps
        self._last_steps_cpu = steps_cpu
        self._last_work = work
        self._last_loops = loops
        self.windows.append(window)
        print(
            f"  {window.scans:6d} scans: {window.scans_per_s:6.1f} scans/s "
            f"({window.scans_per_cpu_s:5.1f} per CPU s), RSS {window.rss_mb:7.1f} MB (peak "
            f"{window.peak_rss_mb:7.1f}), database {size:5d}, query "
            f"{'n/a' if query_ms is None else f'{query_ms:.2f} ms'}; loops verified "
            f"{window.verified}, accepted {window.accepted}, skipped {window.skipped}; "
            + ", ".join(f"{step} {t:.1f} s" for step, t in window.steps_s.items())
            + f"; reference {window.reference_ms:.1f} ms",
            flush=True,
        )
        print(
            "         CPU s: "
            + ", ".join(f"{step} {t:.2f}" for step, t in window.steps_cpu_s.items())
            + "; loop parts (calls, CPU s): "
            + ", ".join(f"{part} {n} {t:.2f}" for part, (n, t) in window.loop_work.items()),
            flush=True,
        )
        self._last_scans = progress.done
        self._probe_s = time.perf_counter() - now
        self._probe_cpu_s = time.process_time() - now_cpu
        self._last_time = now
        self._last_cpu = now_cpu


def loop_counts(detector: object) -> tuple[int, int, int]:
    """(verified, accepted, skipped queries) of the detector so far (zeros for another one)."""
    if not isinstance(detector, LoopDetector):
        return 0, 0, 0
    accepted, rejected = detector.tally()
    return accepted + rejected, accepted, getattr(detector, "skipped_queries", 0)


def grown_database(descriptors: np.ndarray, n: int, seed: int) -> np.ndarray:
    """n descriptors from (m, n_theta, n_freq) real ones: each repeated in turn, turned by a
    random number of rows and perturbed (`bench_raplace.DATABASE_NOISE`); the first m as they
    are."""
    rng = np.random.default_rng(seed)
    m, n_theta = descriptors.shape[:2]
    source = np.arange(n) % m
    shifts = np.where(np.arange(n) < m, 0, rng.integers(0, n_theta, n))
    rows = (np.arange(n_theta)[None, :] - shifts[:, None]) % n_theta
    grown = descriptors[source[:, None], rows]
    grown[m:] += DATABASE_NOISE * rng.standard_normal(grown[m:].shape, dtype=np.float32)
    return z_normalise(grown)


@dataclass
class QueryProbe:
    """A standalone place-query benchmark: `keyframes` entries grown from real descriptors of
    the sequence, and a real query."""

    real: np.ndarray
    """(PROBE_SOURCE_SCANS, n_theta, n_freq) real descriptors (grown to `keyframes` entries
    only while timing, so that their memory is not held during the run)."""
    keyframes: int
    query: np.ndarray
    """(n_theta, n_freq) descriptor of the query scan."""
    k: int
    """Candidates asked for (the loop detector's count)."""


def query_probe(
    sequence: RadarSequence, frames: int, config: LoopClosureConfig, keyframes: int
) -> QueryProbe:
    """Descriptors of `PROBE_SOURCE_SCANS` scans spread over the first `frames`, grown to
    `keyframes` entries (`grown_database`); the query is the last scan, which revisits a place
    driven before."""
    describe = DescriptorExtractor(LOOP_RAPLACE.descriptor)
    preprocess = load_config(sequence.family).odometry.preprocess

    def descriptor(index: int) -> np.ndarray:
        return describe(*raplace_input(preprocess_polar(sequence[index], preprocess)))

    sources = np.linspace(0, frames - 2, min(PROBE_SOURCE_SCANS, frames - 1)).astype(int)
    real = np.stack([descriptor(int(n)) for n in sources])
    return QueryProbe(real, keyframes, descriptor(frames - 1), config.candidates)


def standalone_query_ms(probe: QueryProbe, retrieval: RetrievalConfig) -> dict[str, float]:
    """Median query time over the probe's database [ms]: "new" (the invariant shortlist) and
    "old" (every entry scored at low resolution) on the wall clock, "new_cpu" and "old_cpu" in
    this process's CPU time (which other processes' load does not stretch)."""
    keyframes = probe.keyframes
    entries = grown_database(probe.real, keyframes, seed=1)
    times = {}
    for label, settings in (("new", retrieval), ("old", replace(retrieval, coarse_shortlist=0))):
        recognizer = PlaceRecognizer(settings)
        recognizer.add_batch(entries, np.arange(keyframes))
        query = partial(recognizer.query, probe.query, probe.k)
        times[label] = median_ms(query, QUERY_REPEATS)
        cpu = timings_ms(query, QUERY_REPEATS, time.process_time)
        times[f"{label}_cpu"] = float(np.median(cpu))
    return times


def false_loops(results: Results) -> list[dict[str, float]]:
    """The accepted loops that are false on the ground truth: keys, RaPlace distance, the
    measured and true T_query_match, their gap [m, deg], the scans' ground-truth distance [m],
    and the status reason."""
    gt = results.ground_truth_poses
    rows: list[dict[str, float]] = []
    if gt is None:
        return rows
    for decision, true in zip(results.loops, results.true_loops, strict=True):
        if not decision.accepted or true is not False:
            continue
        q, m = decision.query_key, decision.match_key
        truth = between(gt[q], gt[m])
        error = between(truth, decision.measurement)
        rows.append(
            {
                "query": q,
                "match": m,
                "distance": decision.distance,
                "measured": [float(v) for v in decision.measurement],
                "true": [float(v) for v in truth],
                "error_m": float(np.hypot(error[0], error[1])),
                "error_deg": float(np.rad2deg(abs(error[2]))),
                "reason": decision.reason,
            }
        )
    return rows


def plot(path: Path, windows: list[Window], title: str) -> None:
    """scans/s and peak RSS against scans processed."""
    scans = [w.scans for w in windows]
    figure = Figure(figsize=(8.0, 5.5), dpi=120)
    FigureCanvasAgg(figure)
    top, bottom = figure.subplots(2, 1, sharex=True)
    top.plot(scans, [w.scans_per_s for w in windows], "o-", color="tab:blue")
    top.set_ylabel("scans/s (window)")
    top.set_ylim(bottom=0)
    top.set_title(title)
    bottom.plot(scans, [w.peak_rss_mb for w in windows], "o-", color="tab:red", label="peak")
    bottom.plot(scans, [w.rss_mb for w in windows], ".--", color="tab:orange", label="current")
    bottom.axhline(MEMORY_BAR_MB, color="grey", linestyle="--", label="1.5 GB bar")
    bottom.set_ylabel("RSS [MB]")
    bottom.set_xlabel("scans processed")
    bottom.set_ylim(bottom=0)
    bottom.legend(loc="lower right")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def _m(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


DOC_SECTION = "Long drive"
"""The section of docs/benchmarks.md this script writes with `--write-doc`."""


def parse_arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=None, help="first N scans only")
    parser.add_argument("--every", type=int, default=1000, help="scans per window")
    parser.add_argument("--keyframes", type=int, default=20_000)
    parser.add_argument("--plot", type=Path, default=Path("docs/long_drive.png"))
    parser.add_argument("--write-doc", action="store_true", help="write docs/benchmarks.md")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--g2o", type=Path, default=None, help="write the final graph (g2o)")
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument("--config", type=Path, default=None, help="YAML overrides")
    return parser.parse_args()


@dataclass
class Measured:
    """What one benchmark run measured.

    Attributes:
        label: `family/name` of the drive.
        results: the run's results.
        windows: the recorder's windows, in scan order.
        query_ms, fresh_query_ms: the standalone query times after and before the run [ms]
            ("new": with the invariant shortlist, "old": without; "_cpu": in CPU time).
    """

    label: str
    results: Results
    windows: list[Window]
    query_ms: dict[str, float]
    fresh_query_ms: dict[str, float]


def run_measured(args: argparse.Namespace) -> Measured:
    """The run over the long drive with its recorder, and the standalone queries around it."""
    core = pin_to_one_core()
    sequence = long_sequence(args.frames, args.data_root)
    # One core, sequential: the probes query the database the loop detector fills, which a loop
    # thread would be changing under them.
    config = with_workers(load_config(sequence.family, args.config), 1)
    recorder = Recorder(args.every)
    pipeline = Pipeline(sequence, config, max_frames=args.frames, progress=recorder)
    probe = query_probe(sequence, pipeline.frames, config.loop_closure, args.keyframes)
    retrieval = LOOP_RAPLACE.retrieval
    # Before the run, in a child process (fresh, and its memory not counted in the peak here).
    with multiprocessing.get_context("fork").Pool(1) as pool:
        fresh_query_ms = pool.apply(standalone_query_ms, (probe, retrieval))
    recorder.pipeline = pipeline
    recorder.meter.install(pipeline.loop_detector)
    recorder.reference = ReferenceWork(sequence, config.odometry)
    print(f"{sequence.family}/{sequence.name}: {pipeline.frames} scans on core {core}")
    recorder.start()
    results = pipeline.run()
    query_ms = standalone_query_ms(probe, retrieval)  # the same, after the run
    label = f"{sequence.family}/{sequence.name}"
    return Measured(label, results, recorder.windows, query_ms, fresh_query_ms)


@dataclass(frozen=True)
class Bars:
    """The figures the bars judge (first and last `BAR_SPAN_SCANS` scans).

    Attributes:
        first, last: scans/s on the wall clock.
        first_cpu, last_cpu: scans per CPU second.
        speed_ms: the reference workload's CPU time over the first span [ms].
        first_ref, last_ref: scans per CPU second at the first span's machine speed.
        peak_mb: the peak RSS [MiB].
    """

    first: float
    last: float
    first_cpu: float
    last_cpu: float
    speed_ms: float
    first_ref: float
    last_ref: float
    peak_mb: float

    @classmethod
    def of(cls, windows: list[Window], every: int) -> Bars:
        span = max(1, BAR_SPAN_SCANS // every)
        head, tail = windows[:span], windows[-span:]
        speed = float(np.median([w.reference_ms for w in head]))
        return cls(
            span_scans_per_s(head),
            span_scans_per_s(tail),
            span_cpu_scans_per_s(head),
            span_cpu_scans_per_s(tail),
            speed,
            span_cpu_scans_per_s(head, speed),
            span_cpu_scans_per_s(tail, speed),
            max(w.peak_rss_mb for w in windows),
        )


def print_run(results: Results, wrong: list[dict[str, float]]) -> None:
    """The run's summary line and its false loops."""
    m = results.metrics
    print(
        f"done: {m.frames} scans in {m.seconds:.1f} s ({m.frames_per_second:.1f} scans/s), "
        f"loops {m.loops_accepted} accepted ({m.loops_accepted_true} true), "
        f"ATE odometry {m.ate_odometry_m} m, SLAM {m.ate_slam_m} m"
    )
    for row in wrong:
        print(
            f"false loop {row['query']} -> {row['match']}: RaPlace distance "
            f"{row['distance']:.3f}, off by {row['error_m']:.2f} m / {row['error_deg']:.2f} deg; "
            f"{row['reason']}"
        )


def print_bars(bars: Bars, measured: Measured, keyframes: int) -> None:
    """Each bar's figures and verdict."""
    ratio = bars.last / bars.first
    print(
        f"throughput  first {BAR_SPAN_SCANS} scans {bars.first:.1f}, last {bars.last:.1f} scans/s "
        f"({100 * (ratio - 1):+.1f} %)   bar within 20 %: "
        f"{verdict(abs(ratio - 1) <= THROUGHPUT_TOLERANCE)}"
    )
    print(
        f"            per CPU second: first {bars.first_cpu:.1f}, last {bars.last_cpu:.1f} "
        f"({100 * (bars.last_cpu / bars.first_cpu - 1):+.1f} %)"
    )
    at_speed = bars.last_ref / bars.first_ref - 1
    print(
        f"            per CPU second at the first {BAR_SPAN_SCANS} scans' machine speed (reference "
        f"workload {bars.speed_ms:.1f} ms CPU, last {measured.windows[-1].reference_ms:.1f} ms): "
        f"first {bars.first_ref:.1f}, last {bars.last_ref:.1f} ({100 * at_speed:+.1f} %)   "
        f"bar within 20 %: {verdict(abs(at_speed) <= THROUGHPUT_TOLERANCE)}"
    )
    peak = bars.peak_mb
    print(f"memory      peak RSS {peak:.0f} MB   bar <= 1.5 GB: {verdict(peak <= MEMORY_BAR_MB)}")
    after, before = measured.query_ms, measured.fresh_query_ms
    cpu = after["new_cpu"]
    print(
        f"place query over {keyframes} keyframes: {after['new']:.2f} ms after the run, "
        f"{before['new']:.2f} ms before it (without the invariant shortlist "
        f"{after['old']:.2f} / {before['old']:.2f} ms); after the run in CPU time {cpu:.2f} ms "
        f"(before {before['new_cpu']:.2f})   bar <= 5 ms: {verdict(cpu <= QUERY_BAR_MS)}"
    )


def write_doc(bars: Bars, measured: Measured, keyframes: int) -> None:
    """The table of docs/benchmarks.md's `DOC_SECTION`."""
    from benchmark_doc import markdown_table, update_section

    m = measured.results.metrics
    after, before = measured.query_ms, measured.fresh_query_ms
    rows = [
        ["scans", f"{m.frames:,} in {m.seconds:.0f} s", ""],
        [
            f"scans/s, first -> last {BAR_SPAN_SCANS:,} scans",
            f"{bars.first:.1f} -> {bars.last:.1f} ({100 * (bars.last / bars.first - 1):+.1f} % "
            f"on the wall clock, {100 * (bars.last_ref / bars.first_ref - 1):+.1f} % at machine "
            "speed)",
            "within 20 %",
        ],
        ["peak memory (RSS)", f"{bars.peak_mb:,.0f} MB", "<= 1.5 GB"],
        [
            f"place query over {keyframes:,} keyframes, after / before the run (CPU time)",
            f"{after['new']:.2f} / {before['new']:.2f} ms ({after['new_cpu']:.2f} / "
            f"{before['new_cpu']:.2f})",
            "<= 5 ms",
        ],
        ["loops accepted / true", f"{m.loops_accepted} / {m.loops_accepted_true}", ""],
        ["ATE odometry -> SLAM", f"{_m(m.ate_odometry_m)} -> {_m(m.ate_slam_m)} m", ""],
    ]
    table = markdown_table(["what", "measured", "bar"], rows)
    update_section(DOC_SECTION, table, script="scripts/bench_long.py")


def main() -> None:
    args = parse_arguments()
    measured = run_measured(args)
    results = measured.results
    wrong = false_loops(results)
    print_run(results, wrong)
    if args.g2o is not None:
        write_pose_graph(args.g2o, results.graph)
    bars = Bars.of(measured.windows, args.every)
    print_bars(bars, measured, args.keyframes)
    if args.write_doc:
        write_doc(bars, measured, args.keyframes)
    m = results.metrics
    plot(args.plot, measured.windows, f"{measured.label}: {m.frames} scans")
    print(f"plot in {args.plot}")
    if args.json is not None:
        report = {
            "sequence": measured.label,
            "metrics": m.to_dict(),
            "windows": [asdict(w) for w in measured.windows],
            "standalone_query_ms": measured.query_ms,
            "standalone_query_ms_before_run": measured.fresh_query_ms,
            "keyframes": args.keyframes,
            "false_loops": wrong,
        }
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
