"""Maps damaged in content but freshly checksummed (NaN poses, an edge to a keyframe that does
not exist, settings out of range) are refused by every command that reads a map, with one line
naming the file and the key, before any work; `map info --json` is strict JSON."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Callable
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from bad_input_support import assert_refused, run_cli

from radar_slam.datasets.frame import RadarSequence
from radar_slam.maps.format import (
    EDGE_DTYPE,
    KEYFRAME_DTYPE,
    MANIFEST_FILE,
    META_FILE,
    Map,
    Session,
    write_map,
)
from raplace import DescriptorExtractor

KEYFRAMES = 5


def small_map(**changes: object) -> Map:
    """A sound five-keyframe map on a straight line (placeholder images and descriptors)."""
    keyframes = np.zeros(KEYFRAMES, dtype=KEYFRAME_DTYPE)
    keyframes["scan"] = np.arange(KEYFRAMES) * 4
    keyframes["timestamp_ns"] = np.arange(KEYFRAMES) * 1_000_000_000
    keyframes["pose"][:, 0] = np.arange(KEYFRAMES) * 4.0
    keyframes["gt_pose"] = np.nan
    keyframes["image_scale"] = 1.0
    edges = np.zeros(KEYFRAMES - 1, dtype=EDGE_DTYPE)
    edges["i"] = np.arange(KEYFRAMES - 1)
    edges["j"] = edges["i"] + 1
    edges["measurement"][:, 0] = 4.0
    edges["information"][:] = (100.0, 0, 0, 100.0, 0, 1000.0)
    the_map = Map(
        keyframes=keyframes,
        descriptors=np.zeros((KEYFRAMES, 4, 4), dtype=np.float16),
        images=tuple(b"png" for _ in range(KEYFRAMES)),
        edges=edges,
        sessions=(Session("synthetic/tiny", 20, 0, 19, "origin"),),
        settings={"keyframe_spacing_m": 4.0},
    )
    return dataclasses.replace(the_map, **changes)  # type: ignore[arg-type]


def _nan_pose() -> Map:
    m = small_map()
    m.keyframes["pose"][2, 1] = np.nan
    return m


def _edge_to_nowhere() -> Map:
    m = small_map()
    edges = np.concatenate([m.edges, m.edges[:1]])
    edges["j"][-1] = 9999
    return dataclasses.replace(m, edges=edges)


DAMAGE: dict[str, tuple[Callable[[], Map], list[str]]] = {
    "NaN keyframe pose": (_nan_pose, ["keyframes.npy", "keyframe 2", "non-finite pose"]),
    "edge to keyframe 9999": (_edge_to_nowhere, ["edges.npy", "9999"]),
    "negative keyframe spacing": (
        lambda: small_map(settings={"keyframe_spacing_m": -4}),
        ["map.json", "keyframe_spacing_m"],
    ),
    "image geometry out of range": (
        lambda: small_map(settings={"image": {"cell_m": 0}}),
        ["map.json", "settings.image.cell_m"],
    ),
    "infinite GT alignment": (
        lambda: small_map(gt_alignment=np.array([0.0, 1.0, 0.0])),
        ["map.json", "gt_alignment"],
    ),
}


def rewrite_with_checksum(folder: Path, name: str, data: bytes) -> None:
    """Replace a map file and its manifest entry, as a careless tool would."""
    (folder / name).write_bytes(data)
    manifest_path = folder / MANIFEST_FILE
    manifest = json.loads(manifest_path.read_text())
    manifest["files"][name] = {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    manifest_path.write_text(json.dumps(manifest))


@pytest.mark.parametrize("command", ["map info", "map info --json", "localize", "run --map"])
@pytest.mark.parametrize("damage", list(DAMAGE))
def test_map_damaged_in_content_is_refused_before_any_work(
    damage: str,
    command: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    make, expected = DAMAGE[damage]
    folder = workdir / "map"
    write_map(folder, make())
    if damage == "infinite GT alignment":  # JSON itself cannot say inf; Python's reader can
        text = (folder / META_FILE).read_text().replace("1.0", "Infinity")
        rewrite_with_checksum(folder, META_FILE, text.encode())
    root: list[str | Path] = ["--data-root", synthetic_root]
    args: list[str | Path] = {
        "map info": ["map", "info", folder],
        "map info --json": ["map", "info", folder, "--json"],
        "localize": ["localize", "synthetic/tiny", "--map", folder, *root],
        "run --map": ["run", "synthetic/tiny", "--map", folder, *root],
    }[command]
    assert_refused(capsys, (workdir, synthetic_root), args, str(folder), *expected)


def test_map_info_json_is_strict_json(workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = workdir / "map"
    write_map(folder, small_map())
    outcome = run_cli(capsys, "map", "info", folder, "--json")
    assert outcome.code == 0, outcome.stderr
    info = json.loads(outcome.stdout, parse_constant=lambda name: pytest.fail(name))
    assert info["extent_m"] == [16.0, 0.0]


def test_queries_of_a_map_use_the_descriptor_it_was_made_with() -> None:
    """A map made with n_theta 60 is queried with 60; one that records no descriptor settings,
    with the loop closer's."""
    from radar_slam.loops.config import LOOP_RAPLACE
    from radar_slam.maps.localizer import descriptor_config_of

    assert descriptor_config_of(small_map(settings={"descriptor": {"n_theta": 60}})).n_theta == 60
    assert descriptor_config_of(small_map(settings={})) == LOOP_RAPLACE.descriptor


@pytest.mark.parametrize(
    ("setting", "expected"),
    [
        ({"n_theta": 60}, "settings.descriptor.n_theta is 60, a run describes scans with 120"),
        ({"image": {"cell_m": 0.5}}, "settings.descriptor.image.cell_m is 0.5, a run"),
    ],
)
def test_run_refuses_a_map_described_otherwise_before_any_work(
    setting: dict[str, object],
    expected: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A session joins a map by comparing descriptors and adds its own to it: a map whose
    descriptors a run does not make is refused (one line naming the file and the key), before
    any scan is read or described."""
    folder = workdir / "map"
    write_map(folder, small_map(settings={"keyframe_spacing_m": 4.0, "descriptor": setting}))
    args: list[str | Path] = ["run", "synthetic/tiny", "--map", folder]
    args += ["--data-root", synthetic_root]
    with mock.patch.object(
        DescriptorExtractor, "__call__", autospec=True, side_effect=DescriptorExtractor.__call__
    ) as described:
        assert_refused(capsys, (workdir, synthetic_root), args, f"{folder}: map.json", expected)
    assert described.call_count == 0
