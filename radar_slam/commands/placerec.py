"""`radar-slam pr SEQ [--map SEQ2]`: place-recognition precision-recall of RaPlace and Scan Context.

The protocol is defined in radar_slam.placerec. This module opens the sequences, runs the
recognizers over the frames with a progress bar, and writes the result folder:

- `pr.json`: {method: {auc, max_f1, recall_at_1, precision, recall, thresholds, queries,
  true_revisits, seconds, ...}};
- `matches.csv`: `method,query_ns,match_ns,distance`, each query's best candidate (match_ns empty
  and distance inf when it had none), enough to recompute the curves with the ground truth;
- `pr_curve.png`: the curves of every method run;
- `config.yaml`: the raplace settings used (loadable with --config), `summary.txt`.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

import numpy as np
import typer
from numpy.typing import NDArray
from tqdm import tqdm

from radar_slam.commands.options import DATA_ROOT_OPTION
from radar_slam.config import merge, read_yaml, write_yaml
from radar_slam.datasets import RadarFrame, RadarSequence, open_sequence
from radar_slam.loops.recent import NO_EXCLUSION
from radar_slam.placerec import (
    DEFAULT_CRITERION_M,
    DEFAULT_EXCLUDE_RECENT,
    METHODS,
    NO_MATCH,
    BestMatches,
    Mode,
    PlaceRecognitionError,
    PRCurve,
    build_map,
    evaluate_matches,
    intra_session_candidate_counts,
    match_intra_session,
    match_queries,
    method_runs,
    path_length_m,
    standing_queries,
    with_exclusion,
)
from radar_slam.plots import plot_pr_curves
from radar_slam.results import check_output_root, write_result_dir
from raplace import NS_PER_S, ExclusionConfig, RaPlaceConfig

log = logging.getLogger(__name__)

RESULTS_FAMILY = "pr"
MATCHES_HEADER = ("method", "query_ns", "match_ns", "distance")
METHOD_LABELS = {"raplace": "RaPlace", "scancontext": "Scan Context"}
NUMBER_LIST = re.compile(r"\[\s*([-+0-9.eE,\snul]*?)\s*\]")
"""A JSON list holding only numbers (and null), as json.dumps(indent=...) spreads it."""
WHITESPACE = re.compile(r"\s+")


class MethodChoice(str, Enum):
    """Which recognizers to evaluate."""

    raplace = "raplace"
    scancontext = "scancontext"
    both = "both"

    def methods(self) -> tuple[str, ...]:
        return METHODS if self is MethodChoice.both else (self.value,)


@dataclass(frozen=True)
class EvaluatedFrames:
    """The frames of a sequence that have ground truth, and their positions.

    Attributes:
        sequence: the opened sequence.
        indices: (n,) indices into the sequence of the frames evaluated.
        xy: (n, 2) ground-truth positions [m].
        timestamps_ns: (n,) frame times [ns].
    """

    sequence: RadarSequence
    indices: NDArray[np.int64]
    xy: NDArray[np.float64]
    timestamps_ns: NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.indices)

    def frames(self, description: str) -> Iterator[tuple[int, RadarFrame]]:
        """(evaluated index, frame), loaded lazily, with a frames/s progress bar on stderr."""
        for position in tqdm(
            range(len(self)),
            desc=description,
            unit="frame",
            dynamic_ncols=True,
            leave=False,
            disable=None,
        ):
            yield position, self.sequence[int(self.indices[position])]


def spec_name(sequence: RadarSequence) -> str:
    return f"{sequence.family}/{sequence.name}"


def evaluated_frames(sequence: RadarSequence, max_frames: int | None) -> EvaluatedFrames:
    """The first `max_frames` frames of `sequence` that have a ground-truth pose.

    Raises:
        PlaceRecognitionError: the sequence has no ground truth at all.
    """
    gt = sequence.ground_truth
    if gt is None:
        raise PlaceRecognitionError(
            f"{spec_name(sequence)} has no ground truth: PR curves need GT poses to tell true "
            "revisits (give a sequence with GT, e.g. MulRan global_pose.csv)"
        )
    n = len(sequence) if max_frames is None else min(len(sequence), max_frames)
    finite = np.flatnonzero(np.all(np.isfinite(gt[:n, :2]), axis=1))
    if len(finite) == 0:
        raise PlaceRecognitionError(f"{spec_name(sequence)}: no frame has a ground-truth pose")
    if len(finite) < n:
        log.warning(
            "%s: %d of %d frames have no ground-truth pose and are left out",
            spec_name(sequence),
            n - len(finite),
            n,
        )
    return EvaluatedFrames(
        sequence=sequence,
        indices=finite.astype(np.int64),
        xy=np.asarray(gt[finite, :2], dtype=np.float64),
        timestamps_ns=np.asarray(sequence.timestamps_ns)[finite].astype(np.int64),
    )


def load_config(path: Path | None) -> RaPlaceConfig:
    """RaPlace settings: the defaults, overridden by the YAML file (strictly) if given."""
    if path is None:
        return RaPlaceConfig()
    return merge(RaPlaceConfig, RaPlaceConfig(), read_yaml(path), str(path))


def method_summary(
    curve: PRCurve, matches: BestMatches, settings: dict[str, object]
) -> dict[str, object]:
    """The pr.json object of one method (JSON-ready; an infinite threshold becomes null)."""
    frames = max(1, matches.frames)
    best_threshold = curve.threshold_at_max_f1
    return {
        "auc": curve.auc,
        "max_f1": curve.max_f1,
        "recall_at_1": curve.recall_at_1,
        "threshold_at_max_f1": best_threshold if math.isfinite(best_threshold) else None,
        "precision": curve.precision.tolist(),
        "recall": curve.recall.tolist(),
        "thresholds": curve.thresholds.tolist(),
        "queries": curve.queries,
        "true_revisits": curve.true_revisits,
        "seconds": matches.seconds,
        "frames": matches.frames,
        "ms_per_frame": 1e3 * matches.seconds / frames,
        "descriptor_ms": 1e3 * matches.descriptor_seconds / frames,
        **settings,
    }


def compact_json(data: object) -> str:
    """Indented JSON with every list of numbers on one line (curves stay readable)."""
    text = json.dumps(data, indent=2, allow_nan=False)
    return NUMBER_LIST.sub(lambda match: "[" + WHITESPACE.sub(" ", match.group(1)) + "]", text)


def write_matches(
    path: Path,
    results: dict[str, BestMatches],
    query_ns: NDArray[np.int64],
    map_ns: NDArray[np.int64],
) -> None:
    """matches.csv: one row per query and method, the best candidate whatever its distance."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(MATCHES_HEADER)
        for method, matches in results.items():
            for q, m, d in zip(
                matches.query_index, matches.match_index, matches.distance, strict=True
            ):
                match_ns = "" if m == NO_MATCH else str(int(map_ns[m]))
                writer.writerow((method, int(query_ns[q]), match_ns, repr(float(d))))


def format_table(curves: dict[str, PRCurve], results: dict[str, BestMatches]) -> str:
    """Plain-text summary, one row per method."""
    lines = [
        f"{'method':<12} {'queries':>7} {'revisits':>8} {'AUC':>6} {'max F1':>6} "
        f"{'R@1':>6} {'seconds':>8} {'frames/s':>8}"
    ]
    for method, curve in curves.items():
        seconds = results[method].seconds
        rate = results[method].frames / seconds if seconds > 0 else float("nan")
        lines.append(
            f"{method:<12} {curve.queries:>7d} {curve.true_revisits:>8d} {curve.auc:>6.3f} "
            f"{curve.max_f1:>6.3f} {curve.recall_at_1:>6.3f} {seconds:>8.1f} {rate:>8.1f}"
        )
    return "\n".join(lines)


def warn_overridden_exclusion(cfg: RaPlaceConfig, exclusion: ExclusionConfig) -> None:
    """The evaluation's window replaces the config's; say so when they differ."""
    for section, configured in (
        ("retrieval", cfg.retrieval.exclusion),
        ("scancontext", cfg.scancontext.exclusion),
    ):
        if configured != exclusion:
            log.warning(
                "%s.exclusion %s is replaced by the evaluation's window %s",
                section,
                configured,
                exclusion,
            )


STANDING_RULE = (
    "a query is standing when the frame and time rules leave it candidates and the newest is "
    "less than criterion_m of ground-truth travel behind it"
)

MAX_OPTION_VALUE = 1e9
"""Upper bound of the distance [m] and time [s] options (rejects inf, which JSON cannot hold)."""


def pr_command(
    sequence_spec: str = typer.Argument(
        ..., metavar="SEQ", help="Query sequence: family/sequence or a folder path."
    ),
    map_spec: str | None = typer.Option(
        None,
        "--map",
        metavar="SEQ2",
        help="Map sequence for multi-session evaluation (queries of SEQ against all of SEQ2).",
    ),
    method: MethodChoice = typer.Option(MethodChoice.both, "--method", help="Recognizers to run."),
    criterion_m: float = typer.Option(
        DEFAULT_CRITERION_M,
        "--criterion",
        min=0.0,
        max=MAX_OPTION_VALUE,
        help="Revisit criterion: a match is true within this distance \\[m] (10/20/50 in papers).",
    ),
    exclude_recent: int = typer.Option(
        DEFAULT_EXCLUDE_RECENT,
        "--exclude-recent",
        min=0,
        help="Intra-session: the most recent N frames are never candidates (nor revisits).",
    ),
    exclude_seconds: float = typer.Option(
        0.0,
        "--exclude-seconds",
        min=0.0,
        max=MAX_OPTION_VALUE,
        help="Intra-session: frames less than this many seconds older are excluded too.",
    ),
    exclude_metres: float = typer.Option(
        0.0,
        "--exclude-metres",
        min=0.0,
        max=MAX_OPTION_VALUE,
        help="Intra-session: frames less than this distance travelled before the query "
        "(ground-truth path length) \\[m] are excluded too. A query is counted as standing when "
        "the frame and time rules leave it a candidate less than the criterion of travel "
        "behind (a trivial revisit); pr.json reports how many.",
    ),
    out: Path | None = typer.Option(
        None, "--out", help="Output folder (absent or empty); default results/pr_<seq>/<time>/."
    ),
    data_root: Path | None = DATA_ROOT_OPTION,
    config_path: Path | None = typer.Option(
        None, "--config", exists=True, dir_okay=False, help="YAML overrides of raplace settings."
    ),
    max_frames: int | None = typer.Option(
        None, "--max-frames", min=1, help="Use only the first N frames of each sequence."
    ),
) -> None:
    """Precision-recall of loop detection (intra-session) or relocalisation (--map)."""
    check_output_root(out)
    cfg = load_config(config_path)
    query = evaluated_frames(open_sequence(sequence_spec, data_root), max_frames)
    if map_spec is None:
        exclusion = ExclusionConfig(recent_keyframes=exclude_recent, recent_seconds=exclude_seconds)
        reference = None
    else:
        exclusion = ExclusionConfig(recent_keyframes=0, recent_seconds=0.0)
        reference = evaluated_frames(open_sequence(map_spec, data_root), max_frames)
    if config_path is not None:
        warn_overridden_exclusion(cfg, exclusion)
    cfg = with_exclusion(cfg, exclusion)
    evaluation = run_evaluation(
        query, reference, method.methods(), cfg, criterion_m, exclude_metres
    )
    folder = write_result_dir(
        RESULTS_FAMILY, evaluation.folder_name, lambda f: write_results(f, evaluation, cfg), out
    )
    typer.echo(evaluation.header)
    typer.echo(format_table(evaluation.curves, evaluation.matches))
    typer.echo(f"wrote {folder}")


@dataclass(frozen=True)
class Evaluation:
    """Everything one `pr` run measured.

    Attributes:
        query: the query frames; map_frames: the frames matched against (the same in
            intra-session mode).
        mode: "intra" or "multi".
        exclusion: the frame and time window used by the recognizers and the truth.
        criterion_m: revisit criterion [m].
        matches: each method's best candidates; curves: each method's PR curve.
        exclude_metres: the distance window [m] (intra-session; 0 none).
        standing: intra-session queries counted as standing (`radar_slam.placerec`).
    """

    query: EvaluatedFrames
    map_frames: EvaluatedFrames
    mode: Mode
    exclusion: ExclusionConfig
    criterion_m: float
    matches: dict[str, BestMatches]
    curves: dict[str, PRCurve]
    exclude_metres: float = 0.0
    standing: int = 0

    @property
    def folder_name(self) -> str:
        name = spec_name(self.query.sequence)
        return name if self.mode == "intra" else f"{name}_vs_{self.map_frames.sequence.name}"

    @property
    def title(self) -> str:
        """Short figure title: the sequence, or `query vs map`."""
        seq, ref = self.query.sequence, self.map_frames.sequence
        if self.mode == "intra":
            return spec_name(seq)
        if ref.family == seq.family:
            return f"{seq.family}: {seq.name} vs {ref.name}"
        return f"{spec_name(seq)} vs {spec_name(ref)}"

    @property
    def header(self) -> str:
        """One line saying what was evaluated."""
        text = f"{self.mode}-session PR of {self.title}; criterion {self.criterion_m:g} m"
        if self.mode == "intra":
            text += f", {self.exclusion.recent_keyframes} most recent frames excluded"
            if self.exclusion.recent_seconds > 0:
                text += f" and those within {self.exclusion.recent_seconds:g} s"
            if self.exclude_metres > 0:
                text += f" and those within {self.exclude_metres:g} m of travel"
            text += f"; {self.standing} standing queries"
        return text

    def settings(self) -> dict[str, object]:
        """The evaluation settings recorded with each method in pr.json."""
        return {
            "mode": self.mode,
            "sequence": spec_name(self.query.sequence),
            "map": spec_name(self.map_frames.sequence),
            "criterion_m": self.criterion_m,
            "exclude_recent": self.exclusion.recent_keyframes,
            "exclude_seconds": self.exclusion.recent_seconds,
            "exclude_metres": self.exclude_metres,
            "standing_queries": self.standing,
            "standing_rule": STANDING_RULE,
        }


def run_evaluation(
    query: EvaluatedFrames,
    reference: EvaluatedFrames | None,
    methods: tuple[str, ...],
    cfg: RaPlaceConfig,
    criterion_m: float,
    exclude_metres: float = 0.0,
) -> Evaluation:
    """Run the recognizers over the frames and evaluate them.

    Intra-session when `reference` is None: each query against the earlier frames outside the
    exclusion window of `cfg` and, when `exclude_metres` > 0, at least that much ground-truth
    travel behind it. Otherwise every frame of `reference` is inserted first and the queries
    are matched against all of it.
    """
    label = spec_name(query.sequence)
    exclusion = cfg.retrieval.exclusion
    mode: Mode
    standing = 0
    if reference is None:
        times_s = query.timestamps_ns.astype(np.float64) / NS_PER_S
        travelled = path_length_m(query.xy)
        counts = intra_session_candidate_counts(times_s, exclusion, travelled, exclude_metres)
        standing = int(standing_queries(times_s, exclusion, travelled, criterion_m).sum())
        runs = method_runs(methods, with_exclusion(cfg, NO_EXCLUSION))
        matches = match_intra_session(query.frames(f"pr {label}"), runs, counts)
        map_frames, mode = query, "intra"
    else:
        exclude_metres = 0.0  # every map frame is a candidate
        runs = method_runs(methods, cfg)
        build_map(reference.frames(f"map {spec_name(reference.sequence)}"), runs)
        matches = match_queries(query.frames(f"query {label}"), runs)
        counts = np.full(len(query), len(reference), dtype=np.int64)
        map_frames, mode = reference, "multi"
    curves = {
        m: evaluate_matches(matches[m], query.xy, map_frames.xy, counts, criterion_m)
        for m in methods
    }
    return Evaluation(
        query, map_frames, mode, exclusion, criterion_m, matches, curves, exclude_metres, standing
    )


def write_results(folder: Path, evaluation: Evaluation, cfg: RaPlaceConfig) -> None:
    """config.yaml, pr.json, matches.csv, pr_curve.png and summary.txt into `folder`."""
    write_yaml(cfg, folder / "config.yaml")
    settings = evaluation.settings()
    report = {
        m: method_summary(curve, evaluation.matches[m], settings)
        for m, curve in evaluation.curves.items()
    }
    (folder / "pr.json").write_text(compact_json(report) + "\n")
    write_matches(
        folder / "matches.csv",
        evaluation.matches,
        evaluation.query.timestamps_ns,
        evaluation.map_frames.timestamps_ns,
    )
    labelled = {
        f"{METHOD_LABELS[m]} (max F1 {c.max_f1:.2f}, AUC {c.auc:.2f})": (c.precision, c.recall)
        for m, c in evaluation.curves.items()
    }
    title = f"{evaluation.title}, {evaluation.criterion_m:g} m criterion"
    plot_pr_curves(folder / "pr_curve.png", labelled, title=title)
    table = format_table(evaluation.curves, evaluation.matches)
    (folder / "summary.txt").write_text(f"{evaluation.header}\n{table}\n")


def register(app: typer.Typer) -> None:
    """Add the `pr` command to `app`."""
    app.command("pr")(pr_command)
