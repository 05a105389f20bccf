"""Time `radar-slam run` as a user runs it: one subprocess, from its start to its exit.

The wall time covers everything a user waits for: the interpreter starting, the imports, opening
the sequence, every scan, the final optimisation and evaluation, and every file of the result
folder (map/ included). The run's own figure (`metrics.json` `frames_per_second`, the line the
command prints) covers the scans only; both are reported side by side, with the CPU time of the
subprocess (user + system [s], what a shared machine distorts least), its peak resident memory
(RSS, the figure `radar_slam.pipeline.MEMORY_BUDGET_BYTES` bounds) and the machine's load
average before and after (`os.getloadavg`, one-minute).

The subprocess gets the default configuration and the environment of this process without the
single-thread variables the benchmarks set for themselves, and runs on the given cores through
`taskset -c` (or `os.sched_setaffinity` where taskset is missing).
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from bench_raplace import PINNED_FLAG, THREAD_VARIABLES

CLI_MODULE = "radar_slam.cli"
"""The module behind the `radar-slam` console script (run with this interpreter)."""
METRICS_FILE = "metrics.json"


@dataclass(frozen=True)
class WholeCommand:
    """One timed `radar-slam run` subprocess.

    Attributes:
        sequence: the sequence spec (with `--stride K` when strided).
        cores: the CPU cores it ran on.
        scans: scans processed.
        wall_s: wall time from its start to its exit [s].
        last_file_s: wall time from its start to the last file written into the result folder [s].
        cpu_s: its CPU time, user + system [s].
        peak_rss_mib: its peak resident memory [MiB].
        scans_per_s: scans / wall_s (the whole command).
        run_scans_per_s: the run's own figure (scans over the in-run time, `metrics.json`).
        run_s: the run's own time [s].
        ate_slam_m, ate_odometry_m: the run's ATE [m] (None without ground truth).
        loops_accepted: accepted loops.
        load_before, load_after: one-minute load average before and after the run.
    """

    sequence: str
    cores: tuple[int, ...]
    scans: int
    wall_s: float
    last_file_s: float
    cpu_s: float
    peak_rss_mib: float
    scans_per_s: float
    run_scans_per_s: float
    run_s: float
    ate_slam_m: float | None
    ate_odometry_m: float | None
    loops_accepted: int
    load_before: float
    load_after: float

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def child_environment() -> dict[str, str]:
    """This process's environment without the single-thread settings of the benchmarks."""
    dropped = {PINNED_FLAG, *THREAD_VARIABLES}
    return {k: v for k, v in os.environ.items() if k not in dropped}


def run_arguments(spec: str, out: Path, options: Sequence[str]) -> list[str]:
    """The command line of `radar-slam run SPEC --out OUT [options]` with this interpreter."""
    return [sys.executable, "-m", CLI_MODULE, "run", spec, "--out", str(out), *options]


def on_cores(
    command: list[str], cores: Sequence[int]
) -> tuple[list[str], Callable[[], None] | None]:
    """(command, preexec_fn) running `command` on `cores`: `taskset -c` when available."""
    listed = ",".join(str(c) for c in sorted(cores))
    taskset = shutil.which("taskset")
    if taskset is not None:
        return [taskset, "-c", listed, *command], None
    chosen = set(cores)
    return command, lambda: os.sched_setaffinity(0, chosen)


def last_write_epoch(folder: Path) -> float:
    """The latest modification time of any file under `folder` [s since the epoch]."""
    return max((p.stat().st_mtime for p in folder.rglob("*") if p.is_file()), default=0.0)


KIB_PER_MIB = 1024
"""`ru_maxrss` is in KiB on Linux."""


def run_child(
    command: list[str], cwd: str, preexec: Callable[[], None] | None
) -> tuple[int, str, resource.struct_rusage]:
    """Run `command` to its end: (exit code, its stderr, its own resource usage)."""
    with tempfile.TemporaryFile(mode="w+") as stderr:
        child = subprocess.Popen(
            command,
            cwd=cwd,  # `python -m` puts the current folder first on the module path
            env=child_environment(),
            preexec_fn=preexec,
            stdout=subprocess.DEVNULL,
            stderr=stderr,
            text=True,
        )
        _, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        stderr.seek(0)
        return child.returncode, stderr.read(), usage


def time_run(
    spec: str, cores: Sequence[int], options: Sequence[str] = (), label: str | None = None
) -> WholeCommand:
    """Run `radar-slam run SPEC` on `cores` in a subprocess and time it (see the module doc).

    Args:
        spec: the sequence (family/name, folder or bag).
        cores: CPU cores for the subprocess.
        options: further options of `radar-slam run` (e.g. --data-root DIR, --stride K; paths
            absolute: the subprocess runs in a temporary folder).
        label: the sequence's name in the report (default: `spec`).

    Raises:
        SystemExit: the command failed (its stderr is shown).
    """
    with tempfile.TemporaryDirectory(prefix="whole_command_") as tmp:
        out = Path(tmp) / "run"
        command, preexec = on_cores(run_arguments(spec, out, options), cores)
        load_before = os.getloadavg()[0]
        start_epoch, start = time.time(), time.perf_counter()
        code, errors, usage = run_child(command, tmp, preexec)
        wall = time.perf_counter() - start
        if code != 0:
            raise SystemExit(f"{' '.join(command)} failed:\n{errors}")
        metrics = json.loads((out / METRICS_FILE).read_text())
        last_file = last_write_epoch(out) - start_epoch
    scans = int(metrics["frames"])
    return WholeCommand(
        sequence=spec if label is None else label,
        cores=tuple(sorted(cores)),
        scans=scans,
        wall_s=wall,
        last_file_s=last_file,
        cpu_s=usage.ru_utime + usage.ru_stime,
        peak_rss_mib=usage.ru_maxrss / KIB_PER_MIB,
        scans_per_s=scans / wall,
        run_scans_per_s=float(metrics["frames_per_second"]),
        run_s=float(metrics["seconds"]),
        ate_slam_m=metrics.get("ate_slam_m"),
        ate_odometry_m=metrics.get("ate_odometry_m"),
        loops_accepted=int(metrics["loops_accepted"]),
        load_before=load_before,
        load_after=os.getloadavg()[0],
    )


def table(rows: Sequence[WholeCommand]) -> str:
    """The timed runs as a Markdown table."""
    lines = [
        "| sequence | cores | scans | whole command [s] | scans/s whole command "
        "| scans/s in run | last file [s] | CPU [s] | peak RSS [MiB] | SLAM ATE [m] | loops "
        "| load before/after |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ate = "n/a" if r.ate_slam_m is None else f"{r.ate_slam_m:.3f}"
        lines.append(
            f"| `{r.sequence}` | {len(r.cores)} | {r.scans} | {r.wall_s:.1f} "
            f"| {r.scans_per_s:.1f} | {r.run_scans_per_s:.1f} | {r.last_file_s:.1f} "
            f"| {r.cpu_s:.1f} | {r.peak_rss_mib:.0f} | {ate} | {r.loops_accepted} "
            f"| {r.load_before:.1f} / {r.load_after:.1f} |"
        )
    return "\n".join(lines)
