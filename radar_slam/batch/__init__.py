"""`radar-slam batch`: many sequences (and a grid of configurations) as Dask tasks.

    grid.py     grid files: named override sets and products of value lists
    tasks.py    BatchJob / BatchRow, plan_jobs (checks before submitting), run_job (one run on
                a worker: pipeline + result folder), run_batch (local cluster or scheduler)
    summary.py  summary.csv / summary.md / summary.png

A writer-level package (like `radar_slam.outputs`): the library never imports it.
"""

from radar_slam.batch.grid import DEFAULT_GRID, GridPoint, parse_grid, read_grid
from radar_slam.batch.summary import SUMMARY_COLUMNS, markdown_text, write_summary
from radar_slam.batch.tasks import (
    BatchJob,
    BatchRow,
    check_scheduler,
    place_jobs,
    plan_jobs,
    run_batch,
    run_job,
)

__all__ = [
    "DEFAULT_GRID",
    "SUMMARY_COLUMNS",
    "BatchJob",
    "BatchRow",
    "GridPoint",
    "check_scheduler",
    "markdown_text",
    "parse_grid",
    "place_jobs",
    "plan_jobs",
    "read_grid",
    "run_batch",
    "run_job",
    "write_summary",
]
