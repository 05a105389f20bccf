"""Batch runs on Dask: one task per (sequence, configuration), each a full `radar-slam run`.

`plan_jobs` opens each sequence once, in the submitting process, and `run_job` is what a worker
executes with it: the same library code as `radar-slam run` (`Pipeline.run`,
`outputs.write_results`) into the job's own result folder, written under a temporary name and
renamed when complete. It never raises: a failure becomes a `BatchRow` with a one-line error,
so one bad sequence does not stop the others.

`run_batch` submits the jobs to a local cluster (`LocalCluster`, N worker processes of one thread
each) or to an existing scheduler (`tcp://host:8786`), and collects the rows as tasks finish.
Workers of an existing cluster must see the data root and the output folder at the same paths
(a shared file system) and have radar-slam installed: a job carries its opened sequence (the
scans' paths and the ground truth, no scan), and the worker reads the scans it runs on.
"""

from __future__ import annotations

import dataclasses
import logging
import shutil
import socket
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from radar_slam.batch.grid import GridPoint
from radar_slam.datasets.frame import RadarSequence
from radar_slam.errors import RadarSlamError
from radar_slam.outputs import write_results
from radar_slam.pipeline import Pipeline, PipelineConfig, open_configurations
from radar_slam.signals import children_ignore_sigint

log = logging.getLogger(__name__)

PARTIAL_PREFIX = ".partial-"
"""A job writes into `<parent>/.partial-<name>` and renames it to `<parent>/<name>` when done."""
SCHEDULER_CONNECT_TIMEOUT_S = 10.0
SCHEDULER_PROBE_TIMEOUT_S = 5.0
"""How long the check before any work waits for the scheduler's port to answer [s]."""
MALLOC_TRIM_SETTING = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"
"""Dask's nanny sets glibc's MALLOC_TRIM_THRESHOLD_ in its workers by default, which also turns
off glibc's adaptive mmap threshold: every large numpy array is then mmap'ed and page-faulted
afresh, and the pipeline ran about 3x slower per scan. Local workers are started without it."""


@dataclass(frozen=True)
class BatchJob:
    """One run of a batch.

    Attributes:
        sequence: the opened sequence (shared by the jobs of its loader settings).
        settings: the run's whole configuration (defaults, family YAML, `--config`, grid).
        label: `family/name` of the sequence (for the table).
        config_name: the grid configuration's name.
        folder: the run's result folder (must not exist yet; absolute once placed).
        max_frames: process only the first scans.
    """

    sequence: RadarSequence
    settings: PipelineConfig
    label: str
    config_name: str
    folder: Path
    max_frames: int | None = None


@dataclass(frozen=True)
class BatchRow:
    """One row of the summary table: a run's figures, or its error.

    Attributes:
        sequence, config: `family/name` and the configuration's name.
        status: "ok" or "failed".
        frames: scans processed; scans_per_s: frames / wall time of the pipeline [1/s].
        ate_*_m: Umeyama-aligned ATE RMSE [m]; drift_*_pct: KITTI translation drift [%].
        loops_accepted: accepted loop closures; loops_true: how many of them are true (GT).
        folder: the run's result folder ("" when it failed).
        error: one line ("" when it succeeded).
    """

    sequence: str
    config: str
    status: str
    frames: int | None = None
    scans_per_s: float | None = None
    ate_odometry_m: float | None = None
    ate_slam_m: float | None = None
    drift_odometry_pct: float | None = None
    drift_slam_pct: float | None = None
    loops_accepted: int | None = None
    loops_true: int | None = None
    folder: str = ""
    error: str = field(default="")

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def one_line(exc: BaseException) -> str:
    """An error as one line: the message of a user error, else `Type: message`."""
    text = " ".join(str(exc).split())
    if isinstance(exc, RadarSlamError) and text:
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def failed_row(job: BatchJob, error: str) -> BatchRow:
    return BatchRow(sequence=job.label, config=job.config_name, status="failed", error=error)


def run_job(job: BatchJob) -> BatchRow:
    """Run one job (on a worker): SLAM, result folder, summary row. Never raises for a failure
    of the run itself; the row then carries the error."""
    partial = job.folder.parent / f"{PARTIAL_PREFIX}{job.folder.name}"
    try:
        results = Pipeline(job.sequence, job.settings, max_frames=job.max_frames).run()
        partial.mkdir(parents=True)
        write_results(partial, results)
        partial.rename(job.folder)
    except Exception as exc:  # any failure of one run belongs in its row, not in the batch
        log.warning("%s [%s] failed: %s", job.label, job.config_name, exc)
        shutil.rmtree(partial, ignore_errors=True)
        return failed_row(job, one_line(exc))
    m = results.metrics
    return BatchRow(
        sequence=job.label,
        config=job.config_name,
        status="ok",
        frames=m.frames,
        scans_per_s=m.frames_per_second,
        ate_odometry_m=m.ate_odometry_m,
        ate_slam_m=m.ate_slam_m,
        drift_odometry_pct=m.drift_odometry_pct,
        drift_slam_pct=m.drift_slam_pct,
        loops_accepted=m.loops_accepted,
        loops_true=m.loops_accepted_true,
        folder=str(job.folder),
    )


ProgressHook = Callable[[BatchRow, int, int], None]
"""Called in the submitting process as each run finishes: (row, runs done, runs in total)."""


def check_scheduler(address: str) -> None:
    """Reject an address that is not `scheme://host:port`, or a tcp:// one where nothing
    listens, before anything starts."""
    scheme, separator, rest = address.partition("://")
    if not separator or not scheme or not rest:
        raise RadarSlamError(
            f"--scheduler {address!r}: expected a scheduler address such as tcp://host:8786"
        )
    host, _, port = rest.rpartition(":")
    if scheme != "tcp" or not port.isdigit():
        return  # other transports: Dask's own connection attempt tells
    try:
        socket.create_connection((host.strip("[]"), int(port)), SCHEDULER_PROBE_TIMEOUT_S).close()
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise RadarSlamError(f"--scheduler {address}: cannot connect ({reason})") from None


def run_batch(
    jobs: list[BatchJob],
    scheduler: str | None = None,
    workers: int = 2,
    on_done: ProgressHook | None = None,
) -> list[BatchRow]:
    """Run `jobs` as Dask tasks; returns one row per job, in the order of `jobs`.

    Args:
        jobs: the runs (their folders must not exist yet).
        scheduler: address of an existing Dask scheduler; None starts a local cluster.
        workers: worker processes of the local cluster (one thread each).
        on_done: progress hook, called as each run finishes.

    Raises:
        RadarSlamError: the scheduler cannot be reached.
    """
    import dask  # heavy; only batch needs it
    from distributed import Client, LocalCluster, as_completed

    if scheduler is None:  # workers deaf to Ctrl-C: this process ends them, without tracebacks
        with dask.config.set({MALLOC_TRIM_SETTING: None}), children_ignore_sigint():
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.CRITICAL,
            )
        client = Client(cluster)
    else:
        cluster = None
        try:
            client = Client(scheduler, timeout=SCHEDULER_CONNECT_TIMEOUT_S)
        except OSError as exc:
            raise RadarSlamError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    try:
        futures = {
            client.submit(run_job, job, pure=False, key=f"radar-slam-{n}-{job.config_name}"): n
            for n, job in enumerate(jobs)
        }
        rows: list[BatchRow | None] = [None] * len(jobs)
        for done, future in enumerate(as_completed(futures), start=1):
            n = futures[future]
            try:
                row = future.result()
            except Exception as exc:  # the worker itself died (e.g. out of memory)
                row = failed_row(jobs[n], one_line(exc))
            rows[n] = row
            if on_done is not None:
                on_done(row, done, len(jobs))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return [row for row in rows if row is not None]


def plan_jobs(
    sequences: list[str],
    grid: list[GridPoint],
    config_path: Path | None = None,
    data_root: Path | None = None,
    max_frames: int | None = None,
) -> list[BatchJob]:
    """One job per (sequence, configuration), checked before anything is submitted.

    Each sequence is opened here, once per distinct `dataset:` section of the grid (no scan is
    read; a synthetic sequence is generated here, once, rather than by several workers at the
    same time), and its jobs carry it to the workers, which do not open it again. The jobs'
    folders are relative, `<family>_<name>/<configuration>`: see `place_jobs`.

    Raises:
        RadarSlamError: a sequence is missing or malformed, a configuration invalid, or a
            sequence given twice.
    """
    jobs: list[BatchJob] = []
    labels: set[str] = set()
    root = None if data_root is None else Path(data_root).absolute()
    config = None if config_path is None else Path(config_path).absolute()
    for spec in sequences:
        label = ""
        opened = open_configurations(spec, root, config, [point.overrides for point in grid])
        for point, (sequence, settings) in zip(grid, opened, strict=True):
            label = f"{sequence.family}/{sequence.name}"
            folder = Path(label.replace("/", "_")) / point.name
            jobs.append(BatchJob(sequence, settings, label, point.name, folder, max_frames))
        if label in labels:
            raise RadarSlamError(f"{spec}: the sequence {label} is given twice")
        labels.add(label)
    return jobs


def place_jobs(jobs: list[BatchJob], batch_folder: Path) -> list[BatchJob]:
    """The jobs with their relative folders placed under `batch_folder` (made absolute)."""
    root = Path(batch_folder).absolute()
    return [dataclasses.replace(job, folder=root / job.folder) for job in jobs]
