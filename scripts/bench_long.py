"""Long-drive benchmark: throughput, memory and place-query time over `synthetic/long_city`.

Runs `radar_slam.pipeline.Pipeline` over the long scenario (10,000 scans, about 24 km, several
revisits in both directions; generated on first use) and records, every `--every` scans: the
scans/s of that window (wall clock, the probes' own time taken out), the process's peak RSS
(`resource.getrusage`), the loop detector's database size and the time of one RaPlace query at
that size (median of a few, on the live database). Then a standalone query benchmark over
`--keyframes` (20,000) synthetic descriptors (`bench_raplace.database`), with the invariant
shortlist (new) and without it (old, every entry scored at low resolution), and a plot of
scans/s and memory against scans processed.

The run is one core, sequential (`bench_pipeline.with_workers(config, 1)`).

Bars (issue 15): scans/s of the last window within 20 % of the first; peak memory <= 2 GB; place
query over 20,000 keyframes <= 5 ms.

`--frames N` runs on the first N scans only (generated separately into
`<data root>/synthetic_prefix/long_city_<N>`), e.g. to check the script: `--frames 600 --every 100`.
Sequences are generated (first use) in a child process so that the simulator's memory is not
counted in the peak.

Usage: python scripts/bench_long.py [--frames N] [--every 1000] [--keyframes 20000]
                                    [--plot docs/long_drive.png] [--json OUT] [--data-root DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from bench_pipeline import with_workers
from bench_raplace import database, median_ms, pin_to_one_core
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from radar_slam.datasets import open_sequence, registry
from radar_slam.datasets.frame import RadarSequence
from radar_slam.loops import LoopDetector
from radar_slam.pipeline import Pipeline, Progress, load_config
from radar_slam.sim.family import is_complete
from radar_slam.sim.scenarios import SCENARIOS
from raplace.retrieval import PlaceRecognizer

SCENARIO = "long_city"
PREFIX_FOLDER = "synthetic_prefix"
THROUGHPUT_TOLERANCE = 0.20
MEMORY_BAR_MB = 2048.0
QUERY_BAR_MS = 5.0
PROBE_QUERIES = 5
QUERY_REPEATS = 50
KIB_PER_MIB = 1024.0


@dataclass
class Window:
    """Figures at the end of a window of scans."""

    scans: int
    scans_per_s: float
    rss_mb: float
    peak_rss_mb: float
    database: int
    query_ms: float | None
    steps_s: dict[str, float]
    """Seconds each pipeline step took within the window (`Pipeline.timer`)."""


def long_sequence(frames: int | None, data_root: Path | None) -> RadarSequence:
    """The whole scenario (synthetic/long_city), or its first `frames` scans in a folder of
    their own. Generation runs in a child process, so that its memory is not counted here."""
    root = registry.data_root(data_root)
    full = SCENARIOS[SCENARIO].max_frames
    if frames is None or (full is not None and frames >= full):
        folder = root / "synthetic" / SCENARIO
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


def probe_query_ms(detector: object) -> float | None:
    """Median time of a query on the detector's live database [ms] (None while it is empty)."""
    if not isinstance(detector, LoopDetector) or len(detector.recognizer) == 0:
        return None
    recognizer = detector.recognizer
    if not isinstance(recognizer, PlaceRecognizer) or recognizer.descriptor_shape is None:
        return None
    rng = np.random.default_rng(len(recognizer))
    query = rng.standard_normal(recognizer.descriptor_shape).astype(np.float32)
    return median_ms(lambda: recognizer.query(query, k=5), PROBE_QUERIES)


class Recorder:
    """A `Pipeline` progress callback that records a `Window` every `every` scans."""

    def __init__(self, every: int) -> None:
        self.every = every
        self.windows: list[Window] = []
        self.pipeline: Pipeline | None = None
        self._last_scans = 0
        self._last_time = time.perf_counter()
        self._probe_s = 0.0
        self._last_steps: dict[str, float] = {}

    def __call__(self, progress: Progress) -> None:
        if progress.done % self.every and progress.done != progress.total:
            return
        now = time.perf_counter()
        elapsed = now - self._last_time - self._probe_s
        detector = None if self.pipeline is None else self.pipeline.loop_detector
        query_ms = probe_query_ms(detector)
        size = len(detector) if isinstance(detector, LoopDetector) else 0
        scans = progress.done - self._last_scans
        steps = {} if self.pipeline is None else dict(self.pipeline.timer.seconds)
        window = Window(
            progress.done,
            scans / elapsed,
            current_rss_mb(),
            peak_rss_mb(),
            size,
            query_ms,
            {step: t - self._last_steps.get(step, 0.0) for step, t in steps.items()},
        )
        self._last_steps = steps
        self.windows.append(window)
        print(
            f"  {window.scans:6d} scans: {window.scans_per_s:6.1f} scans/s, RSS "
            f"{window.rss_mb:7.1f} MB (peak {window.peak_rss_mb:7.1f}), database {size:5d}, query "
            f"{'n/a' if query_ms is None else f'{query_ms:.2f} ms'}; "
            + ", ".join(f"{step} {t:.1f} s" for step, t in window.steps_s.items()),
            flush=True,
        )
        self._last_scans = progress.done
        self._probe_s = time.perf_counter() - now
        self._last_time = now


def standalone_query_ms(keyframes: int) -> dict[str, float]:
    """Median RaPlace query time over `keyframes` synthetic descriptors [ms] (default config):
    "new" (the invariant shortlist) and "old" (every entry scored at low resolution)."""
    cfg = load_config().loop_closure.raplace
    rng = np.random.default_rng(0)
    first = rng.standard_normal((cfg.descriptor.n_theta, cfg.descriptor.n_freq)).astype(np.float32)
    entries = database(first, keyframes, seed=1)
    query = entries[keyframes // 2]
    times = {}
    for label, retrieval in (
        ("new", cfg.retrieval),
        ("old", replace(cfg.retrieval, coarse_shortlist=0)),
    ):
        recognizer = PlaceRecognizer(retrieval)
        recognizer.add_batch(entries, np.arange(keyframes))
        times[label] = median_ms(lambda r=recognizer: r.query(query, k=5), QUERY_REPEATS)
    return times


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
    bottom.axhline(MEMORY_BAR_MB, color="grey", linestyle="--", label="2 GB bar")
    bottom.set_ylabel("RSS [MB]")
    bottom.set_xlabel("scans processed")
    bottom.set_ylim(bottom=0)
    bottom.legend(loc="lower right")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path)


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=None, help="first N scans only")
    parser.add_argument("--every", type=int, default=1000, help="scans per window")
    parser.add_argument("--keyframes", type=int, default=20_000)
    parser.add_argument("--plot", type=Path, default=Path("docs/long_drive.png"))
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--data-root", type=Path, default=None)
    parser.add_argument("--config", type=Path, default=None, help="YAML overrides")
    args = parser.parse_args()
    core = pin_to_one_core()
    sequence = long_sequence(args.frames, args.data_root)
    # One core, sequential: the probes query the database the loop detector fills, which a loop
    # thread would be changing under them.
    config = with_workers(load_config(sequence.family, args.config), 1)
    recorder = Recorder(args.every)
    pipeline = Pipeline(sequence, config, max_frames=args.frames, progress=recorder)
    recorder.pipeline = pipeline
    print(f"{sequence.family}/{sequence.name}: {pipeline.frames} scans on core {core}")
    results = pipeline.run()
    m = results.metrics
    print(
        f"done: {m.frames} scans in {m.seconds:.1f} s ({m.frames_per_second:.1f} scans/s), "
        f"loops {m.loops_accepted} accepted ({m.loops_accepted_true} true), "
        f"ATE odometry {m.ate_odometry_m} m, SLAM {m.ate_slam_m} m"
    )
    query_ms = standalone_query_ms(args.keyframes)
    windows = recorder.windows
    first, last = windows[0], windows[-1]
    ratio = last.scans_per_s / first.scans_per_s
    peak = max(w.peak_rss_mb for w in windows)
    print(
        f"throughput  first window {first.scans_per_s:.1f}, last {last.scans_per_s:.1f} scans/s "
        f"({100 * (ratio - 1):+.1f} %)   bar within 20 %: "
        f"{verdict(abs(ratio - 1) <= THROUGHPUT_TOLERANCE)}"
    )
    print(f"memory      peak RSS {peak:.0f} MB   bar <= 2 GB: {verdict(peak <= MEMORY_BAR_MB)}")
    print(
        f"place query over {args.keyframes} keyframes: {query_ms['new']:.2f} ms (old coarse "
        f"stage {query_ms['old']:.2f} ms)   bar <= 5 ms: "
        f"{verdict(query_ms['new'] <= QUERY_BAR_MS)}"
    )
    plot(args.plot, windows, f"{sequence.family}/{sequence.name}: {m.frames} scans")
    print(f"plot in {args.plot}")
    if args.json is not None:
        report = {
            "sequence": f"{sequence.family}/{sequence.name}",
            "metrics": m.to_dict(),
            "windows": [asdict(w) for w in windows],
            "standalone_query_ms": query_ms,
            "keyframes": args.keyframes,
        }
        args.json.write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
