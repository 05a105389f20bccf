"""`radar-slam run SEQ` (full SLAM) and `radar-slam odometry SEQ` (odometry only).

Both write a result folder `results/<family>_<sequence>/<timestamp>/` (or `--out`, which must be
absent or empty) with a `latest` link, show a progress bar with frames/s, and print a short
summary. The files are listed in `radar_slam.outputs`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import typer

from radar_slam.commands.bag_options import (
    GT_TOPIC_OPTION,
    LAYOUT_OPTION,
    TOPIC_OPTION,
    bag_overrides,
)
from radar_slam.commands.options import (
    CONFIG_OPTION,
    DATA_ROOT_OPTION,
    MAX_FRAMES_OPTION,
    OUT_OPTION,
    RunProgress,
    progress_bar,
)
from radar_slam.datasets.frame import RadarSequence
from radar_slam.datasets.stride import strided
from radar_slam.evaluation.metrics import EVO_MODULES
from radar_slam.lazy import preload
from radar_slam.maps.build import build_map  # every run writes map/
from radar_slam.maps.format import Map, write_map
from radar_slam.maps.session import InterSessionQueries, join_session  # run --map
from radar_slam.maps.writers import write_joined
from radar_slam.outputs import (
    odometry_summary,
    slam_summary,
    write_odometry_results,
    write_results,
)
from radar_slam.pipeline import (
    Pipeline,
    PipelineConfig,
    Progress,
    ProgressCallback,
    Results,
    frame_count,
    open_configured,
    run_odometry,
)
from radar_slam.plots import MATPLOTLIB_MODULES
from radar_slam.results import check_output_root, check_result_location, write_result_dir
from radar_slam.viewer import SPAWN, RerunViewer, check_viewer_target, import_rerun

MAP_FOLDER = "map"
"""The map every SLAM run writes into its result folder (`radar_slam.maps`)."""
END_OF_RUN_MODULES = (*EVO_MODULES, *MATPLOTLIB_MODULES)
"""Loaded on a thread while the scans go by (`radar_slam.lazy.preload`): the evaluation and the
plots need them only after the last scan."""
SEQUENCE_ARGUMENT = typer.Argument(
    ...,
    help="Sequence: family/name (mulran/KAIST01, oxford/..., boreas/..., radiate/..., "
    "synthetic/loop), a folder, a ROS 1 .bag or a ROS 2 bag folder.",
)
MAP_OPTION = typer.Option(
    None,
    "--map",
    help="Extend this map (a run's map/): multi-session SLAM in the map's frame.",
    file_okay=False,
)
VIEWER_OPTION = typer.Option(  # live viewer
    None,
    "--viewer",
    help="Stream the run to Rerun: --viewer spawns the viewer, --viewer FILE.rrd saves a "
    "recording (needs the viewer extra: pip install 'radar-slam\\[viewer]').",
)
STRIDE_OPTION = typer.Option(  # strided view of the sequence
    1, "--stride", min=1, help="Use every K-th scan (4 Hz data at --stride 4 is 1 Hz)."
)


def preloaded_by_last_scan(
    progress: ProgressCallback, modules: tuple[str, ...]
) -> ProgressCallback:
    """`progress`, with `modules` loaded on a thread from now until the run reports the first
    step after its last scan (the report waits for the thread then: the evaluation and the
    plots import them next)."""
    loader = preload(modules)

    def report(update: Progress) -> None:
        if update.step:
            loader.join()
        progress(update)

    return report


def without_loops(config: PipelineConfig) -> PipelineConfig:
    """`config` with loop closing disabled (recorded as such in config.yaml)."""
    loop_closure = dataclasses.replace(config.loop_closure, enabled=False)
    return dataclasses.replace(config, loop_closure=loop_closure)


def run_command(
    sequence: str = SEQUENCE_ARGUMENT,
    out: Path | None = OUT_OPTION,
    config: Path | None = CONFIG_OPTION,
    max_frames: int | None = MAX_FRAMES_OPTION,
    stride: int = STRIDE_OPTION,
    no_loops: bool = typer.Option(
        False, "--no-loops", help="Odometry and pose graph only, no loop closing."
    ),
    data_root: Path | None = DATA_ROOT_OPTION,
    topic: str | None = TOPIC_OPTION,  # ROS bag input and live viewer
    gt_topic: str | None = GT_TOPIC_OPTION,
    layout: str | None = LAYOUT_OPTION,
    viewer: str | None = VIEWER_OPTION,
    map_path: Path | None = MAP_OPTION,
) -> None:
    """Radar SLAM: odometry, verified RaPlace loop closures, GTSAM pose graph; writes results."""
    check_output_root(out)
    if viewer is not None:  # fail before any work: rerun-sdk missing, no display, bad file
        import_rerun()
        check_viewer_target(viewer)
    prior_map = None if map_path is None else Map.load(map_path)
    bag_options = bag_overrides(topic, gt_topic, layout)
    seq, settings = open_configured(sequence, data_root, config, bag_options)
    seq = strided(seq, stride)
    check_result_location(seq.family, seq.name, out)  # before the run, not after it
    if no_loops:
        settings = without_loops(settings)
    total = frame_count(seq, max_frames)
    observer = None if viewer is None else RerunViewer(viewer, f"{seq.family}/{seq.name}")
    queries = None  # run --map: a map the session cannot join is refused before the run
    if prior_map is not None and map_path is not None:
        queries = InterSessionQueries(prior_map, settings, map_path)
    with progress_bar(total, f"{seq.family}/{seq.name}") as bar:  # until map/ is written
        try:
            results = Pipeline(
                seq,
                settings,
                max_frames=max_frames,
                progress=preloaded_by_last_scan(bar, END_OF_RUN_MODULES),
                observer=observer,
                record_map=True,  # map/ is written from what the run keeps
                on_keyframe=queries,  # run --map: each keyframe looked up in the map
            ).run()
        except BaseException:
            if observer is not None:
                observer.abandon()
            raise
        folder, results, joined_text = write_run(seq, results, prior_map, queries, out, bar)
    typer.echo(slam_summary(results), nl=False)
    typer.echo(joined_text, nl=False)  # run --map
    typer.echo(f"results in {folder}")
    if viewer is not None and viewer != SPAWN:
        typer.echo(f"viewer recording in {viewer}")


def write_run(
    seq: RadarSequence,
    results: Results,
    prior_map: Map | None,
    queries: InterSessionQueries | None,
    out: Path | None,
    bar: RunProgress,
) -> tuple[Path, Results, str]:
    """Write the result folder of a finished run, map/ included (with `prior_map`: the session
    joined to it first, from the run's `queries` of it); returns the folder, the results written
    (in the map's frame when joined) and the text about the join ("" without)."""
    joined = None
    if prior_map is not None and queries is not None:
        bar.step("joining the map")
        joined = join_session(results, prior_map, queries)
    written = results if joined is None else joined.results  # in the map's frame
    joined_text: list[str] = []

    def write(folder: Path) -> None:
        bar.step("results")
        write_results(folder, written)
        bar.step("map")
        the_map = build_map(written) if joined is None else joined.map
        write_map(folder / MAP_FOLDER, the_map)
        if joined is not None:
            joined_text.append(write_joined(folder, joined))

    folder = write_result_dir(seq.family, seq.name, write, out)
    return folder, written, "".join(joined_text)


def odometry_command(
    sequence: str = SEQUENCE_ARGUMENT,
    out: Path | None = OUT_OPTION,
    config: Path | None = CONFIG_OPTION,
    max_frames: int | None = MAX_FRAMES_OPTION,
    stride: int = STRIDE_OPTION,
    data_root: Path | None = DATA_ROOT_OPTION,
    topic: str | None = TOPIC_OPTION,  # ROS bag input
    gt_topic: str | None = GT_TOPIC_OPTION,
    layout: str | None = LAYOUT_OPTION,
) -> None:
    """Phase-correlation radar odometry only; writes odometry.tum/.kitti and, with ground truth,
    metrics.json (ATE, KITTI drift) and trajectory.png."""
    check_output_root(out)
    bag_options = bag_overrides(topic, gt_topic, layout)
    seq, settings = open_configured(sequence, data_root, config, bag_options)
    seq = strided(seq, stride)
    check_result_location(seq.family, seq.name, out)
    total = frame_count(seq, max_frames)
    with progress_bar(total, f"{seq.family}/{seq.name}", loops=False) as update:
        run = run_odometry(seq, settings, max_frames=max_frames, progress=update)
    folder = write_result_dir(seq.family, seq.name, lambda f: write_odometry_results(f, run), out)
    typer.echo(odometry_summary(run), nl=False)
    typer.echo(f"results in {folder}")


def register(app: typer.Typer) -> None:
    """Add the `run` and `odometry` commands to `app`."""
    app.command("run")(run_command)
    app.command("odometry")(odometry_command)
