"""`radar-slam localize SEQ --map MAP` and `radar-slam map info MAP`.

The map is read and verified before anything else (a damaged or foreign folder is one line and
exit code 1). `localize` writes a result folder (`--out`, or
`results/<family>_<sequence>_localize/<timestamp>/`) with the files of `radar_slam.maps.writers`.
"""

from __future__ import annotations

import time
from pathlib import Path

import typer
from tqdm import tqdm

from radar_slam.commands.options import (
    CONFIG_OPTION,
    DATA_ROOT_OPTION,
    MAX_FRAMES_OPTION,
    OUT_OPTION,
)
from radar_slam.config import write_yaml
from radar_slam.maps.format import Map
from radar_slam.outputs import json_text
from radar_slam.pipeline import frame_count, ground_truth_of, open_configured, sequence_label
from radar_slam.results import check_output_root, check_result_location, write_result_dir

MAP_OPTION = typer.Option(
    ..., "--map", help="A map folder (the map/ of a `radar-slam run` result).", file_okay=False
)
map_app = typer.Typer(help="Inspect radar maps.", no_args_is_help=True)


def localize_command(
    sequence: str = typer.Argument(..., help="Sequence to localise: family/name or a folder."),
    map_path: Path = MAP_OPTION,
    out: Path | None = OUT_OPTION,
    config: Path | None = CONFIG_OPTION,
    max_frames: int | None = MAX_FRAMES_OPTION,
    data_root: Path | None = DATA_ROOT_OPTION,
) -> None:
    """Localise every scan of SEQ in MAP: global relocalisation, then tracking; writes
    localization.tum/.csv, localization_boreas.txt, a plot and, with ground truth, metrics.json."""
    # The localiser's modules load only for this command (not for every `radar-slam` call).
    from radar_slam.maps.evaluate import evaluate_localization
    from radar_slam.maps.localizer import Localization, Localizer
    from radar_slam.maps.writers import localization_summary, write_localization

    check_output_root(out)
    the_map = Map.load(map_path)
    seq, settings = open_configured(sequence, data_root, config)
    check_result_location(seq.family, f"{seq.name}_localize", out)  # before the work
    total = frame_count(seq, max_frames)
    localizer = Localizer(the_map, settings)
    fixes: list[Localization] = []
    start = time.perf_counter()
    with tqdm(total=total, desc=sequence_label(seq), unit="scan", dynamic_ncols=True) as bar:
        for index in range(total):
            fixes.append(localizer.localize(seq[index]))
            bar.update(1)
    seconds = time.perf_counter() - start
    gt_poses, _ = ground_truth_of(seq, total)
    metrics = None if gt_poses is None else evaluate_localization(fixes, gt_poses, the_map)

    def write(folder: Path) -> None:
        write_yaml(settings, folder / "config.yaml")
        write_localization(folder, sequence_label(seq), the_map, fixes, seconds, metrics)

    folder = write_result_dir(seq.family, f"{seq.name}_localize", write, out)
    typer.echo(localization_summary(sequence_label(seq), fixes, seconds, metrics), nl=False)
    typer.echo(f"results in {folder}")


@map_app.command("info")
def info_command(
    map_path: Path = typer.Argument(..., help="A map folder.", file_okay=False),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of text."),
) -> None:
    """Print a map's sessions, keyframes, extent, size and GT alignment."""
    from radar_slam.maps.writers import map_info

    info = map_info(map_path, Map.load(map_path))
    if as_json:
        typer.echo(json_text(info), nl=False)
        return
    alignment = info["gt_alignment"]
    lines = [f"map           {map_path}"]
    lines += [f"session       {s}" for s in info["sessions"]]
    lines += [
        f"keyframes     {info['keyframes']} ({info['edges']} graph edges)",
        f"extent        {info['extent_m'][0]:.0f} x {info['extent_m'][1]:.0f} m",
        f"size          {info['bytes'] / 1e6:.2f} MB ({info['bytes_per_keyframe'] / 1e3:.1f} kB "
        "per keyframe)",
        "GT alignment  "
        + (
            "none"
            if alignment is None
            else f"x {alignment[0]:.3f} m, y {alignment[1]:.3f} m, yaw {alignment[2]:.3f} deg"
        ),
    ]
    typer.echo("\n".join(lines))


def register(app: typer.Typer) -> None:
    """Add `localize` and the `map` group to `app`."""
    app.command("localize")(localize_command)
    app.add_typer(map_app, name="map")
