"""Maps: the on-disk format (round trip, integrity), keyframe images good enough to verify
loops, `map info`, and a `run` writing map/. Built from `synthetic/tiny_loop` (reduced bins)."""

from __future__ import annotations

import csv
import dataclasses
import json
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from odometry import OdometryConfig, preprocess_polar
from radar_slam.cli import main
from radar_slam.datasets import open_sequence
from radar_slam.datasets._png import _parse_chunks
from radar_slam.datasets.frame import RadarSequence
from radar_slam.loops import GeometricVerifier, KeyScan, LoopClosureConfig
from radar_slam.maps import ImageGeometry, KeyframeImager, Map, MapError, build_map
from radar_slam.maps.boreas import BOREAS_FILE, read_boreas
from radar_slam.maps.build import select_keyframes
from radar_slam.maps.evaluate import evaluate_localization
from radar_slam.maps.format import DATA_FILES, MANIFEST_FILE, encode_map
from radar_slam.maps.images import SCALE_PERCENTILE, quantise, top_level
from radar_slam.maps.localizer import Localization, Localizer
from radar_slam.maps.session import InterSessionQueries, join_session
from radar_slam.maps.writers import LOCALIZATION_CSV_COLUMNS
from radar_slam.pipeline import Pipeline, Results, load_config
from radar_slam.trajectory import read_tum
from raplace.se2 import between, compose, wrap_angle

MAP_FRAMES = 110
"""Scans of tiny_loop that make the map (the first lap and a bit)."""
OTHER_TOWN_SCANS = 120
"""Scans of the other town's drive localised in the tiny town's map."""
TRACKED_BEFORE_FAILURE = 10
"""Tracked scans before the map registrations are made to fail."""


@pytest.fixture(scope="module")
def map_run(tiny_loop: RadarSequence) -> Results:
    return Pipeline(tiny_loop, load_config("synthetic"), max_frames=MAP_FRAMES).run()


@pytest.fixture(scope="module")
def tiny_map(map_run: Results, tiny_loop: RadarSequence) -> Map:
    return build_map(map_run, tiny_loop)


@pytest.fixture(scope="module")
def saved_map(tiny_map: Map, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("maps") / "map"
    tiny_map.save(path)
    return path


def test_keyframes_every_spacing() -> None:
    x = np.arange(0.0, 20.5, 0.5)
    poses = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    np.testing.assert_array_equal(select_keyframes(poses, 4.0), [0, 8, 16, 24, 32, 40])


def test_map_content(tiny_map: Map, map_run: Results) -> None:
    cfg = map_run.config.maps
    path = map_run.slam.length_m()
    max_step = float(np.max(np.hypot(*np.diff(map_run.slam.positions, axis=0).T)))
    assert path / (cfg.keyframe_spacing_m + max_step) <= len(tiny_map)
    assert len(tiny_map) <= path / cfg.keyframe_spacing_m + 1
    kf = tiny_map.keyframes
    np.testing.assert_allclose(tiny_map.poses, map_run.slam.poses[kf["scan"]])
    assert np.all(np.isfinite(tiny_map.gt_poses))
    # The stored alignment takes the map's poses onto the ground truth (SLAM ATE is ~0.1 m).
    assert tiny_map.gt_alignment is not None

    placed = compose(tiny_map.gt_alignment, tiny_map.poses)
    assert np.max(np.hypot(*(placed[:, :2] - tiny_map.gt_poses[:, :2]).T)) < 1.0
    # A chain of odometry edges plus the accepted loops moved onto keyframes.
    odometry_edges = tiny_map.edges[tiny_map.edges["kind"] == 0]
    assert len(odometry_edges) == len(tiny_map) - 1
    assert tiny_map.sessions[0].sequence == "synthetic/tiny_loop"
    assert tiny_map.sessions[0].scans == MAP_FRAMES


def test_round_trip_is_byte_identical(saved_map: Path, tmp_path: Path) -> None:
    loaded = Map.load(saved_map)
    again = tmp_path / "again"
    loaded.save(again)
    for name in (MANIFEST_FILE, *DATA_FILES):
        assert (again / name).read_bytes() == (saved_map / name).read_bytes(), name
    assert encode_map(Map.load(again)) == encode_map(loaded)
    with pytest.raises(MapError, match="exists already"):
        loaded.save(again)


def test_compact(saved_map: Path, tiny_map: Map) -> None:
    size = sum(f.stat().st_size for f in saved_map.iterdir())
    assert size / len(tiny_map) < 40_000  # bytes per keyframe: no polar scans inside


def _one_line_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    return err


def test_damaged_and_foreign_maps_give_one_line(
    saved_map: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    for f in saved_map.iterdir():
        (damaged / f.name).write_bytes(f.read_bytes())
    blob = bytearray((damaged / "images.bin").read_bytes())
    blob[len(blob) // 2] ^= 0xFF
    (damaged / "images.bin").write_bytes(bytes(blob))
    err = _one_line_error(capsys, ["map", "info", str(damaged)])
    assert "images.bin is damaged" in err and str(damaged) in err

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("hello")
    assert "not a radar-slam map" in _one_line_error(capsys, ["map", "info", str(foreign)])

    newer = tmp_path / "newer"
    newer.mkdir()
    for f in saved_map.iterdir():
        (newer / f.name).write_bytes(f.read_bytes())
    manifest = json.loads((newer / MANIFEST_FILE).read_text())
    manifest["version"] = 99
    (newer / MANIFEST_FILE).write_text(json.dumps(manifest))
    assert "version 99" in _one_line_error(capsys, ["map", "info", str(newer)])

    missing = tmp_path / "missing"
    missing.mkdir()
    for f in saved_map.iterdir():
        if f.name != "edges.npy":
            (missing / f.name).write_bytes(f.read_bytes())
    assert "edges.npy is missing" in _one_line_error(capsys, ["map", "info", str(missing)])


def test_map_info(saved_map: Path, tiny_map: Map, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["map", "info", str(saved_map), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["keyframes"] == len(tiny_map)
    assert info["sessions"][0].startswith("synthetic/tiny_loop")
    assert info["gt_alignment"] is not None
    assert main(["map", "info", str(saved_map)]) == 0
    assert "GT alignment" in capsys.readouterr().out


def _percentile_images() -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    sparse = rng.exponential(1.0, (400, 400)).astype(np.float32)
    sparse[rng.random((400, 400)) < 0.9] = 0.0  # mostly empty, like a conditioned scan's image
    ties = rng.integers(0, 5, (400, 400)).astype(np.float32)
    with_nan = rng.random((50, 40), dtype=np.float32)
    with_nan[7, 3] = np.nan
    return [sparse, ties, rng.random((3, 2), dtype=np.float32), with_nan, rng.random((400, 400))]


def test_top_level_is_the_images_percentile() -> None:
    ramp = np.random.default_rng(4).permutation(np.arange(160_000, dtype=np.float32))
    assert top_level(ramp.reshape(400, 400)) == pytest.approx(0.999 * 159_999, abs=0.01)
    for image in _percentile_images():
        expected = float(np.percentile(image, SCALE_PERCENTILE))
        assert top_level(image) == expected or np.isnan(expected) and np.isnan(top_level(image))


def test_quantised_levels() -> None:
    relative = np.array([[-1.0, 0.0, 0.05, 0.25, 0.5, 1.0, 4.0]], dtype=np.float32)
    np.testing.assert_array_equal(
        quantise(2.0 * relative, 2.0, 0.1, 15), [[0, 0, 0, 8, 11, 15, 15]]
    )
    for image in _percentile_images()[:3]:
        for scale in (0.3, 1.7, 1e-4):
            expected = np.clip(image / scale, 0.0, 1.0)
            expected[expected < 0.1] = 0.0
            expected = np.rint(np.sqrt(expected) * 15).astype(np.uint8)
            np.testing.assert_array_equal(quantise(image, scale, 0.1, 15), expected)


def test_keyframe_png_is_lossless_and_unfiltered(tiny_loop: RadarSequence) -> None:
    """A keyframe image's PNG decodes to exactly its quantised pixels, its rows stored unfiltered
    (filter type 0), and it is no larger than libpng's adaptive filtering makes it."""
    imager = KeyframeImager(ImageGeometry(), OdometryConfig())
    image = imager.render(preprocess_polar(tiny_loop[40], imager.odometry.preprocess), None)
    png, scale = imager.encode(image)
    geo = imager.geometry
    np.testing.assert_array_equal(
        imager.decode(png), quantise(image, scale, geo.floor_fraction, geo.levels)
    )
    parsed = _parse_chunks(png)
    assert parsed is not None
    rows = np.frombuffer(zlib.decompress(parsed[1]), dtype=np.uint8).reshape(geo.size_px, -1)
    assert set(rows[:, 0].tolist()) == {0}
    adaptive = cv2.imencode(".png", imager.decode(png), [cv2.IMWRITE_PNG_COMPRESSION, 6])[1]
    assert 0.2 * len(adaptive) < len(png) <= len(adaptive)


def test_keyframe_image_verifies_like_the_scan(tiny_loop: RadarSequence) -> None:
    """A loop verified against a keyframe's stored image (made back into a scan) recovers the
    ground-truth relative pose as well as one against the scan itself."""
    imager = KeyframeImager(ImageGeometry(), OdometryConfig())
    verifier = GeometricVerifier(LoopClosureConfig())
    gt = np.asarray(tiny_loop.ground_truth)
    query = 150  # on the revisit: its nearest scan of the first lap is the match
    match = int(np.argmin(np.hypot(*(gt[:80, :2] - gt[query, :2]).T)))
    assert 0.5 < np.hypot(*(gt[query, :2] - gt[match, :2])) < 5.0
    polar = preprocess_polar(tiny_loop[match], imager.odometry.preprocess)
    png, _ = imager.encode(imager.render(polar, None))
    pseudo = imager.pseudo_scan(png, tiny_loop[match].timestamp_ns)
    result = verifier(
        KeyScan(query, pseudo.timestamp_ns, tiny_loop[query]),
        KeyScan(10_000, pseudo.timestamp_ns, pseudo),
    )
    assert result.ok, result.reason
    error = between(between(gt[query], gt[match]), result.measurement)
    assert np.hypot(error[0], error[1]) < 0.5
    assert abs(np.rad2deg(wrap_angle(error[2]))) < 1.0


def test_run_writes_a_map(synthetic_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = ["run", "synthetic/tiny", "--data-root", str(synthetic_root), "--out", str(out)]
    assert main([*argv, "--max-frames", "30"]) == 0
    m = Map.load(out / "map")
    assert m.sessions[0].scans == 30
    assert len(m) >= 3
    assert dataclasses.asdict(ImageGeometry()) == m.settings["image"]


def test_localize_the_revisit_in_the_map(tiny_map: Map, tiny_loop: RadarSequence) -> None:
    """The scans after the map's end drive its streets again: once relocalised, every scan near
    the map is placed within 1 m and 2 deg of GT (through the map's own GT alignment)."""
    localizer = Localizer(tiny_map, load_config("synthetic"))
    fixes = [localizer.localize(tiny_loop[n]) for n in range(MAP_FRAMES, len(tiny_loop))]
    gt = np.asarray(tiny_loop.ground_truth)[MAP_FRAMES:]
    metrics = evaluate_localization(fixes, gt, tiny_map)
    assert metrics is not None
    assert metrics.relocalisations >= 1
    assert metrics.wrong_localised == 0
    # Near the route but lost: the scans before hypotheses from three keyframes agree.
    assert metrics.near_route_correct is not None and metrics.near_route_correct >= 0.85
    assert metrics.max_error_m is not None and metrics.max_error_m < 2.0


def test_localize_command(
    saved_map: Path, synthetic_root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "loc"
    argv = ["localize", "synthetic/tiny_loop", "--map", str(saved_map), "--out", str(out)]
    assert main([*argv, "--data-root", str(synthetic_root), "--max-frames", "40"]) == 0
    with (out / "localization.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == LOCALIZATION_CSV_COLUMNS and len(rows) == 40
    assert {r["status"] for r in rows} <= {"relocalised", "tracked", "lost"}
    localised = [r for r in rows if r["status"] != "lost"]
    assert len(localised) >= 20  # the map was built from these very scans
    keyframe_poses = Map.load(saved_map).poses
    for row in localised:  # the pose relative to its keyframe, with its covariance
        relative = [float(row[k]) for k in ("rel_x", "rel_y", "rel_yaw")]
        pose = compose(keyframe_poses[int(row["map_key"])], relative)
        np.testing.assert_allclose(pose, [float(row[k]) for k in ("x", "y", "yaw")], atol=1e-6)
        assert float(row["sigma_m"]) ** 2 <= float(row["cov_xx"]) + float(row["cov_yy"])
    lost = [r for r in rows if r["status"] == "lost"]
    assert all(r["sigma_m"] == r["cov_xx"] == r["x"] == "" for r in lost)
    assert len(read_tum(out / "localization.tum")) == len(localised)
    boreas = read_boreas(out / BOREAS_FILE)  # the same poses, in the benchmark's form
    np.testing.assert_allclose(
        boreas.relative,
        [[float(r[k]) for k in ("rel_x", "rel_y", "rel_yaw")] for r in localised],
        atol=1e-9,
    )
    assert boreas.information is not None and boreas.information.shape == (len(localised), 6, 6)
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["wrong_localised"] == 0 and metrics["scans"] == 40
    assert (out / "localization.png").is_file()
    assert "localised within 1 m" in capsys.readouterr().out
    # A damaged map stops before any work.
    (saved_map.parent / "broken").mkdir()
    err = _one_line_error(
        capsys, ["localize", "synthetic/tiny", "--map", str(saved_map.parent / "broken")]
    )
    assert "not a radar-slam map" in err


@pytest.fixture(scope="module")
def reverse_pair(synthetic_root: Path) -> tuple[RadarSequence, RadarSequence]:
    """`synthetic/tiny_reverse_a` and `_b`: one block driven one way, then the other way round
    in the other lane in another session (reduced bins)."""
    return (
        open_sequence("synthetic/tiny_reverse_a", synthetic_root),
        open_sequence("synthetic/tiny_reverse_b", synthetic_root),
    )


@pytest.fixture(scope="module")
def reverse_map(reverse_pair: tuple[RadarSequence, RadarSequence]) -> Map:
    a = reverse_pair[0]
    return build_map(Pipeline(a, load_config("synthetic")).run(), a)


def test_reverse_session_localised_in_the_map(
    reverse_map: Map, reverse_pair: tuple[RadarSequence, RadarSequence]
) -> None:
    """Driving the map's street the other way round: relocalised (the 180-degree case) and
    tracked within 1 m and 2 deg of GT, through the map's own GT alignment."""
    b = reverse_pair[1]
    localizer = Localizer(reverse_map, load_config("synthetic"))
    fixes = [localizer.localize(b[n]) for n in range(len(b))]
    metrics = evaluate_localization(fixes, np.asarray(b.ground_truth), reverse_map)
    assert metrics is not None and metrics.relocalisations >= 1
    assert metrics.near_route_correct is not None and metrics.near_route_correct >= 0.95
    assert metrics.wrong_localised == 0
    assert metrics.fraction_localised >= 0.8  # lost: the scans before the chain agrees
    # Each localised pose comes relative to its map keyframe with a covariance.
    for f in (f for f in fixes if f.localised):
        np.testing.assert_allclose(
            compose(reverse_map.poses[f.map_key], f.relative), f.pose, atol=1e-9
        )
        assert np.all(np.linalg.eigvalsh(f.covariance) > 0) and 0 < f.sigma_m < 1.0
        assert f.quality >= load_config("synthetic").loop_closure.verification.min_refined_quality


def shuffled(m: Map, seed: int) -> Map:
    """`m` with its keyframe poses dealt out to the wrong keyframes (descriptors and images stay
    in place): every match to it is a match to a wrong place."""
    keyframes = m.keyframes.copy()
    keyframes["pose"] = keyframes["pose"][np.random.default_rng(seed).permutation(len(m))]
    return dataclasses.replace(m, keyframes=keyframes)


@pytest.mark.parametrize("seed", [0, 3])
def test_a_map_of_wrong_places_places_no_scan(
    reverse_map: Map, reverse_pair: tuple[RadarSequence, RadarSequence], seed: int
) -> None:
    """Keyframes under wrong poses: single matches verify, but their hypotheses never agree
    along the path driven, so no scan is placed (all lost) and none is off. Under seed 3 two
    neighbouring keyframes land on neighbouring wrong poses, a wrong street with the right
    local geometry: their hypotheses agree, and only a third keyframe refuses them."""
    b = reverse_pair[1]
    localizer = Localizer(shuffled(reverse_map, seed=seed), load_config("synthetic"))
    fixes = [localizer.localize(b[n]) for n in range(len(b))]
    assert not any(f.localised for f in fixes)
    assert localizer.global_attempts > 0 and localizer.relocalisations == 0


def test_a_drive_in_another_town_places_no_scan(reverse_map: Map, synthetic_root: Path) -> None:
    """A drive through another simulated town, localised in the tiny town's map: nothing is
    claimed."""
    other = open_sequence("synthetic/tiny_u_turn", synthetic_root)
    localizer = Localizer(reverse_map, load_config("synthetic"))
    fixes = [localizer.localize(other[n]) for n in range(min(len(other), OTHER_TOWN_SCANS))]
    assert not any(f.localised for f in fixes)


def test_sigma_is_the_least_certain_axis() -> None:
    covariance = np.array([[3.0, 1.0, 0.0], [1.0, 3.0, 0.0], [0.0, 0.0, 1.0]])
    placed = Localization(1, "tracked", np.zeros(3), 0, 20.0, np.zeros(3), covariance)
    assert placed.sigma_m == pytest.approx(2.0)  # eigenvalues 2 and 4
    assert np.isnan(Localization(1, "lost", np.full(3, np.nan), -1, 0.0).sigma_m)


def test_reverse_session_joins_the_map(
    reverse_map: Map, reverse_pair: tuple[RadarSequence, RadarSequence], tmp_path: Path
) -> None:
    """The reverse session is tied to the map by verified inter-session loops, all true, and
    lands in the map's frame within 1 m ATE without re-alignment."""
    b = reverse_pair[1]
    config = load_config("synthetic")
    queries = InterSessionQueries(reverse_map, config)
    run = Pipeline(b, config, on_keyframe=queries).run()
    joined = join_session(run, reverse_map, queries)
    assert joined.met_map
    accepted = [n for n, d in enumerate(joined.loops) if d.accepted]
    assert len(accepted) >= 2
    assert all(joined.true_loops[n] for n in accepted)
    assert joined.ate_map_frame_m is not None and joined.ate_map_frame_m < 1.0
    yaw = [abs(wrap_angle(d.measurement[2])) for d in joined.accepted]
    assert max(yaw) > np.deg2rad(150)  # loops across the opposite direction
    extended = joined.map
    assert [s.joined for s in extended.sessions] == ["origin", "loops"]
    assert len(extended) > len(reverse_map)
    assert np.sum(extended.edges["kind"] == 2) == len(accepted)
    # The extended map round-trips and serves a third session.
    extended.save(tmp_path / "two")
    again = Map.load(tmp_path / "two")
    assert encode_map(again) == encode_map(extended)
    assert len(again.sessions) == 2


def test_a_session_elsewhere_never_meets_the_map(tiny: RadarSequence, oxford_dir: Path) -> None:
    """A map of a real Oxford street and a simulated town: no inter-session loop is accepted,
    and the session is reported as such (its trajectory stays in its own frame)."""
    oxford = open_sequence(str(oxford_dir))
    config = load_config("synthetic")
    oxford_map = build_map(Pipeline(oxford, load_config("oxford")).run(), oxford)
    queries = InterSessionQueries(oxford_map, config)
    run = Pipeline(tiny, config, max_frames=30, on_keyframe=queries).run()
    joined = join_session(run, oxford_map, queries)
    assert not joined.met_map
    assert not any(d.accepted for d in joined.loops)
    np.testing.assert_allclose(joined.results.slam.poses, run.slam.poses)
    assert [s.sequence for s in joined.map.sessions] == [run.sequence]


def test_a_tracked_pose_whose_fixes_fail_is_reported_lost(
    reverse_map: Map, reverse_pair: tuple[RadarSequence, RadarSequence]
) -> None:
    """Once tracking, every map registration fails from some scan on (as on a street the map
    no longer shows): the scans are tracked on odometry only until the second failed fix
    attempt, then reported lost, before `lost_after_m`."""
    b = reverse_pair[1]
    config = load_config("synthetic")
    localizer = Localizer(reverse_map, config)
    statuses, fixed_at, last_fix = [], 0, None
    for n in range(len(b)):
        failing = statuses.count("tracked") >= TRACKED_BEFORE_FAILURE
        if failing:
            localizer._tracking_fix = lambda *_: None  # type: ignore[method-assign]
        statuses.append(localizer.localize(b[n]).status)
        if not failing and localizer.state.last_fix is not last_fix:
            fixed_at, last_fix = n, localizer.state.last_fix
    failed_from = statuses.index("tracked") + TRACKED_BEFORE_FAILURE
    first_lost = statuses.index("lost", failed_from)
    assert set(statuses[failed_from:first_lost]) == {"tracked"}
    # Lost until global relocalisation (its registrations still work) places the scans again.
    again = (
        statuses.index("relocalised", first_lost)
        if "relocalised" in statuses[first_lost:]
        else len(statuses)
    )
    assert set(statuses[first_lost:again]) == {"lost"} and again - first_lost >= 3
    path = np.hypot(*np.diff(np.asarray(b.ground_truth)[:, :2], axis=0).T)
    cfg = config.maps.localization
    # From the last accepted fix: one fix spacing to the failed attempt, one scan more to lost.
    unfixed_m = float(np.sum(path[fixed_at:first_lost]))
    assert cfg.fix_every_m < unfixed_m < cfg.lost_after_m
