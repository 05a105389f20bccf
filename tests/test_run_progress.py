"""Progress after the last scan: the run names each final step (loops, optimisation, evaluation,
results, map) on its progress bar, so that nothing of seconds runs unseen."""

from __future__ import annotations

import io
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from tqdm import tqdm

from radar_slam.cli import main
from radar_slam.commands import run as run_command
from radar_slam.commands.options import RunProgress
from radar_slam.datasets.frame import RadarSequence
from radar_slam.pipeline import Pipeline, Progress, load_config

FRAMES = 12
PIPELINE_STEPS = ["last loops", "optimisation", "evaluation"]


def test_pipeline_reports_its_steps_after_the_last_scan(tiny: RadarSequence) -> None:
    seen: list[Progress] = []
    Pipeline(tiny, load_config("synthetic"), max_frames=FRAMES, progress=seen.append).run()
    assert [p.done for p in seen if not p.step] == list(range(1, FRAMES + 1))
    after = [p for p in seen if p.step]
    assert [p.step for p in after] == PIPELINE_STEPS
    assert all(p.done == p.total == FRAMES for p in after)
    assert seen[-len(after) :] == after  # only after the last scan


def test_the_bar_names_the_step_that_runs() -> None:
    shown = io.StringIO()
    with tqdm(total=3, file=shown, disable=False, mininterval=0) as bar:
        progress = RunProgress(bar, loops=True)
        progress(Progress(3, 3, 2, 1, 0.5))
        progress.step("map")
        text = shown.getvalue()
        progress.done()
    assert "loops=2" in text and "rejected=1" in text and "step=map" in text
    assert "step=" not in shown.getvalue()[len(text) :]  # the final line names no step


def test_radar_slam_run_shows_every_final_step(
    tiny: RadarSequence, synthetic_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    steps: list[str] = []

    class Recording(RunProgress):
        def step(self, name: str) -> None:
            steps.append(name)
            super().step(name)

    @contextmanager
    def recording_bar(total: int, description: str, loops: bool = True) -> Iterator[RunProgress]:
        with tqdm(total=total, file=io.StringIO(), disable=False) as bar:
            yield Recording(bar, loops)

    monkeypatch.setattr(run_command, "progress_bar", recording_bar)
    out = tmp_path / "run"
    frames = ["--max-frames", str(FRAMES)]
    assert (
        main(
            [
                "run",
                "synthetic/tiny",
                "--out",
                str(out),
                *frames,
                "--data-root",
                str(synthetic_root),
            ]
        )
        == 0
    )
    assert steps == [*PIPELINE_STEPS, "results", "map"]
    assert (out / "map").is_dir()
