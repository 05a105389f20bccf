"""g2o 2-D pose-graph files: round trips and every malformed-input error (radar_slam.g2o)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from radar_slam.errors import GraphFormatError
from radar_slam.g2o import (
    G2oEdge,
    G2oGraph,
    format_g2o,
    g2o_to_pose_graph,
    parse_g2o,
    pose_graph_to_g2o,
    read_g2o,
    read_pose_graph,
    write_g2o,
    write_pose_graph,
)
from radar_slam.graph import GraphConfig, PoseGraph
from raplace import se2

ODOMETRY_COV = np.array(
    [[0.0025, 0.0004, 0.0001], [0.0004, 0.0036, -0.0002], [0.0001, -0.0002, 4e-5]]
)
LOOP_COV = np.diag([0.01, 0.02, 1e-4])
ROUND_TRIP_TOLERANCE = 1e-9

VALID_INFO = "100 0 0 100 0 1000"


def _pose_graph() -> PoseGraph:
    """A noisy 12-keyframe trajectory with two loops, optimised."""
    rng = np.random.default_rng(3)
    truth = se2.accumulate(np.tile([1.3, 0.1, np.pi / 5], (11, 1)))
    g = PoseGraph(GraphConfig())
    g.add_keyframe(0, truth[0])
    for k in range(1, len(truth)):
        z = se2.between(truth[k - 1], truth[k]) + rng.normal(0.0, 0.02, 3)
        g.add_keyframe(k, g.predict(k - 1, z))
        g.add_odometry(k - 1, k, z, ODOMETRY_COV)
    g.add_loop(10, 0, se2.between(truth[10], truth[0]), LOOP_COV)
    g.add_loop(11, 1, se2.between(truth[11], truth[1]) + 0.01, LOOP_COV)
    g.update()
    return g


def test_record_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    vertices = {k: rng.normal(0.0, 50.0, 3) for k in (3, 0, 7, 1)}  # file order kept
    info = np.array([[1e4 / 3, 1.0 / 7, 0.0], [1.0 / 7, 2e3, -0.5], [0.0, -0.5, 1e5 / 9]])
    edges = [G2oEdge(0, 1, rng.normal(0.0, 1.0, 3), info), G2oEdge(7, 3, rng.normal(size=3), info)]
    record = G2oGraph(vertices, edges, fixed=[0])
    path = tmp_path / "graph.g2o"
    write_g2o(path, record)
    back = read_g2o(path)
    assert list(back.vertices) == [3, 0, 7, 1]
    for k, pose in vertices.items():
        assert np.array_equal(back.vertices[k], pose)
    assert back.fixed == [0]
    for a, b in zip(record.edges, back.edges, strict=True):
        assert (a.i, a.j) == (b.i, b.j)
        assert np.array_equal(a.measurement, b.measurement)
        assert np.array_equal(a.information, b.information)
    assert format_g2o(back) == path.read_text()


def test_pose_graph_round_trip(tmp_path: Path) -> None:
    g = _pose_graph()
    path = tmp_path / "graph.g2o"
    write_pose_graph(path, g)
    back = read_pose_graph(path)
    assert back.keys() == g.keys()
    assert np.abs(back.initial_values() - g.estimates()).max() < ROUND_TRIP_TOLERANCE
    assert [p.key for p in back.priors()] == [0]
    pairs = [(c.kind, c.i, c.j) for _, c in back.constraints()]
    assert pairs == [(c.kind, c.i, c.j) for _, c in g.constraints()]
    assert [k for k, _, _ in pairs].count("loop") == 2
    for (_, a), (_, b) in zip(g.constraints(), back.constraints(), strict=True):
        assert np.abs(a.measurement - b.measurement).max() < ROUND_TRIP_TOLERANCE
        scale = np.abs(a.covariance).max()
        assert np.abs(a.covariance - b.covariance).max() < ROUND_TRIP_TOLERANCE * scale
    # Both graphs optimise to the same poses.
    assert np.abs(back.optimize_final() - g.optimize_final()).max() < 1e-6


def test_initial_values_written_on_request() -> None:
    g = _pose_graph()
    record = pose_graph_to_g2o(g, use_estimates=False)
    assert np.array_equal(record.poses(), g.initial_values())


def test_plain_file_with_comments_and_reverse_edges() -> None:
    text = (
        "# a graph from another odometry\n\n"
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0 0\n"
        f"EDGE_SE2 1 0 -1 0 0 {VALID_INFO}\n"  # odometry written backwards
        f"EDGE_SE2 1 2 1 0 0 {VALID_INFO}\n"
        f"EDGE_SE2 2 0 -2 0 0 {VALID_INFO}\n"
    )
    record = parse_g2o(text, "mem.g2o")
    g = g2o_to_pose_graph(record)
    kinds = [c.kind for _, c in g.constraints()]
    assert kinds == ["odometry", "odometry", "loop"]
    assert np.allclose(record.edges[0].covariance, np.diag([0.01, 0.01, 0.001]))
    poses = g.optimize_final()
    assert np.allclose(poses, [[0, 0, 0], [1, 0, 0], [2, 0, 0]], atol=1e-6)


def test_unknown_tags_are_skipped_with_one_warning(caplog: pytest.LogCaptureFixture) -> None:
    text = "VERTEX_SE2 0 0 0 0\nVERTEX_XY 5 1 2\nVERTEX_XY 6 1 2\nEDGE_SE2_XY 0 5 1 2 1 0 1\n"
    with caplog.at_level(logging.WARNING, logger="radar_slam.g2o"):
        record = parse_g2o(text, "mixed.g2o")
    assert list(record.vertices) == [0]
    messages = [r.getMessage() for r in caplog.records]
    assert messages == [
        "mixed.g2o: skipped 3 line(s) with unsupported tags VERTEX_XY (2), EDGE_SE2_XY (1) "
        "(first at line 2)"
    ]


MALFORMED = {
    "vertex field count": (
        "VERTEX_SE2 0 1 2\n",
        1,
        "VERTEX_SE2 expects 4 values after the tag, got 3",
    ),
    "edge field count": (
        f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 {VALID_INFO}\n",
        3,
        "EDGE_SE2 expects 11 values after the tag, got 10",
    ),
    "non-numeric value": ("VERTEX_SE2 0 0 zero 0\n", 1, "'zero' is not a number"),
    "non-finite value": ("VERTEX_SE2 0 0 nan 0\n", 1, "non-finite value"),
    "non-integer id": ("VERTEX_SE2 0.5 0 0 0\n", 1, "vertex id '0.5' is not an integer"),
    "negative id": ("VERTEX_SE2 -2 0 0 0\n", 1, "vertex id -2 is negative"),
    "duplicate vertex": ("VERTEX_SE2 0 0 0 0\n\nVERTEX_SE2 0 1 0 0\n", 3, "vertex 0 defined twice"),
    "edge to missing vertex": (
        f"VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 {VALID_INFO}\n"
        f"EDGE_SE2 1 9 1 0 0 {VALID_INFO}\n",
        4,
        "edge refers to missing vertex 9",
    ),
    "self edge": (f"VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 0 1 0 0 {VALID_INFO}\n", 2, "to itself"),
    "non-positive-definite information": (
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 2 0 1 0 1\n",
        3,
        "information matrix of edge 0 -> 1 is not positive definite",
    ),
    "zero information": (
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 0 0 0 0 0 0\n",
        3,
        "not positive definite",
    ),
    "FIX of missing vertex": ("VERTEX_SE2 0 0 0 0\nFIX 4\n", 2, "FIX refers to missing vertex 4"),
    "FIX without id": ("VERTEX_SE2 0 0 0 0\nFIX\n", 2, "FIX needs at least one vertex id"),
    "no vertices": ("# nothing here\n", None, "no VERTEX_SE2 lines"),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_input_names_file_and_line(case: str, tmp_path: Path) -> None:
    text, line, message = MALFORMED[case]
    path = tmp_path / "bad.g2o"
    path.write_text(text)
    where = f"{path}:{line}: " if line is not None else f"{path}: "
    with pytest.raises(GraphFormatError) as info:
        read_g2o(path)
    assert str(info.value).startswith(where)
    assert message in str(info.value)


def test_strict_rejects_unknown_tags(tmp_path: Path) -> None:
    path = tmp_path / "landmarks.g2o"
    path.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_XY 5 1 2\n")
    assert list(read_g2o(path).vertices) == [0]
    with pytest.raises(GraphFormatError, match=r"landmarks.g2o:2: unsupported tag 'VERTEX_XY'"):
        read_g2o(path, strict=True)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(GraphFormatError, match="cannot read g2o file"):
        read_g2o(tmp_path / "missing.g2o")
    binary = tmp_path / "binary.g2o"
    binary.write_bytes(b"\xff\xfe\x00VERTEX")
    with pytest.raises(GraphFormatError, match="not a text file"):
        read_g2o(binary)
