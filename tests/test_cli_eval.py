"""`radar-slam eval`, run through Typer's CliRunner on an app holding only this command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from radar_slam.commands import evaluate as evaluate_command
from radar_slam.errors import ResultsError, TrajectoryError
from radar_slam.evaluation.metrics import evaluate
from radar_slam.trajectory import Trajectory, read_kitti, read_tum, write_kitti, write_tum

T0_NS = 1_564_718_976_161_407_002
STEP_NS = 250_000_000  # 4 Hz, as a Navtech radar
N_POSES = 160
USAGE_ERROR = 2


@pytest.fixture
def app() -> typer.Typer:
    application = typer.Typer()

    @application.callback()
    def _root() -> None:  # keeps `eval` a subcommand, as in the real CLI
        pass

    evaluate_command.register(application)
    return application


def drive(step_m: float, yaw_rate: float, seed: int = 0) -> Trajectory:
    """A 159 m drive: `step_m` forward, `yaw_rate` [rad] plus a little wiggle after each step."""
    rng = np.random.default_rng(seed)
    motions = np.tile([step_m, 0.0, yaw_rate], (N_POSES - 1, 1))
    motions[:, 2] += rng.normal(0.0, 0.002, N_POSES - 1)
    stamps = T0_NS + np.arange(N_POSES, dtype=np.int64) * STEP_NS
    return Trajectory.from_relative_motions(stamps, motions, start=(100.0, 50.0, 1.0))


@pytest.fixture
def files(tmp_path: Path) -> dict[str, Path]:
    """GT and two estimates in TUM; the odometry estimate lacks one pose."""
    gt = drive(1.0, 0.01)
    odometry = drive(1.02, 0.011, seed=1)
    slam = drive(1.0, 0.0101, seed=0)
    paths = {name: tmp_path / f"{name}.tum" for name in ("gt", "odometry", "slam")}
    write_tum(paths["gt"], gt)
    write_tum(paths["odometry"], odometry[np.delete(np.arange(N_POSES), 5)])
    write_tum(paths["slam"], slam)
    return paths


def test_single_estimate_json_matches_library(
    app: typer.Typer, files: dict[str, Path], tmp_path: Path, metric_keys: frozenset[str]
) -> None:
    out = tmp_path / "metrics.json"
    result = CliRunner().invoke(
        app, ["eval", str(files["odometry"]), str(files["gt"]), "--json", str(out)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert set(data) == metric_keys
    expected = evaluate(read_tum(files["odometry"]), read_tum(files["gt"])).to_dict()
    assert data["poses_matched"] == N_POSES - 1
    for key, value in expected.items():
        assert data[key] == pytest.approx(value, rel=1e-12), key
    assert data["drift_trans_pct"] > 0
    assert "odometry" in result.output and "ATE origin [m]" in result.output


def test_several_estimates_in_one_table(
    app: typer.Typer, files: dict[str, Path], tmp_path: Path, metric_keys: frozenset[str]
) -> None:
    out = tmp_path / "compare.json"
    args = [
        "eval",
        str(files["odometry"]),
        str(files["slam"]),
        str(files["gt"]),
        "--json",
        str(out),
    ]
    result = CliRunner().invoke(app, [*args, "--rpe-delta", "4"])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert set(data) == {"odometry", "slam"}
    assert all(set(row) == metric_keys for row in data.values())
    assert data["slam"]["ate_origin_rmse_m"] < data["odometry"]["ate_origin_rmse_m"]
    expected = evaluate(read_tum(files["slam"]), read_tum(files["gt"]), rpe_delta=4)
    assert data["slam"]["rpe_trans_rmse_m"] == pytest.approx(expected.rpe_trans_rmse_m, rel=1e-12)
    table_rows = [line.split()[0] for line in result.output.splitlines()]
    assert "odometry" in table_rows and "slam" in table_rows


def test_json_is_not_overwritten_without_force(
    app: typer.Typer, files: dict[str, Path], tmp_path: Path, metric_keys: frozenset[str]
) -> None:
    out = tmp_path / "metrics.json"
    out.write_text("keep me")
    args = ["eval", str(files["slam"]), str(files["gt"]), "--json", str(out)]
    result = CliRunner().invoke(app, args)
    assert isinstance(result.exception, ResultsError)
    assert "--force" in str(result.exception)
    assert out.read_text() == "keep me"
    result = CliRunner().invoke(app, [*args, "--force"])
    assert result.exit_code == 0, result.output
    assert set(json.loads(out.read_text())) == metric_keys


def test_kitti_files_by_index(app: typer.Typer, tmp_path: Path) -> None:
    gt, est = drive(1.0, 0.01), drive(1.01, 0.01)
    write_kitti(tmp_path / "gt.txt", gt)
    write_kitti(tmp_path / "est.txt", est)
    write_kitti(tmp_path / "short.txt", est[:-1])
    out = tmp_path / "m.json"
    args = ["eval", str(tmp_path / "est.txt"), str(tmp_path / "gt.txt"), "--format", "kitti"]
    result = CliRunner().invoke(app, [*args, "--json", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["poses_matched"] == N_POSES
    expected = evaluate(
        read_kitti(tmp_path / "est.txt"), read_kitti(tmp_path / "gt.txt"), by="index"
    )
    assert data == pytest.approx(expected.to_dict(), rel=1e-12)
    # a 1 % scale error on a curve: the chord error is a little below 1 % of the path length
    assert 0.9 < data["drift_trans_pct"] < 1.0
    result = CliRunner().invoke(
        app, ["eval", str(tmp_path / "short.txt"), str(tmp_path / "gt.txt")]
    )
    assert isinstance(result.exception, TrajectoryError)
    assert "equal pose counts" in str(result.exception)


def test_short_trajectory_drift_is_null(app: typer.Typer, tmp_path: Path) -> None:
    gt = drive(1.0, 0.01)[:50]
    write_tum(tmp_path / "gt.tum", gt)
    write_tum(tmp_path / "est.tum", gt)
    out = tmp_path / "m.json"
    result = CliRunner().invoke(
        app, ["eval", str(tmp_path / "est.tum"), str(tmp_path / "gt.tum"), "--json", str(out)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["drift_trans_pct"] is None and data["drift_rot_deg_per_100m"] is None
    assert "n/a" in result.output and "note: drift needs" in result.output


def test_needs_an_estimate_and_ground_truth(app: typer.Typer, files: dict[str, Path]) -> None:
    result = CliRunner().invoke(app, ["eval", str(files["gt"])])
    assert result.exit_code == USAGE_ERROR
