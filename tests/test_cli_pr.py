"""`radar-slam pr` on tiny MulRan-layout sequences rendered from a synthetic world in tmp_path."""

from __future__ import annotations

import csv
import functools
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from raplace_scenes import synthetic_world
from typer.testing import CliRunner

from radar_slam.cli import app, main
from radar_slam.commands.placerec import MATCHES_HEADER, load_config
from radar_slam.datasets import open_sequence
from radar_slam.datasets.mulran import column_azimuths_rad
from radar_slam.datasets.navtech import (
    MULRAN_N_BINS,
    MULRAN_RANGE_RESOLUTION_M,
    MULRAN_T_BASE_RADAR,
)
from radar_slam.placerec import intra_session_candidate_counts, pr_curve, revisit_truth
from raplace import se2
from raplace.config import ExclusionConfig
from raplace.units import NS_PER_S

T0_NS = 1_600_000_000_000_000_000
PERIOD_NS = 250_000_000
WORLD_CELL_M = 0.5
WORLD_PX = 800
STEP_M = 5.0
EXCLUDE = 8
PNG_FAST = [cv2.IMWRITE_PNG_COMPRESSION, 1]
RENDERED_BINS = 1700
"""Bins rendered (to about 100 m; the descriptors look to 80 m)."""
PR_KEYS = {
    "auc",
    "max_f1",
    "recall_at_1",
    "precision",
    "recall",
    "thresholds",
    "queries",
    "true_revisits",
    "seconds",
}


def base_route(lateral_m: float) -> np.ndarray:
    """(n, 3) base poses: 120 m out along x, then back the opposite way `lateral_m` aside."""
    out = np.arange(-60.0, 60.0, STEP_M)
    outbound = np.stack([out, np.zeros_like(out), np.zeros_like(out)], axis=1)
    back = out[::-1]
    inbound = np.stack([back, np.full_like(back, lateral_m), np.full_like(back, np.pi)], axis=1)
    return np.concatenate([outbound, inbound])


@functools.cache
def sensor_grid() -> tuple[np.ndarray, np.ndarray]:
    """(n_rendered, n_azimuths) float32 x and y of the rendered polar samples, sensor frame [m]."""
    azimuths = column_azimuths_rad()
    ranges = (np.arange(RENDERED_BINS) + 0.5) * MULRAN_RANGE_RESOLUTION_M
    x = ranges[:, None] * np.cos(azimuths)[None, :]
    y = ranges[:, None] * np.sin(azimuths)[None, :]
    return x.astype(np.float32), y.astype(np.float32)


def render_mulran_polar(world: np.ndarray, radar_pose: np.ndarray) -> np.ndarray:
    """(n_bins, n_azimuths) uint8 plain MulRan polar image of a radar at `radar_pose` (returns
    beyond RENDERED_BINS are left empty)."""
    local_x, local_y = sensor_grid()
    c, s = np.float32(np.cos(radar_pose[2])), np.float32(np.sin(radar_pose[2]))
    rows = (WORLD_PX / 2 - 0.5 - radar_pose[0] / WORLD_CELL_M) - (c * local_x - s * local_y) / (
        WORLD_CELL_M
    )
    cols = (WORLD_PX / 2 - 0.5 - radar_pose[1] / WORLD_CELL_M) - (s * local_x + c * local_y) / (
        WORLD_CELL_M
    )
    near = cv2.remap(
        world, cols.astype(np.float32), rows.astype(np.float32), cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
    )  # fmt: skip
    polar = np.zeros((MULRAN_N_BINS, near.shape[1]), dtype=np.uint8)
    polar[:RENDERED_BINS] = np.clip(near, 0, 255).astype(np.uint8)
    return polar


def write_sequence(folder: Path, world: np.ndarray, base_poses: np.ndarray, t0_ns: int) -> None:
    """A MulRan sequence: polar/<t_ns>.png and global_pose.csv (base poses, 3x4 rows)."""
    (folder / "polar").mkdir(parents=True)
    stamps = t0_ns + np.arange(len(base_poses), dtype=np.int64) * PERIOD_NS
    radar_poses = se2.compose(base_poses, MULRAN_T_BASE_RADAR)
    for stamp, pose in zip(stamps, radar_poses, strict=True):
        image = render_mulran_polar(world, pose)
        cv2.imwrite(str(folder / "polar" / f"{stamp}.png"), image, PNG_FAST)
    rows = []
    for stamp, (x, y, yaw) in zip(stamps, base_poses, strict=True):
        c, s = np.cos(yaw), np.sin(yaw)
        rows.append(f"{stamp},{c},{-s},0,{x},{s},{c},0,{y},0,0,1,0")
    (folder / "global_pose.csv").write_text("\n".join(rows) + "\n")


@pytest.fixture(scope="module")
def data_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """mulran/session1 (out and back, 3 m aside), mulran/session2 (the same streets later,
    1.5 m aside and 0.7 m shifted) and mulran/nogt (session1 without global_pose.csv)."""
    root = tmp_path_factory.mktemp("pr_data")
    world = synthetic_world(WORLD_PX, seed=11)
    write_sequence(root / "mulran" / "session1", world, base_route(3.0), T0_NS)
    second = base_route(1.5) + np.array([0.7, 0.4, 0.05])
    write_sequence(root / "mulran" / "session2", world, second, T0_NS + 10**12)
    shutil.copytree(root / "mulran" / "session1", root / "mulran" / "nogt")
    (root / "mulran" / "nogt" / "global_pose.csv").unlink()
    return root


def run_pr(*args: str) -> str:
    result = CliRunner().invoke(app, ["pr", *args], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return result.output


def read_matches(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def test_intra_session_writes_curves_matches_and_config(data_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "intra"
    output = run_pr(
        "mulran/session1", "--data-root", str(data_root), "--exclude-recent", str(EXCLUDE),
        "--out", str(out),
    )  # fmt: skip
    assert "raplace" in output and "scancontext" in output
    for name in ("pr.json", "matches.csv", "pr_curve.png", "config.yaml", "summary.txt"):
        assert (out / name).is_file(), name
    report = json.loads((out / "pr.json").read_text())
    assert set(report) == {"raplace", "scancontext"}
    sequence = open_sequence("mulran/session1", data_root)
    n = len(sequence)
    for method, entry in report.items():
        assert PR_KEYS <= set(entry), method
        assert entry["queries"] == n
        assert len(entry["precision"]) == len(entry["recall"]) == len(entry["thresholds"])
        assert entry["exclude_recent"] == EXCLUDE and entry["criterion_m"] == 20.0
    # Out and back 3 m aside: every inbound frame beyond the turn-around window is a revisit.
    assert report["raplace"]["true_revisits"] >= n // 2 - EXCLUDE
    assert report["raplace"]["max_f1"] >= 0.9
    assert report["raplace"]["recall_at_1"] >= 0.9

    rows = read_matches(out / "matches.csv")
    assert tuple(rows[0]) == MATCHES_HEADER
    assert len(rows) == 2 * n
    stamps = sequence.timestamps_ns
    raplace_rows = [r for r in rows if r["method"] == "raplace"]
    assert [int(r["query_ns"]) for r in raplace_rows] == stamps.tolist()
    # The first EXCLUDE + 1 queries have no candidate; every other one names an older frame.
    assert all(r["match_ns"] == "" and r["distance"] == "inf" for r in raplace_rows[: EXCLUDE + 1])
    for i, row in enumerate(raplace_rows[EXCLUDE + 1 :], start=EXCLUDE + 1):
        assert int(row["match_ns"]) <= stamps[i - EXCLUDE - 1]

    # Anyone can recompute the curve from matches.csv and the ground truth.
    index_of = {int(t): i for i, t in enumerate(stamps)}
    xy = sequence.ground_truth[:, :2]
    match = np.array([index_of.get(int(r["match_ns"] or -1), -1) for r in raplace_rows])
    distance = np.array([float(r["distance"]) for r in raplace_rows])
    counts = intra_session_candidate_counts(stamps / NS_PER_S, ExclusionConfig(EXCLUDE, 0.0))
    revisit = revisit_truth(xy, xy, counts, 20.0)
    correct = (match >= 0) & (np.linalg.norm(xy - xy[match], axis=1) <= 20.0)
    curve = pr_curve(distance, correct, revisit)
    assert curve.max_f1 == pytest.approx(report["raplace"]["max_f1"])
    assert curve.auc == pytest.approx(report["raplace"]["auc"])
    np.testing.assert_allclose(curve.precision, report["raplace"]["precision"])

    # The written config is the one used, and it loads back.
    cfg = load_config(out / "config.yaml")
    assert cfg.retrieval.exclusion.recent_keyframes == EXCLUDE


def test_multi_session_queries_the_whole_map(data_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "multi"
    run_pr(
        "mulran/session2", "--map", "mulran/session1", "--data-root", str(data_root),
        "--method", "raplace", "--criterion", "10", "--out", str(out),
    )  # fmt: skip
    report = json.loads((out / "pr.json").read_text())
    assert set(report) == {"raplace"}
    entry = report["raplace"]
    n = len(open_sequence("mulran/session2", data_root))
    assert entry["mode"] == "multi" and entry["exclude_recent"] == 0
    assert entry["queries"] == entry["true_revisits"] == n  # every place was mapped
    assert entry["max_f1"] >= 0.95
    rows = read_matches(out / "matches.csv")
    assert len(rows) == n and all(r["match_ns"] for r in rows)


def test_max_frames_and_default_result_folder(
    data_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    run_pr("mulran/session1", "--data-root", str(data_root), "--max-frames", "12",
           "--method", "scancontext")  # fmt: skip
    folder = tmp_path / "results" / "pr_mulran_session1" / "latest"
    report = json.loads((folder / "pr.json").read_text())
    assert report["scancontext"]["queries"] == 12


def test_sequence_without_ground_truth_is_a_clear_error(
    data_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["pr", "mulran/nogt", "--data-root", str(data_root), "--out", str(tmp_path / "x")])
    assert code == 1
    err = capsys.readouterr().err
    assert "no ground truth" in err and "mulran/nogt" in err
    assert not (tmp_path / "x").exists()


def test_existing_output_folder_is_refused(
    data_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("mine")
    code = main(
        ["pr", "mulran/session1", "--data-root", str(data_root), "--max-frames", "3",
         "--out", str(tmp_path / "full")]
    )  # fmt: skip
    assert code == 1
    assert "not empty" in capsys.readouterr().err


def test_unknown_config_key_is_an_error(
    data_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "bad.yaml"
    config.write_text("retrieval:\n  hierachical: false\n")
    code = main(["pr", "mulran/session1", "--data-root", str(data_root), "--config", str(config)])
    assert code == 1
    assert "hierachical" in capsys.readouterr().err


STAND_FRAMES = 30


@pytest.fixture(scope="module")
def stand_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """mulran/stand: out along x, a stand of STAND_FRAMES frames at the far end (x = 55 m), then
    back 3 m aside."""
    root = tmp_path_factory.mktemp("pr_stand")
    route = base_route(3.0)
    half = len(route) // 2
    stand = np.repeat(route[half - 1 : half], STAND_FRAMES, axis=0)
    poses = np.concatenate([route[:half], stand, route[half:]])
    write_sequence(root / "mulran" / "stand", synthetic_world(WORLD_PX, seed=11), poses, T0_NS)
    return root


def test_a_stand_inflates_revisits_by_frames_but_not_by_distance(
    stand_root: Path, tmp_path: Path
) -> None:
    common = ("--data-root", str(stand_root), "--method", "raplace", "--criterion", "10")
    by_frames = run_pr("mulran/stand", *common, "--exclude-recent", "8", "--out", f"{tmp_path}/f")
    by_metres = run_pr(
        "mulran/stand", *common, "--exclude-recent", "8", "--exclude-metres", "12",
        "--out", str(tmp_path / "m"),
    )  # fmt: skip
    frames = json.loads((tmp_path / "f" / "pr.json").read_text())["raplace"]
    metres = json.loads((tmp_path / "m" / "pr.json").read_text())["raplace"]
    # By frames: the stand's queries 30-53 see the end of the way out (x 45-55 m) and each of
    # the 24 frames back sees the way out. By distance only the 24 frames back are revisits.
    # Standing: the stand's queries 31-53 (their newest candidate is 5 m behind or less) and the
    # first two frames back (the radar, 1.5 m ahead of the base, hops 4.3 m at the turn).
    assert frames["true_revisits"] == 48 and metres["true_revisits"] == 24
    assert frames["standing_queries"] == metres["standing_queries"] == 25
    assert metres["exclude_metres"] == 12.0 and "standing" in metres["standing_rule"]
    assert "25 standing queries" in by_frames and "12 m of travel" in by_metres
    assert metres["recall_at_1"] >= 0.9
