"""One pass per command: `radar-slam run` reads each config file once and opens its sequence
once, for every dataset family, even when the family's shipped config sets a loader setting
(configs/oxford.yaml: the range resolution), and reads the scans it runs on once each;
`radar-slam batch` opens each sequence once per distinct loader setting of its grid (its
workers run on the opened sequence) and each run reads its scans once each."""

from __future__ import annotations

import shutil
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import pytest
from conftest import MULRAN_RAW, OXFORD_SEQ, SHARED_DATA
from distributed import LocalCluster
from real_layouts import write_boreas

from radar_slam.cli import main
from radar_slam.datasets import (
    BoreasSequence,
    MulRanSequence,
    OxfordSequence,
    RadiateSequence,
    open_sequence,
)
from radar_slam.pipeline import config as pipeline_config

MULRAN_SCAN = MULRAN_RAW / "polar" / "1564718976161407002.png"
MULRAN_PERIOD_NS = 250_000_000
RUN_SCANS = 5
"""Scans each run reads (every sample sequence has at least this many)."""


def synthetic_root(tmp: Path, synthetic_data: Path) -> tuple[Path, str]:
    return synthetic_data, "synthetic/tiny"


def mulran_root(tmp: Path, synthetic_data: Path) -> tuple[Path, str]:
    """The real MulRan scan under `RUN_SCANS` stamps, in the MulRan layout (no GT)."""
    scans = tmp / "mulran" / "KAIST01" / "sensor_data" / "radar" / "polar"
    scans.mkdir(parents=True)
    stamp = int(MULRAN_SCAN.stem)
    for k in range(RUN_SCANS):
        shutil.copyfile(MULRAN_SCAN, scans / f"{stamp + k * MULRAN_PERIOD_NS}.png")
    return tmp, "mulran/KAIST01"


def oxford_root(tmp: Path, synthetic_data: Path) -> tuple[Path, str]:
    return SHARED_DATA, f"oxford/{OXFORD_SEQ.name}"


def radiate_root(tmp: Path, synthetic_data: Path) -> tuple[Path, str]:
    return SHARED_DATA, "radiate/fog_6_0-partial"


def boreas_root(tmp: Path, synthetic_data: Path) -> tuple[Path, str]:
    write_boreas(OXFORD_SEQ, tmp / "boreas" / "boreas-2021-08-05-13-34")
    return tmp, "boreas/boreas-2021-08-05-13-34"


FAMILIES: dict[str, tuple[type, Callable[[Path, Path], tuple[Path, str]], str | None]] = {
    "synthetic": (MulRanSequence, synthetic_root, "synthetic.yaml"),
    "mulran": (MulRanSequence, mulran_root, "mulran.yaml"),
    "oxford": (OxfordSequence, oxford_root, "oxford.yaml"),
    "radiate": (RadiateSequence, radiate_root, None),
    "boreas": (BoreasSequence, boreas_root, None),
}
"""Family -> (its reader, where its sample sequence is, its shipped config file if any)."""


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_run_configures_and_opens_once_per_family(
    family: str, synthetic_root: Path, tmp_path: Path
) -> None:
    reader, place, shipped = FAMILIES[family]
    if family != "synthetic" and not SHARED_DATA.is_dir():
        pytest.skip(f"real radar samples not found at {SHARED_DATA}")
    if family == "synthetic":
        open_sequence("synthetic/tiny", synthetic_root)  # generated before counting
    root, spec = place(tmp_path / "data", synthetic_root)
    user = tmp_path / "user.yaml"
    user.write_text("loop_closure: {candidates: 3}\n")
    args = ["run", spec, "--out", str(tmp_path / "out"), "--config", str(user)]
    args += ["--max-frames", str(RUN_SCANS), "--data-root", str(root)]
    read_yaml = pipeline_config.read_yaml
    with (
        mock.patch.object(pipeline_config, "read_yaml", wraps=read_yaml) as reads,
        mock.patch.object(reader, "__init__", autospec=True, side_effect=reader.__init__) as opens,
        mock.patch.object(
            reader, "__getitem__", autospec=True, side_effect=reader.__getitem__
        ) as decodes,
    ):
        assert main(args) == 0
    read = Counter(Path(call.args[0]).name for call in reads.call_args_list)
    expected = Counter({"user.yaml": 1}) + Counter([shipped] if shipped else [])
    assert read == expected
    assert opens.call_count == 1
    assert Counter(int(call.args[1]) for call in decodes.call_args_list) == Counter(
        range(RUN_SCANS)
    )


BATCH_GRID = """configs:
  plain: {}
  fewer_candidates:
    loop_closure: {candidates: 3}
  late_truth:
    dataset: {gt_time_offset_s: 0.05}
"""
"""Three configurations: two share the loader settings, the third has its own."""


def test_batch_opens_each_sequence_once_per_loader_setting(
    synthetic_root: Path, tmp_path: Path
) -> None:
    open_sequence("synthetic/tiny", synthetic_root)  # generated before counting
    grid = tmp_path / "grid.yaml"
    grid.write_text(BATCH_GRID)
    user = tmp_path / "user.yaml"
    user.write_text("odometry: {keyframe: {max_translation_m: 2.0}}\n")
    out = tmp_path / "batch"
    args = ["batch", "synthetic/tiny", "--grid", str(grid), "--config", str(user)]
    args += ["--out", str(out), "--max-frames", str(RUN_SCANS), "--data-root", str(synthetic_root)]
    read_yaml = pipeline_config.read_yaml
    reader = MulRanSequence
    # Workers in this process, reached over TCP: each task's arguments are pickled and sent, as
    # to a worker process, and an opening or scan read in a worker is counted here.
    with (
        LocalCluster(
            n_workers=1, processes=False, protocol="tcp://", dashboard_address=None
        ) as cluster,
        mock.patch.object(pipeline_config, "read_yaml", wraps=read_yaml) as reads,
        mock.patch.object(reader, "__init__", autospec=True, side_effect=reader.__init__) as opens,
        mock.patch.object(
            reader, "__getitem__", autospec=True, side_effect=reader.__getitem__
        ) as decodes,
    ):
        assert main([*args, "--scheduler", cluster.scheduler_address]) == 0
    rows = (out / "summary.csv").read_text().splitlines()[1:]
    assert len(rows) == 3 and all(",ok," in row for row in rows)
    read = Counter(Path(call.args[0]).name for call in reads.call_args_list)
    assert read == Counter({"user.yaml": 1, "synthetic.yaml": 1})
    assert opens.call_count == 2
    scans = Counter(int(call.args[1]) for call in decodes.call_args_list)
    assert scans == Counter({index: 3 for index in range(RUN_SCANS)})
