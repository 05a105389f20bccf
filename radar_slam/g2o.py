"""g2o 2-D pose-graph files: read and write `VERTEX_SE2`, `EDGE_SE2` and `FIX` lines.

Format (one item per line, whitespace separated; blank lines and `#` comments are skipped):

    VERTEX_SE2 id x y theta
    EDGE_SE2 i j dx dy dtheta I11 I12 I13 I22 I23 I33
    FIX id

`(dx, dy, dtheta)` is the pose of vertex j in the frame of vertex i (T_i^-1 T_j), and `I..` the
upper triangle of its 3 x 3 information matrix (inverse covariance), order (x, y, theta). Units
are metres and radians. Other tags (landmark vertices, 3-D types, ...) are skipped with one logged
warning, or rejected with `strict=True`. Every malformed line raises `GraphFormatError`
naming the file and line.

Numbers are written with `repr`, the shortest text that reads back to the same float, so
`read_g2o(write_g2o(g))` reproduces `g` exactly.

Mapping to `PoseGraph` (`g2o_to_pose_graph`): an edge between vertices adjacent in sorted id order
is odometry, any other edge a loop (robust kernel); `FIX` vertices get a prior at their pose with
`radar_slam.graph.PRIOR_SIGMAS`; without `FIX`, the graph's automatic prior anchors the smallest id.
Writing a `PoseGraph` writes each prior as `FIX` (g2o has no standard SE(2) prior edge, so the
prior covariance is not kept).
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from radar_slam.errors import GraphError, GraphFormatError
from radar_slam.graph import POSE_DIM, PRIOR_SIGMAS, GraphConfig, PoseGraph
from radar_slam.results import write_text_atomically

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

VERTEX_TAG = "VERTEX_SE2"
EDGE_TAG = "EDGE_SE2"
FIX_TAG = "FIX"
COMMENT_PREFIX = "#"
VERTEX_FIELDS = 4  # id x y theta
EDGE_FIELDS = 11  # i j dx dy dtheta + 6 information entries
FIX_MIN_FIELDS = 1  # FIX id [id ...]
_UPPER = np.triu_indices(POSE_DIM)  # row-major upper triangle: I11 I12 I13 I22 I23 I33


@dataclass(frozen=True)
class G2oEdge:
    """One `EDGE_SE2`.

    Attributes:
        i, j: vertex ids.
        measurement: (3,) T_i^-1 T_j `(x [m], y [m], theta [rad])`.
        information: (3, 3) symmetric positive definite inverse covariance.
    """

    i: int
    j: int
    measurement: FloatArray
    information: FloatArray

    @property
    def covariance(self) -> FloatArray:
        """(3, 3) covariance, the inverse of `information`."""
        cov = np.linalg.inv(self.information)
        return 0.5 * (cov + cov.T)


@dataclass(frozen=True)
class G2oGraph:
    """The content of a g2o 2-D pose-graph file.

    Attributes:
        vertices: id -> (3,) pose T_world_vertex `(x [m], y [m], theta [rad])`, in file order.
        edges: the `EDGE_SE2`s in file order.
        fixed: ids of `FIX`ed vertices, in file order.
    """

    vertices: dict[int, FloatArray]
    edges: list[G2oEdge] = field(default_factory=list)
    fixed: list[int] = field(default_factory=list)

    def keys(self) -> list[int]:
        """Vertex ids in increasing order."""
        return sorted(self.vertices)

    def poses(self) -> FloatArray:
        """(N, 3) vertex poses in increasing id order."""
        return np.array([self.vertices[k] for k in self.keys()], dtype=np.float64).reshape(-1, 3)


# --------------------------------------------------------------------------- parsing


def _ids(tokens: list[str], where: str) -> list[int]:
    out = []
    for t in tokens:
        try:
            value = int(t)
        except ValueError:
            raise GraphFormatError(f"{where}: vertex id {t!r} is not an integer") from None
        if value < 0:
            raise GraphFormatError(f"{where}: vertex id {value} is negative")
        out.append(value)
    return out


def _numbers(tokens: list[str], where: str) -> FloatArray:
    try:
        values = np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise GraphFormatError(f"{where}: {bad!r} is not a number") from None
    if not np.all(np.isfinite(values)):
        raise GraphFormatError(f"{where}: non-finite value in {' '.join(tokens)}")
    return values


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _expect(tokens: list[str], count: int, where: str) -> None:
    if len(tokens) - 1 != count:
        raise GraphFormatError(
            f"{where}: {tokens[0]} expects {count} values after the tag, got {len(tokens) - 1}"
        )


def information_from_upper(upper: FloatArray) -> FloatArray:
    """(3, 3) symmetric matrix from its row-major upper triangle (6,) I11 I12 I13 I22 I23 I33."""
    info = np.zeros((POSE_DIM, POSE_DIM))
    info[_UPPER] = upper
    return info + np.triu(info, 1).T


def parse_g2o(text: str, source: str = "<g2o>") -> G2oGraph:
    """Parse g2o text (see the module docstring); `source` names it in error messages.

    Unknown tags are skipped with one warning per tag.
    """
    return _parse(text.splitlines(), source, strict=False)


def _parse(lines: Iterable[str], source: str, strict: bool) -> G2oGraph:
    vertices: dict[int, FloatArray] = {}
    edges: list[G2oEdge] = []
    edge_lines: list[int] = []
    fixed: list[tuple[int, int]] = []
    skipped: Counter[str] = Counter()
    first_skipped: dict[str, int] = {}
    for lineno, line in enumerate(lines, start=1):
        tokens = line.split()
        if not tokens or tokens[0].startswith(COMMENT_PREFIX):
            continue
        where = f"{source}:{lineno}"
        tag = tokens[0]
        if tag == VERTEX_TAG:
            _expect(tokens, VERTEX_FIELDS, where)
            (key,) = _ids(tokens[1:2], where)
            if key in vertices:
                raise GraphFormatError(f"{where}: vertex {key} defined twice")
            vertices[key] = _numbers(tokens[2:5], where)
        elif tag == EDGE_TAG:
            _expect(tokens, EDGE_FIELDS, where)
            i, j = _ids(tokens[1:3], where)
            if i == j:
                raise GraphFormatError(f"{where}: edge from vertex {i} to itself")
            values = _numbers(tokens[3:], where)
            info = information_from_upper(values[3:])
            try:
                np.linalg.cholesky(info)
            except np.linalg.LinAlgError:
                raise GraphFormatError(
                    f"{where}: information matrix of edge {i} -> {j} is not positive definite"
                ) from None
            edges.append(G2oEdge(i, j, values[:3], info))
            edge_lines.append(lineno)
        elif tag == FIX_TAG:
            if len(tokens) - 1 < FIX_MIN_FIELDS:
                raise GraphFormatError(f"{where}: FIX needs at least one vertex id")
            fixed.extend((key, lineno) for key in _ids(tokens[1:], where))
        elif strict:
            raise GraphFormatError(f"{where}: unsupported tag {tag!r}")
        else:
            skipped[tag] += 1
            first_skipped.setdefault(tag, lineno)
    if not vertices:
        raise GraphFormatError(f"{source}: no {VERTEX_TAG} lines")
    if skipped:
        log.warning(
            "%s: skipped %d line(s) with unsupported tags %s (first at line %d)",
            source,
            sum(skipped.values()),
            _tag_list(skipped),
            min(first_skipped.values()),
        )
    for edge, lineno in zip(edges, edge_lines, strict=True):
        for key in (edge.i, edge.j):
            if key not in vertices:
                raise GraphFormatError(f"{source}:{lineno}: edge refers to missing vertex {key}")
    for key, lineno in fixed:
        if key not in vertices:
            raise GraphFormatError(f"{source}:{lineno}: FIX refers to missing vertex {key}")
    return G2oGraph(vertices, edges, list(dict.fromkeys(k for k, _ in fixed)))


MAX_TAGS_NAMED = 5
"""A warning about skipped lines names at most this many of their tags."""


def _tag_list(skipped: Counter[str]) -> str:
    """The most frequent skipped tags with their counts, and how many others."""
    common = skipped.most_common(MAX_TAGS_NAMED)
    text = ", ".join(f"{tag[:40]} ({count})" for tag, count in common)
    others = len(skipped) - len(common)
    return text + (f" and {others} other(s)" if others else "")


def read_g2o(path: Path | str, strict: bool = False) -> G2oGraph:
    """Read a g2o 2-D pose-graph file; `strict` rejects unsupported tags instead of skipping."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) else "not a text file"
        raise GraphFormatError(f"{path}: cannot read g2o file ({reason})") from None
    return _parse(text.splitlines(), str(path), strict)


# --------------------------------------------------------------------------- writing


def _num(value: float) -> str:
    return repr(float(value))


def format_g2o(graph: G2oGraph) -> str:
    """g2o text of `graph`: vertices, edges, then FIX lines, numbers exact (`repr`)."""
    lines = [
        f"{VERTEX_TAG} {key} " + " ".join(_num(v) for v in pose)
        for key, pose in graph.vertices.items()
    ]
    for e in graph.edges:
        upper = np.asarray(e.information, dtype=np.float64)[_UPPER]
        numbers = [*np.asarray(e.measurement, dtype=np.float64), *upper]
        lines.append(f"{EDGE_TAG} {e.i} {e.j} " + " ".join(_num(v) for v in numbers))
    lines.extend(f"{FIX_TAG} {key}" for key in graph.fixed)
    return "\n".join(lines) + "\n"


def write_g2o(path: Path | str, graph: G2oGraph) -> None:
    """Write `graph` as a g2o file (see `format_g2o`), atomically (temporary file renamed)."""
    path = Path(path)
    try:
        write_text_atomically(path, format_g2o(graph))
    except OSError as exc:
        raise GraphError(f"{path}: cannot write g2o file ({exc.strerror})") from None


# --------------------------------------------------------------------------- PoseGraph bridge


def pose_graph_to_g2o(graph: PoseGraph, use_estimates: bool = True) -> G2oGraph:
    """A `G2oGraph` of `graph`: vertices = latest estimates (or initial guesses), edges = active
    odometry and loop factors in insertion order with information = covariance^-1, priors as
    FIX."""
    poses = graph.estimates() if use_estimates else graph.initial_values()
    vertices = {key: pose.copy() for key, pose in zip(graph.keys(), poses, strict=True)}
    edges = []
    for _, c in graph.constraints():
        info = np.linalg.inv(c.covariance)
        edges.append(G2oEdge(c.i, c.j, c.measurement.copy(), 0.5 * (info + info.T)))
    fixed = list(dict.fromkeys(p.key for p in graph.priors()))
    return G2oGraph(vertices, edges, fixed)


def g2o_to_pose_graph(record: G2oGraph, config: GraphConfig | None = None) -> PoseGraph:
    """A `PoseGraph` of a g2o record (classification rules in the module docstring).

    Vertices become keyframes (initial guess = vertex pose) in increasing id order.
    """
    graph = PoseGraph(config)
    keys = record.keys()
    rank = {key: n for n, key in enumerate(keys)}
    for key in keys:
        graph.add_keyframe(key, record.vertices[key])
    sigmas = np.asarray(PRIOR_SIGMAS, dtype=np.float64)
    for key in record.fixed:
        graph.add_prior(key, record.vertices[key], np.diag(sigmas**2))
    for e in record.edges:
        if abs(rank[e.i] - rank[e.j]) == 1:
            graph.add_odometry(e.i, e.j, e.measurement, e.covariance)
        else:
            graph.add_loop(e.i, e.j, e.measurement, e.covariance)
    return graph


def write_pose_graph(path: Path | str, graph: PoseGraph, use_estimates: bool = True) -> None:
    """Write a `PoseGraph` as g2o (vertices = estimates unless `use_estimates` is False)."""
    write_g2o(path, pose_graph_to_g2o(graph, use_estimates))


def read_pose_graph(
    path: Path | str, config: GraphConfig | None = None, strict: bool = False
) -> PoseGraph:
    """Read a g2o file into a `PoseGraph` (see `g2o_to_pose_graph`)."""
    return g2o_to_pose_graph(read_g2o(path, strict), config)
