"""Peak memory: a whole `radar-slam run` at MulRan resolution stays within `MEMORY_BUDGET_BYTES`
over `MEMORY_BUDGET_SCANS` scans.

A run's peak resident memory is its working set (the interpreter and libraries, the odometry's
images, the scans read ahead, the result files being written) plus what it keeps of each scan
(records, descriptors, odometry results, pose-graph nodes), which grows with the scans. The
working set is measured here: the peak RSS of a whole command over the first `SHORT_SCANS` scans
of the simulated `long` drive (400 x 3360 scans), in a subprocess, plus the working set of loop
closing, which these first scans do not reach yet (`LOOP_WORKING_SET_BYTES`). What a run keeps
per scan is bounded by tests/test_one_pass.py (`GROWTH_BUDGET_BYTES` over 10,000 scans, from the
Python and numpy allocations it still holds, which are exact where a difference of two peak RSS
figures moves by whole allocator arenas). Both together must fit the budget.

The child reads its own peak (`VmHWM` of /proc/self/status, the high-water mark of the memory it
maps after starting): the `ru_maxrss` a parent gets from `wait4` keeps the high-water mark from
before the child's `exec`, which with Python's vfork-based spawning is the test process's own
(about 870 MiB late in the suite).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from test_one_pass import GROWTH_BUDGET_BYTES

from radar_slam.cli import main
from radar_slam.pipeline import MEMORY_BUDGET_BYTES

SHORT_SCANS = 60
"""Scans of the measured run: past the odometry's and the loop detector's warm-up."""
LOOP_WORKING_SET_BYTES = 64 * 2**20
"""Added for loop closing's working set, which the short run does not reach: on the whole
`synthetic/long` drive (87 loops) the peak exceeded a projection from its first scans by 25 MiB
(docs/benchmarks.md, Memory budget); about two and a half times that."""
BYTES_PER_KIB = 1024
"""/proc's memory figures are in KiB."""
REPORTING_CHILD = """
import sys
from radar_slam.cli import main
try:
    code = main(sys.argv[2:])
finally:
    with open("/proc/self/status") as status:
        peak = next(line for line in status if line.startswith("VmHWM:"))
    with open(sys.argv[1], "w") as out:
        out.write(peak.split()[1])
sys.exit(code)
"""
"""Runs the CLI with the arguments after the first, then writes its own peak RSS [KiB] there."""


def peak_rss_bytes(drive: Path, scans: int, workdir: Path) -> int:
    """Peak resident memory of `radar-slam run DRIVE --max-frames SCANS` in a subprocess [B]."""
    out, report = workdir / f"run_{scans}", workdir / f"peak_{scans}.txt"
    command = [sys.executable, "-c", REPORTING_CHILD, str(report), "run", str(drive)]
    command += ["--max-frames", str(scans), "--out", str(out)]
    done = subprocess.run(command, cwd=workdir, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (out / "metrics.json").is_file()
    return int(report.read_text()) * BYTES_PER_KIB


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/status: Linux")
def test_working_set_and_what_a_run_keeps_fit_the_budget(tmp_path: Path) -> None:
    drive = tmp_path / "long_start"
    assert main(["simulate", "long", "--out", str(drive), "--frames", str(SHORT_SCANS)]) == 0
    working_set = peak_rss_bytes(drive, SHORT_SCANS, tmp_path) + LOOP_WORKING_SET_BYTES
    projected = working_set + GROWTH_BUDGET_BYTES
    figures = (
        f"working set {working_set / 2**20:.0f} MiB (loop closing included) + what a run keeps "
        f"{GROWTH_BUDGET_BYTES / 2**20:.0f} MiB = {projected / 2**20:.0f} MiB"
    )
    assert projected <= MEMORY_BUDGET_BYTES, figures
