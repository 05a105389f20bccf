"""Result folders never overwrite what a user had."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import pytest

from radar_slam import results
from radar_slam.errors import ResultsError


def test_timestamped_folder_and_latest_link(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    now = datetime(2026, 11, 22, 10, 0, 0)
    first = results.result_dir("synthetic", "loop", now=now)
    second = results.result_dir("synthetic", "loop", now=now)
    assert first != second and first.is_dir() and second.is_dir()
    latest = tmp_path / "results" / "synthetic_loop" / "latest"
    assert latest.resolve() == second.resolve()


def test_explicit_out_must_be_empty(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert results.result_dir("f", "s", out=out) == out
    (out / "keep.txt").write_text("mine")
    with pytest.raises(ResultsError, match="not empty"):
        results.result_dir("f", "s", out=out)
    assert (out / "keep.txt").read_text() == "mine"
