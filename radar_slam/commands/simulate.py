"""`radar-slam simulate SCENARIO --out DIR`: write a simulated Navtech sequence (MulRan layout)."""

from __future__ import annotations

from pathlib import Path

import typer
from tqdm import tqdm

from radar_slam.errors import ResultsError
from radar_slam.results import check_writable
from radar_slam.sim.scenarios import GROUPS, SCENARIOS, expand
from radar_slam.sim.writer import FIGURE_FILE, remove_simulated, simulator_files

FIGURE_NAME = str(FIGURE_FILE)


def _scenario_help() -> str:
    names = ", ".join(list(SCENARIOS) + [f"{g} (= {' + '.join(m)})" for g, m in GROUPS.items()])
    return f"Scenario: {names}."


def _prepare_out(out: Path, force: bool) -> None:
    """Fail before any work unless `out` can take the sequence: absent or empty, or with
    `force` a simulated sequence (complete or interrupted), whose files alone are deleted."""
    if out.exists() and not out.is_dir():
        raise ResultsError(f"{out}: exists and is not a folder; choose another --out")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise ResultsError(
                f"{out}: output folder exists and is not empty; choose another --out "
                "(or --force to replace a simulated sequence)"
            )
        if not simulator_files(out)[0]:
            raise ResultsError(f"{out}: is not a simulated sequence; --force does not replace it")
        check_writable(out, "the output folder")
        remove_simulated(out)  # refuses, deleting nothing, if a file is not the simulator's
    check_writable(out, "the output folder")


def simulate_command(
    scenario: str = typer.Argument(..., help=_scenario_help()),
    out: Path = typer.Option(
        ...,
        "--out",
        help="Sequence folder to create (must be absent or empty); a group writes "
        "one sub-folder per member.",
    ),
    seed: int | None = typer.Option(
        None, "--seed", min=0, help="Seed, a non-negative integer (default: the scenario's)."
    ),
    frames: int | None = typer.Option(
        None, "--frames", min=1, help="Number of scans (default: the whole route)."
    ),
    plot: bool = typer.Option(
        False, "--plot", help=f"Also write {FIGURE_NAME}: town map, trajectory and scans."
    ),
    force: bool = typer.Option(
        False, "--force", help="Replace a simulated sequence at --out (an interrupted one too)."
    ),
) -> None:
    """Simulate a scenario and write it in the MulRan layout (polar PNGs, global_pose.csv)."""
    # The generator loads only for this command (not for every `radar-slam` call).
    from radar_slam.sim.generate import build_scene, checked_frame_count, generate_sequence

    members = expand(scenario)
    grouped = len(members) > 1
    scenes = [build_scene(member, seed) for member in members]  # frame counts checked first
    for scene in scenes:
        checked_frame_count(scene, frames)
    if grouped and out.is_dir() and force:
        names = {member.name for member in members}
        strays = [p.name for p in out.iterdir() if p.name not in names]
        if strays:
            raise ResultsError(f"{out}: holds {strays[0]!r}, not a member of {scenario!r}")
        for member in members:
            _prepare_out(out / member.name, force)
    else:
        _prepare_out(out, force)
    for member, scene in zip(members, scenes, strict=True):
        folder = out / member.name if grouped else out
        with tqdm(desc=member.name, unit="scan", leave=False, disable=None) as bar:

            def advance(done: int, total: int, bar: tqdm = bar) -> None:
                bar.total = total
                bar.update(done - bar.n)

            summary = generate_sequence(
                member, folder, seed=seed, frames=frames, on_frame=advance, scene=scene
            )
        per_scan_ms = 1000 * (summary.seconds - summary.build_seconds) / summary.n_frames
        typer.echo(
            f"{member.name}: {summary.n_frames} scans, {summary.duration_s:.1f} s, "
            f"{summary.length_m:.0f} m -> {folder} ({summary.seconds:.1f} s: "
            f"{summary.build_seconds:.1f} s setup, {per_scan_ms:.0f} ms/scan)"
        )
        if plot:
            from radar_slam.sim.figure import save_overview  # matplotlib only when asked

            figure = folder / FIGURE_NAME
            save_overview(build_scene(member, seed), figure, n_frames=summary.n_frames)
            typer.echo(f"figure: {figure}")


def register(app: typer.Typer) -> None:
    """Add `simulate` to the CLI app."""
    app.command("simulate")(simulate_command)
