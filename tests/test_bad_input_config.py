"""Bad configuration files: one line naming the file and the key path, exit code 1, no traceback,
nothing written (the tree is compared before and after), before any scan is read."""

from __future__ import annotations

from pathlib import Path

import pytest
from bad_input_support import (
    assert_refused,
)

from radar_slam.datasets.frame import RadarSequence

CONFIG_CASES = [
    # (YAML text, text the message must contain besides the file name)
    ("odometry: {keyframe: {max_translation_m: -1}}", "odometry.keyframe.max_translation_m"),
    ("odometry: {keyframe: {max_translation_m: 0}}", "odometry.keyframe.max_translation_m"),
    ("odometry: {keyframe: {max_translation_m: .nan}}", "odometry.keyframe.max_translation_m"),
    ("odometry: {keyframe: {max_frames: 0}}", "odometry.keyframe.max_frames"),
    ("loop_closure: {query_spacing_m: -4}", "loop_closure.query_spacing_m"),
    ("loop_closure: {query_spacing_m: .nan}", "loop_closure.query_spacing_m"),
    ("loop_closure: {query_spacing_m: .inf}", "loop_closure.query_spacing_m"),
    ("odometry: {preprocess: {bin_size_m: 0}}", "odometry.preprocess.bin_size_m"),
    ("odometry: {preprocess: {bin_size_m: -0.2}}", "odometry.preprocess.bin_size_m"),
    ("odometry: {preprocess: {bin_size_m: .nan}}", "odometry.preprocess.bin_size_m"),
    ("odometry: {preprocess: {min_range_m: 200}}", "odometry.preprocess.min_range_m"),
    ("odometry: {preprocess: {min_range_m: 20, max_range_m: 10}}", "max_range_m"),
    ("loop_closure: {candidates: 0}", "loop_closure.candidates"),
    (
        "loop_closure: {verification: {max_translation_m: 0}}",
        "loop_closure.verification.max_translation_m",
    ),
    (
        "loop_closure: {verification: {min_refined_quality: -1}}",
        "loop_closure.verification.min_refined_quality",
    ),
    ("loop_closure: {consistency: {min_support: -1}}", "loop_closure.consistency.min_support"),
    ("loop_closure: {throttle: {closed_spacing_m: -1}}", "loop_closure.throttle.closed_spacing_m"),
    ("maps: {keyframe_spacing_m: 0}", "maps.keyframe_spacing_m"),
    ("maps: {localization: {lost_after_m: 0}}", "maps.localization.lost_after_m"),
    ("dataset: {range_resolution_m: 0}", "dataset.range_resolution_m"),
    ("dataset: {range_resolution_m: -0.05}", "dataset.range_resolution_m"),
    ("dataset: {scan_rate_hz: 0}", "dataset.scan_rate_hz"),
    ("odometry: {coarse: {cell_m: 0}}", "odometry.coarse.cell_m"),
    ("odometry: {fine: {cell_m: -1}}", "odometry.fine.cell_m"),
    ("odometry: {coarse: {size_px: 256}}", "key 'size_px' is gone: now a constant"),
    ("odometry: {quality: {min_sigma_xy_m: 0.1}}", "MIN_SIGMA_XY_M"),
    ("loop_closure: {raplace: {pose: {n_theta: 5}}}", "loop_closure: key 'raplace' is gone"),
    ("odometry: {rotation: {n_angles: 720}}", "unknown key 'rotation'"),
    ("odometry: {quality: {sigma_scale: 0}}", "odometry.quality.sigma_scale"),
    ("odometry: {deskew: {enabled: false}}", "odometry.deskew: is now a bool, not a mapping"),
    ("graph: {loop_kernel: tukey}", "graph.loop_kernel"),
    ("graph: {loop_kernel_width: 0}", "graph.loop_kernel_width"),
    ("graph: {prior_sigmas: [1, 0, 1]}", "graph: key 'prior_sigmas' is gone"),
    # the strict reader's own checks: unknown keys, wrong types, bad YAML
    ("odometry: {keyframe: {max_distanc: 3}}", "odometry.keyframe: unknown key 'max_distanc'"),
    ("odometry: {keyframe: {max_frames: many}}", "odometry.keyframe.max_frames"),
    ("odometry: {keyframe: {max_frames: 2.5}}", "odometry.keyframe.max_frames"),
    ("odometry: [1, 2]", "odometry"),
    ("- just\n- a list\n", "top level must be a mapping"),
    ("odometry: {keyframe: [unclosed\n", "not valid YAML"),
    # a key given twice, at the top level and inside a section
    ("graph: {}\nodometry: {}\ngraph: {loop_kernel: huber}\n", "'graph' is given twice"),
    (
        "odometry:\n  keyframe: {max_frames: 2}\n  keyframe: {max_frames: 3}\n",
        "'keyframe' is given twice",
    ),
    ("odometry: {keyframe: {max_frames: 2, max_frames: 3}}", "'max_frames' is given twice"),
]


@pytest.mark.parametrize(("text", "key"), CONFIG_CASES)
def test_bad_config_is_one_line_and_writes_nothing(
    text: str,
    key: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    config = workdir / "bad.yaml"
    config.write_text(text)
    args: list[str | Path] = ["run", "synthetic/tiny", "--config", config]
    assert_refused(
        capsys, (workdir, synthetic_root), [*args, "--data-root", synthetic_root], "bad.yaml", key
    )


def test_non_utf8_config(
    tiny: RadarSequence, synthetic_root: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = workdir / "latin1.yaml"
    config.write_bytes("odometry: {keyframe: {max_frames: 3}}  # \xe9t\xe9\n".encode("latin-1"))
    args: list[str | Path] = ["odometry", "synthetic/tiny", "--config", config]
    assert_refused(
        capsys,
        (workdir, synthetic_root),
        [*args, "--data-root", synthetic_root],
        "latin1.yaml",
        "UTF-8",
    )


@pytest.mark.parametrize("command", ["run", "odometry", "loops"])
def test_config_errors_of_every_command_name_the_file(
    command: str,
    tiny: RadarSequence,
    synthetic_root: Path,
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    config = workdir / "neg.yaml"
    config.write_text("odometry: {preprocess: {bin_size_m: -1}}\n")
    graph = workdir / "in.g2o"
    graph.write_text("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n")
    head = [command, graph] if command == "loops" else [command]
    tail = ["--out", workdir / "out.g2o"] if command == "loops" else []
    args = [*head, "synthetic/tiny", "--config", config, "--data-root", synthetic_root, *tail]
    expected = ("neg.yaml", "odometry.preprocess.bin_size_m", "-1")
    assert_refused(capsys, (workdir, synthetic_root), args, *expected)


def test_pr_config_error_names_file_and_key(
    tiny: RadarSequence, synthetic_root: Path, workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = workdir / "pr.yaml"
    config.write_text("retrieval: {loop_threshold: -1}\n")
    args: list[str | Path] = ["pr", "synthetic/tiny", "--config", config]
    args += ["--data-root", synthetic_root]
    assert_refused(capsys, (workdir, synthetic_root), args, "pr.yaml", "retrieval.loop_threshold")
