"""The strided sequence view (`--stride K`): frames, timestamps and ground truth follow."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from radar_slam.cli import app
from radar_slam.datasets.frame import Sequence
from radar_slam.datasets.stride import ScanSelection, StridedSequence, strided
from radar_slam.errors import RadarSlamError


@pytest.mark.parametrize("stride", [2, 3, 4, 7])
def test_strided_view_keeps_every_kth_scan(tiny: Sequence, stride: int) -> None:
    view = strided(tiny, stride)
    assert isinstance(view, Sequence)
    assert len(view) == len(range(0, len(tiny), stride))
    assert view.family == tiny.family and view.name == f"{tiny.name}_stride{stride}"
    np.testing.assert_array_equal(view.timestamps_ns, tiny.timestamps_ns[::stride])
    gt = tiny.ground_truth
    assert gt is not None and view.ground_truth is not None
    np.testing.assert_array_equal(view.ground_truth, gt[::stride])
    for index in (0, 1, len(view) - 1, -1):
        frame = view[index]
        source = tiny[(index % len(view)) * stride]
        assert frame.timestamp_ns == source.timestamp_ns
        np.testing.assert_array_equal(frame.polar, source.polar)
    with pytest.raises(IndexError):
        view[len(view)]


def test_selection_keeps_the_chosen_scans(tiny: Sequence) -> None:
    """Any increasing scans (e.g. a recording with dropped scans)."""
    keep = np.array([0, 1, 5, 6, 30])
    view = ScanSelection(tiny, keep, "tiny_dropped")
    assert isinstance(view, Sequence) and len(view) == 5 and view.name == "tiny_dropped"
    np.testing.assert_array_equal(view.timestamps_ns, tiny.timestamps_ns[keep])
    gt = tiny.ground_truth
    assert gt is not None and view.ground_truth is not None
    np.testing.assert_array_equal(view.ground_truth, gt[keep])
    assert view[-1].timestamp_ns == tiny[30].timestamp_ns
    assert view[2].timestamp_ns == tiny[5].timestamp_ns
    with pytest.raises(IndexError):
        view[5]


def test_stride_one_is_the_sequence_and_zero_is_an_error(tiny: Sequence) -> None:
    assert strided(tiny, 1) is tiny
    with pytest.raises(RadarSlamError, match="stride"):
        StridedSequence(tiny, 0)


def test_odometry_command_with_stride(tiny: Sequence, synthetic_root: Path, tmp_path: Path) -> None:
    """`radar-slam odometry --stride 2` runs on every other scan and says so in its outputs."""
    out = tmp_path / "out"
    result = CliRunner().invoke(
        app,
        [
            "odometry",
            "synthetic/tiny",
            "--stride",
            "2",
            "--data-root",
            str(synthetic_root),
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    rows = (out / "odometry.tum").read_text().split("\n")
    poses = [row for row in rows if row and not row.startswith("#")]
    assert len(poses) == len(strided(tiny, 2))
    bad = CliRunner().invoke(app, ["odometry", "synthetic/tiny", "--stride", "0"])
    assert bad.exit_code != 0
