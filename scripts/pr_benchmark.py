"""Place-recognition benchmark on the synthetic scenarios: runs `radar-slam pr`, prints a table.

Runs RaPlace and Scan Context on
- synthetic/loop and synthetic/reverse: intra-session loop detection (50 most recent frames
  excluded);
- synthetic/multisession_b queried against synthetic/multisession_a (multi-session);
- optionally synthetic/long,
at the given revisit criteria, and prints a Markdown table with the bars
(RaPlace max F1 >= 0.9 on loop and reverse at 20 m and above Scan Context on reverse;
>= 0.85 multi-session). Sequences are generated on first use into the data root
($RADAR_SLAM_DATA) and reused afterwards. `--write-doc` writes the summary (max F1 / AUC at
20 m) into docs/benchmarks.md; `--docs` copies the reverse-direction PR curve to docs/.

Usage: python scripts/pr_benchmark.py [--scenarios loop reverse multisession] [--criteria 20]
           [--config FILE] [--out DIR] [--docs] [--write-doc]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from radar_slam.cli import main as cli_main

PROJECT = Path(__file__).resolve().parents[1]
DOCS = PROJECT / "docs"
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
PINNED_FLAG = "PR_BENCHMARK_ONE_THREAD"
METHOD_NAMES = {"raplace": "RaPlace", "scancontext": "Scan Context"}


@dataclass(frozen=True)
class Case:
    """One benchmark run: the query sequence, the map (None: intra-session), the bar."""

    name: str
    sequence: str
    map_sequence: str | None
    bar_f1: float | None


CASES = {
    "loop": Case("loop", "synthetic/loop", None, 0.9),
    "reverse": Case("reverse", "synthetic/reverse", None, 0.9),
    "multisession": Case(
        "multisession", "synthetic/multisession_b", "synthetic/multisession_a", 0.85
    ),
    "long": Case("long", "synthetic/long", None, None),
}
BAR_CRITERION_M = 20.0


def single_threaded() -> None:
    """Re-execute with single-threaded BLAS (its thread count is read when numpy loads)."""
    if os.environ.get(PINNED_FLAG) != "1":
        env = dict(os.environ, **{name: "1" for name in (PINNED_FLAG, *THREAD_VARIABLES)})
        os.execve(sys.executable, [sys.executable, *sys.argv], env)


def run_case(
    case: Case, criterion_m: float, out: Path, config: Path | None, max_frames: int | None
) -> dict:
    """Run `radar-slam pr` for one case; returns its pr.json."""
    argv = ["pr", case.sequence, "--criterion", f"{criterion_m:g}", "--out", str(out)]
    if case.map_sequence is not None:
        argv += ["--map", case.map_sequence]
    if config is not None:
        argv += ["--config", str(config)]
    if max_frames is not None:
        argv += ["--max-frames", str(max_frames)]
    code = cli_main(argv)
    if code != 0:
        raise SystemExit(f"radar-slam {' '.join(argv)} failed with exit code {code}")
    return json.loads((out / "pr.json").read_text())


def table_rows(case: Case, criterion_m: float, report: dict) -> list[str]:
    rows = []
    for method, entry in report.items():
        bar = ""
        if method == "raplace" and case.bar_f1 is not None and criterion_m == BAR_CRITERION_M:
            verdict = "pass" if entry["max_f1"] >= case.bar_f1 else "FAIL"
            bar = f">= {case.bar_f1:.2f}: {verdict}"
        mode = "intra" if case.map_sequence is None else "multi"
        seconds = entry["seconds"]
        rows.append(
            f"| {case.name} ({mode}) | {criterion_m:g} | {METHOD_NAMES[method]} | "
            f"{entry['queries']} | {entry['true_revisits']} | {entry['auc']:.3f} | "
            f"{entry['max_f1']:.3f} | {entry['recall_at_1']:.3f} | {seconds:.1f} | "
            f"{entry['ms_per_frame']:.1f} | {bar} |"
        )
    if case.name == "reverse" and criterion_m == BAR_CRITERION_M and len(report) == 2:
        better = report["raplace"]["max_f1"] > report["scancontext"]["max_f1"]
        rows.append(
            f"| reverse: RaPlace F1 > Scan Context | | | | | | | | | | "
            f"{'pass' if better else 'FAIL'} |"
        )
    return rows


def summary_row(case: Case, report: dict) -> str:
    """One line of the summary table: max F1 / AUC of each method."""
    label = f"`{case.sequence}`"
    if case.map_sequence is not None:
        label += f" against `{case.map_sequence}`"
    cells = [
        f"{report[m]['max_f1']:.3f} / {report[m]['auc']:.3f}" if m in report else "n/a"
        for m in METHOD_NAMES
    ]
    return f"| {label} | " + " | ".join(cells) + " |"


DOC_SECTION = "Place recognition"
"""The section of docs/benchmarks.md this script writes with `--write-doc`."""
DOC_CURVE = "reverse"
"""The scenario whose PR curve `--docs` copies to docs/ (the one docs/benchmarks.md shows)."""


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenarios", nargs="+", default=["loop", "reverse", "multisession"], choices=CASES
    )
    parser.add_argument("--criteria", nargs="+", type=float, default=[BAR_CRITERION_M])
    parser.add_argument("--config", type=Path, default=None, help="raplace YAML overrides")
    parser.add_argument("--max-frames", type=int, default=None)
    parser.add_argument("--out", type=Path, default=None, help="folder for the pr results")
    parser.add_argument(
        "--docs", action="store_true", help=f"copy the {DOC_CURVE} PR curve to docs/"
    )
    parser.add_argument("--write-doc", action="store_true", help="write docs/benchmarks.md")
    args = parser.parse_args(argv)
    single_threaded()
    root = args.out or Path("results") / "pr_benchmark" / datetime.now().strftime("%Y%m%d_%H%M%S")
    lines = [
        "| scenario | criterion [m] | method | queries | revisits | AUC | max F1 | recall@1 | "
        "seconds | ms/frame | bar |",
        "| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |",
    ]
    summary = []
    for name in args.scenarios:
        case = CASES[name]
        for criterion_m in args.criteria:
            out = root / f"{name}_{criterion_m:g}m"
            report = run_case(case, criterion_m, out, args.config, args.max_frames)
            lines += table_rows(case, criterion_m, report)
            if criterion_m == BAR_CRITERION_M:
                summary.append(summary_row(case, report))
                if args.docs and name == DOC_CURVE:
                    DOCS.mkdir(exist_ok=True)
                    shutil.copyfile(out / "pr_curve.png", DOCS / f"pr_{name}.png")
    print("\n".join(lines))
    if args.write_doc and summary:
        from benchmark_doc import update_section

        header = "| sequence | RaPlace max F1 / AUC | Scan Context max F1 / AUC |\n|---|---|---|"
        intro = f"At the {BAR_CRITERION_M:g} m revisit criterion."
        table = f"{intro}\n\n{header}\n" + "\n".join(summary)
        update_section(DOC_SECTION, table, script="scripts/pr_benchmark.py")
    print(
        f"\nresults in {root}; seconds and ms/frame: descriptors, insertions and queries of "
        "every scan (map scans included), one thread, PNG reading excluded"
    )


if __name__ == "__main__":
    main()
