"""`radar-slam loops GRAPH.g2o SEQ --out OUT.g2o`: our verified loops on another odometry's graph.

The input graph has one vertex per scan of SEQ (vertex ids increasing in scan order) and its own
odometry edges; the vertex poses serve as the odometry poses of the loop detector (spacing of
the database, de-skew velocity, consistency of loops). Verified loops are added as robust
between-factors, the graph is optimised (ISAM2, then the final pass of the graph config), and
written with the optimised vertex poses.
"""

from __future__ import annotations

from pathlib import Path

import typer

from radar_slam.commands.options import DATA_ROOT_OPTION, progress_bar
from radar_slam.errors import ResultsError
from radar_slam.g2o import read_g2o, write_pose_graph
from radar_slam.pipeline import close_loops_on_graph, open_configured
from radar_slam.results import check_output_file


def loops_command(
    graph: Path = typer.Argument(
        ..., help="Input pose graph (g2o VERTEX_SE2/EDGE_SE2), one vertex per scan.", dir_okay=False
    ),
    sequence: str = typer.Argument(
        ..., help="The sequence the graph was made from: family/name or a folder."
    ),
    out: Path = typer.Option(..., "--out", help="Output g2o file.", dir_okay=False),
    force: bool = typer.Option(False, "--force", help="Overwrite an existing --out file."),
    config: Path | None = typer.Option(
        None,
        "--config",
        help="YAML overrides applied on top of the defaults and configs/<family>.yaml.",
        exists=True,
        dir_okay=False,
    ),
    data_root: Path | None = DATA_ROOT_OPTION,
) -> None:
    """Add verified radar loop closures to a pose graph from another odometry and optimise it."""
    check_output_file(out, "--out", force)
    if out.resolve() == graph.resolve():
        raise ResultsError(f"{out}: would overwrite the input graph; choose another --out")
    record = read_g2o(graph)
    seq, settings = open_configured(sequence, data_root, config)
    with progress_bar(len(seq), f"{seq.family}/{seq.name}") as update:
        run = close_loops_on_graph(record, seq, settings, progress=update)
    write_pose_graph(out, run.graph)
    typer.echo(
        f"{seq.family}/{seq.name}: {len(record.vertices)} vertices, {len(record.edges)} edges in; "
        f"{len(run.loops)} verified loop proposals, {run.n_accepted} accepted; "
        f"{run.seconds:.1f} s"
    )
    if run.input_loops:
        typer.echo(
            f"input loops: {run.input_loops}, {run.input_loops_left_out} left out as inconsistent "
            "with the odometry (named in the warnings above)"
        )
    typer.echo(f"wrote {out}")


def register(app: typer.Typer) -> None:
    """Add the `loops` command to `app`."""
    app.command("loops")(loops_command)
