"""How alike simulated places are, against the real drive, for a scenario with changed settings.

Renders every `--step`-th scan of a simulated scenario in memory (nothing is written), with
town and object settings overridden from the command line, and compares the RaPlace distances
of its non-revisits (pairs more than 50 m apart) with those of the real RADIATE Edinburgh drive
(`scripts/pr_real.py`): the two-sample Kolmogorov-Smirnov distance says how much easier the
simulated places are to tell apart. It also prints the pixel statistics of a few of the
rendered scans (tests/test_sim_stats.py bands them against the real MulRan scan), so that a
world that looks more like the real one in the descriptor does not drift away from it in the
raw intensities.

A town's random layout moves the distance by several hundredths: compare settings over a few
`--seed`s.

Usage: python scripts/sim_confusability.py loop [--step 4] [--seed 11]
       [--set town.block_size_m=(120.0,190.0) ...] [--real-cache real.npy]
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
from bench_real import DEFAULT_ROOT
from numpy.typing import NDArray
from pr_real import gnss_positions, non_revisit_distances
from scipy import stats

from radar_slam.sim.generate import build_scene, make_renderer, render_frame
from radar_slam.sim.scenarios import Scenario, get_scenario
from raplace import DescriptorExtractor, RaPlaceConfig

STATS_SCANS = 6
"""Scans (spread over the drive) whose pixel statistics are printed."""
QUANTILES = (0.05, 0.5, 0.95)


def overridden(scenario: Scenario, settings: list[str]) -> Scenario:
    """`scenario` with `section.key=value` settings (section `town` or `objects`) replaced."""
    sections: dict[str, dict[str, Any]] = {"town": {}, "objects": {}}
    for setting in settings:
        key, _, value = setting.partition("=")
        section, _, name = key.partition(".")
        if section not in sections or not name or not value:
            raise SystemExit(f"--set {setting!r}: expected town.<key>=<value> or objects.<...>")
        sections[section][name] = ast.literal_eval(value)
    return dataclasses.replace(
        scenario,
        town=dataclasses.replace(scenario.town, **sections["town"]),
        objects=dataclasses.replace(scenario.objects, **sections["objects"]),
    )


def real_distances(root: Path, cache: Path | None) -> NDArray[np.float64]:
    """RaPlace distances of the real drive's non-revisits (read from / written to `cache`)."""
    if cache is not None and cache.exists():
        return np.asarray(np.load(cache), dtype=np.float64)
    sequence, xy, _ = gnss_positions(root)
    extract = DescriptorExtractor(RaPlaceConfig().descriptor)
    known = np.flatnonzero(np.isfinite(xy[:, 0]))
    frames = (sequence[int(i)] for i in known)
    described = np.stack([extract(f.polar, f.azimuths_rad, f.range_resolution_m) for f in frames])
    distances = non_revisit_distances(described, xy[known])
    if cache is not None:
        np.save(cache, distances)
    return distances


def simulated(scenario: Scenario, seed: int | None, step: int) -> tuple[NDArray, NDArray]:
    """(RaPlace distances of the non-revisits among every `step`-th scan, (STATS_SCANS,
    n_azimuths, n_bins) uint8 scans spread over the drive)."""
    scene = build_scene(scenario, seed)
    renderer = make_renderer(scene)
    extract = DescriptorExtractor(RaPlaceConfig().descriptor)
    azimuths = scenario.sensor.azimuths_ccw_rad()
    resolution = scenario.sensor.range_resolution_m
    frames = np.arange(0, scene.n_frames, step)
    kept = set(frames[np.linspace(0, len(frames) - 1, STATS_SCANS).astype(int)].tolist())
    described, scans = [], []
    for index in frames:
        scan = render_frame(scene, renderer, int(index))
        described.append(extract(scan, azimuths, resolution))
        if int(index) in kept:
            scans.append(scan)
    xy = scene.base_poses(scene.scan_end_offsets_ns(scene.n_frames)[frames])[:, :2]
    return non_revisit_distances(np.stack(described), xy), np.stack(scans)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", help="simulated scenario, e.g. loop")
    parser.add_argument("--step", type=int, default=4, help="render every step-th scan")
    parser.add_argument("--seed", type=int, default=None, help="town seed (scenario's default)")
    parser.add_argument("--set", action="append", default=[], help="town.<key>=<value> ...")
    parser.add_argument("--data-root", type=Path, default=DEFAULT_ROOT, help="real data root")
    parser.add_argument("--real-cache", type=Path, default=None, help="real distances (.npy)")
    args = parser.parse_args(argv)
    real = real_distances(args.data_root, args.real_cache)
    scenario = overridden(get_scenario(args.scenario), args.set)
    sim, scans = simulated(scenario, args.seed, args.step)
    fmt = ", ".join
    q_real = fmt(f"{v:.3f}" for v in np.quantile(real, QUANTILES))
    q_sim = fmt(f"{v:.3f}" for v in np.quantile(sim, QUANTILES))
    levels = np.percentile(scans.astype(np.float64), [50, 90, 99, 99.9])
    print(
        f"{args.scenario} (seed {args.seed if args.seed is not None else scenario.seed}, "
        f"every {args.step}th scan; {fmt(args.set) or 'default settings'}): "
        f"Kolmogorov-Smirnov distance {stats.ks_2samp(real, sim).statistic:.3f}; "
        f"non-revisit distances 5/50/95 %: real {q_real}, simulated {q_sim}; "
        f"pixels < 5: {(scans < 5).mean():.3f}, 50/90/99/99.9th percentiles "
        f"{'/'.join(f'{v:.0f}' for v in levels)}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
