"""Diagnose the odometry's rotation bias (issue 10) with controlled cases, stage by stage.

Sub-commands (each prints a small table; docs/odometry_notes.md quotes them):

- `timestamps`: the per-azimuth timestamps of the real samples (MulRan raw CSV, Oxford PNG
  headers) against the straight line the odometry fits (`odometry.preprocess`), and the
  simulator's column times against the MulRan loader's uniform times.
- `geometry`: where the de-skew samples a point (`odometry.deskew.sampling_maps`, one
  fixed-point step) against where the sweep really sees it (the fixed point solved exactly) and
  where the simulator puts it (`radar_slam.sim.render.project`), for straight driving and pure
  turns: the angle error [mrad], mean and rms.
- `rotation`: known rotations at sub-bin angles (0.1-1.1 deg; azimuth step 0.9 deg, refinement
  bin 0.5 deg), with and without translation, on exactly rendered point-target scans
  (`tests/point_scenes.py`, no radar physics): the Fourier-Mellin (coarse) yaw and the refined
  yaw for 1 and 2 refinement passes (`--full`: at MulRan's 3360 range bins).
- `deskew`: a point-target scan rendered with motion distortion, de-skewed with the exact twist,
  registered against the undistorted scan at the same pose (the de-skew's own residual).
- `sim`: 10 m straight drives at 10 m/s through `loop`'s town rendered by the simulator, paired
  with the same drives with the facades' slant range, the traffic or the motion distortion
  switched off (the same speckle seeds): what each contributes to the yaw error.
- `forward`: the forward translation error of such drives against the baseline (1-10 m), with
  the simulator's effects switched off in turn: the short-baseline overestimate that makes
  keyframes 10 m apart drift less than 5 m apart.

Usage: python scripts/diagnose_rotation_bias.py {timestamps,geometry,rotation,deskew,sim,forward}
       [--scenes N] [--shared-data DIR]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from point_scenes import (  # noqa: E402  (the test helper folder is put on the path above)
    BIN_M,
    N_AZIMUTHS,
    SWEEP_NS,
    moving_poses,
    point_scene,
    render_polar,
    scan_frame,
    static_poses,
)

from odometry import registration  # noqa: E402
from odometry.config import DeskewConfig, OdometryConfig  # noqa: E402
from odometry.deskew import motion_from_twist, sampling_maps  # noqa: E402
from odometry.registration import MotionEstimate, estimate_motion  # noqa: E402
from odometry.scan import Scan  # noqa: E402
from radar_slam.datasets.mulran import column_azimuths_rad  # noqa: E402
from radar_slam.sim.generate import Scene, build_scene  # noqa: E402
from raplace import se2  # noqa: E402

FloatArray = NDArray[np.float64]
PERIOD_S = SWEEP_NS / 1e9 / N_AZIMUTHS
FIRST_ROW_S = -(N_AZIMUTHS - 1) * PERIOD_S
"""Time of row 0 relative to the scan's reference time (its end, MulRan) [s]."""
MID_SWEEP_S = FIRST_ROW_S + 0.5 * (N_AZIMUTHS - 1) * PERIOD_S
TWISTS: dict[str, FloatArray] = {
    "10 m/s": np.array([10.0, 0.0, 0.0]),
    "-10 m/s": np.array([-10.0, 0.0, 0.0]),
    "20 m/s": np.array([20.0, 0.0, 0.0]),
    "turn +30 deg/s": np.array([0.0, 0.0, np.radians(30.0)]),
    "turn -30 deg/s": np.array([0.0, 0.0, np.radians(-30.0)]),
}


def _mean_se(values: FloatArray) -> str:
    return f"{values.mean():+7.2f} +- {values.std() / np.sqrt(len(values)):5.2f}"


def timestamps(shared: Path) -> None:
    """Real per-azimuth timestamps against the linear model; simulator vs loader times."""
    raw = sorted((shared / "mulran" / "raw_scan").glob("*.csv"))
    series: list[tuple[str, FloatArray]] = []
    for path in raw:
        t_ns = np.loadtxt(path, delimiter=",", usecols=0, dtype=np.int64)
        series.append((f"MulRan {path.name}", (t_ns - t_ns[0]).astype(np.float64) * 1e-9))
    for path in sorted((shared / "oxford").glob("*/radar/*.png"))[:3]:
        image = np.asarray(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), dtype=np.uint8)
        t_us = np.ascontiguousarray(image[:, :8]).view("<i8")[:, 0]
        series.append((f"Oxford {path.name}", (t_us - t_us[0]).astype(np.float64) * 1e-6))
    print("scan | period [us] | residual of the linear fit [ms]: min, max, rms | largest step [ms]")
    for name, t in series:
        index = np.arange(len(t), dtype=np.float64)
        slope, offset = np.polyfit(index, t, 1)
        residual = t - (offset + slope * index)
        print(
            f"{name} | {slope * 1e6:.1f} | {residual.min() * 1e3:+.2f}, "
            f"{residual.max() * 1e3:+.2f}, {np.sqrt(np.mean(residual**2)) * 1e3:.2f} | "
            f"{np.diff(t).max() * 1e3:.2f}"
        )
    from radar_slam.datasets.mulran import uniform_azimuth_times_ns
    from radar_slam.sim.sensor import SensorConfig

    sensor = SensorConfig()
    sim = sensor.azimuth_offsets_ns()
    loader = uniform_azimuth_times_ns(0, sensor.scan_period_ns, sensor.n_azimuths)
    print(
        f"simulator column times - MulRan loader times: max |diff| {np.abs(sim - loader).max()} ns"
    )
    azimuth_diff = sensor.azimuths_ccw_rad() - column_azimuths_rad(sensor.n_azimuths)
    print(
        f"simulator azimuths - MulRan loader azimuths: max |diff| {np.abs(azimuth_diff).max()} rad"
    )


def _exp(twist: FloatArray, t_s: FloatArray) -> FloatArray:
    """(3, N) poses after t_s (N,) seconds at a constant body twist."""
    return np.stack([motion_from_twist(twist, float(t)) for t in t_s], axis=1)


def _exact_rows(x: FloatArray, y: FloatArray, twist: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Fractional row and range [m] at which the sweep sees the points (x, y) of the mid-sweep
    frame: the fixed point row = azimuth^-1(bearing from the pose at row's time), iterated to
    convergence."""
    az = column_azimuths_rad(N_AZIMUTHS)
    a0, step = float(az[0]), float(az[1] - az[0])
    mid = motion_from_twist(twist, MID_SWEEP_S)
    wx, wy = se2.transform_points(mid, np.c_[x, y]).T
    rows = np.mod((np.arctan2(y, x) - a0) / step, N_AZIMUTHS)
    for _ in range(60):
        poses = _exp(twist, FIRST_ROW_S + rows * PERIOD_S)
        c, s = np.cos(poses[2]), np.sin(poses[2])
        dx, dy = wx - poses[0], wy - poses[1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        rows = np.mod((np.arctan2(ly, lx) - a0) / step, N_AZIMUTHS)
    return rows, np.hypot(lx, ly)


def geometry(n_points: int) -> None:
    """Angle error of the de-skew's and the simulator's row of a point against the exact one."""
    from radar_slam.sim.physics import PhysicsConfig
    from radar_slam.sim.render import make_tables, project
    from radar_slam.sim.sensor import SensorConfig

    tables = make_tables(SensorConfig(), PhysicsConfig())
    az = column_azimuths_rad(N_AZIMUTHS)
    a0, step = float(az[0]), float(az[1] - az[0])
    rng = np.random.default_rng(0)
    r, b = rng.uniform(3.0, 80.0, n_points), rng.uniform(-np.pi, np.pi, n_points)
    x, y = r * np.cos(b), r * np.sin(b)
    print("twist | [mrad] de-skew - exact: mean (r > 10 m), rms | simulator - exact: mean, rms |"
          " de-skew - simulator: mean (r > 10 m), rms")  # fmt: skip
    for name, twist in TWISTS.items():
        exact, _ = _exact_rows(x, y, twist)
        f32 = [np.asarray(v, np.float32)[None, :] for v in (x, y, r, np.arctan2(y, x))]
        _, rows = sampling_maps(
            *f32, first_azimuth_rad=a0, azimuth_step_rad=step, n_azimuths=N_AZIMUTHS,
            bin_size_m=0.2, twist=twist, timing=(FIRST_ROW_S - MID_SWEEP_S, PERIOD_S),
        )  # fmt: skip
        poses = _exp(twist, tables.column_offsets_s).T
        world = se2.transform_points(motion_from_twist(twist, MID_SWEEP_S), np.c_[x, y]).astype(
            np.float32
        )
        sim_rows = project(world[:, 0], world[:, 1], poses, tables)[0]
        keep = np.minimum(exact, N_AZIMUTHS - exact) > 12  # away from the sweep's seam
        far = keep & (r > 10.0)

        def err(a: NDArray, ref: NDArray, mask: NDArray) -> FloatArray:
            return (
                np.asarray(((a - ref + N_AZIMUTHS / 2) % N_AZIMUTHS - N_AZIMUTHS / 2) * step)[mask]
                * 1e3
            )

        d_exact = err(rows[0], exact, keep)
        d_sim = err(sim_rows, exact, keep)
        d_both, d_far = err(rows[0], sim_rows, keep), err(rows[0], sim_rows, far)
        print(
            f"{name} | {d_exact.mean():+.3f} ({err(rows[0], exact, far).mean():+.3f}), "
            f"{np.sqrt(np.mean(d_exact**2)):.3f} | {d_sim.mean():+.3f}, "
            f"{np.sqrt(np.mean(d_sim**2)):.3f} | {d_both.mean():+.3f} ({d_far.mean():+.3f}), "
            f"{np.sqrt(np.mean(d_both**2)):.3f}"
        )


def _scan(targets: FloatArray, pose: list[float], end_ns: int, size: dict[str, float]) -> Scan:
    """A still scan of `targets` from `pose`, at the default or the given bin size."""
    polar = render_polar(targets, static_poses(pose), **size)  # type: ignore[arg-type]
    return scan_frame(polar, end_ns, False, size.get("bin_m", BIN_M))


def _estimate(ref: Scan, cur: Scan, passes: int) -> MotionEstimate:
    """`estimate_motion` without de-skew, the rotation refined `passes` times."""
    original = registration.ROTATION
    registration.ROTATION = dataclasses.replace(original, refine_passes=passes)
    try:
        return estimate_motion(ref, cur, OdometryConfig(deskew=DeskewConfig(enabled=False)))
    finally:
        registration.ROTATION = original


MULRAN_BIN_M = 0.05952
MULRAN_N_BINS = 3360


def rotation(n_scenes: int, full: bool) -> None:
    """Yaw errors [mdeg] of known rotations: coarse (Fourier-Mellin) and refined; `full`: at
    MulRan's 3360 bins of 0.0595 m instead of 500 of 0.2 m."""
    size = {"n_bins": MULRAN_N_BINS, "bin_m": MULRAN_BIN_M} if full else {}
    angles_mdeg = (0.0, 100.0, 225.0, 450.0, 675.0, 900.0, 1125.0, 1800.0)
    configs = {"1 pass": 1, "2 passes": 2}
    print("translation [m] | rotation [mdeg] | coarse yaw [mdeg] | refined error [mdeg], mean"
          " +- s.e.: " + ", ".join(configs))  # fmt: skip
    scenes = [point_scene(np.random.default_rng(seed)) for seed in range(n_scenes)]
    refs = [_scan(t, [0.0, 0.0, 0.0], 10**9, size) for t in scenes]
    for translation in ((0.0, 0.0), (2.5, 0.0), (10.0, 0.0)):
        for angle in angles_mdeg:
            pose = [translation[0], translation[1], np.radians(angle / 1000.0)]
            curs = [_scan(t, pose, 10**9 + SWEEP_NS, size) for t in scenes]
            coarse: list[float] = []
            refined: dict[str, list[float]] = {name: [] for name in configs}
            for ref, cur in zip(refs, curs, strict=True):
                for name, passes in configs.items():
                    estimate = _estimate(ref, cur, passes)
                    refined[name].append(np.degrees(estimate.dyaw) * 1e3 - angle)
                coarse.append(np.degrees(estimate.coarse_motion[2]) * 1e3)
            cells = " | ".join(_mean_se(np.array(v)) for v in refined.values())
            print(f"{translation} | {angle:.0f} | {np.mean(coarse):+.1f} | {cells}")


def deskew(n_scenes: int) -> None:
    """Yaw [mdeg] of a distorted scan de-skewed with the exact twist against the undistorted
    scan at the same pose (both exactly rendered point targets)."""
    cfg = OdometryConfig(deskew=DeskewConfig(iterations=0))
    print("twist | yaw [mdeg] mean +- s.e. | x, y [mm]")
    for name, twist in TWISTS.items():
        yaws, xy = [], []
        for seed in range(n_scenes):
            targets = point_scene(np.random.default_rng(200 + seed))
            still = scan_frame(render_polar(targets, static_poses([0.0, 0.0, 0.0])), 10**9, False)
            moving = scan_frame(
                render_polar(targets, moving_poses([0.0, 0.0, 0.0], twist)), 10**9, True
            )
            estimate = estimate_motion(still, moving, cfg, twist=twist)
            yaws.append(np.degrees(estimate.dyaw) * 1e3)
            xy.append(estimate.motion[:2] * 1e3)
        mean_xy = np.mean(xy, axis=0)
        print(f"{name} | {_mean_se(np.array(yaws))} | {mean_xy[0]:+.1f}, {mean_xy[1]:+.1f}")


def _sim_errors(
    starts: list[FloatArray],
    world: object,
    physics: object,
    scene: object,
    baseline_m: float = 10.0,
) -> FloatArray:
    """(n, 2) errors of `baseline_m` registrations of straight 10 m/s drives from `starts`: yaw
    [mdeg] and forward translation [mm]."""
    from radar_slam.datasets.frame import RadarFrame
    from radar_slam.datasets.mulran import uniform_azimuth_times_ns
    from radar_slam.sim.render import Renderer
    from radar_slam.sim.route import Trajectory

    sensor = scene.scenario.sensor  # type: ignore[attr-defined]
    distorted = physics.motion_distortion.enabled  # type: ignore[attr-defined]
    twist = np.array([10.0, 0.0, 0.0])
    cfg = OdometryConfig(deskew=DeskewConfig(enabled=distorted, iterations=0))
    ends_s = (0.5, 0.5 + baseline_m / 10.0)
    errors = []
    for k, p0 in enumerate(starts):
        t = np.arange(0.0, ends_s[1] + 1.5, 0.01)
        poses = np.c_[p0[0] + 10 * t * np.cos(p0[2]), p0[1] + 10 * t * np.sin(p0[2]), 0 * t + p0[2]]
        drive = Trajectory(t_s=t, poses=poses, length_m=10.0 * float(t[-1]))
        renderer = Renderer(world, drive, sensor, physics)  # type: ignore[arg-type]
        scans = []
        for end_s in ends_s:
            polar = renderer.scan(end_s, np.random.default_rng([7, k, int(end_s * 10)]))
            end_ns = int(end_s * 1e9)
            times = uniform_azimuth_times_ns(end_ns, SWEEP_NS, N_AZIMUTHS) if distorted else None
            scans.append(
                RadarFrame(
                    end_ns, polar, column_azimuths_rad(), sensor.range_resolution_m, "sim", times
                )
            )
        truth = se2.between(*drive.radar_poses(np.array(ends_s)))
        estimate = estimate_motion(scans[0], scans[1], cfg, twist=twist if distorted else None)
        yaw_mdeg = np.degrees(se2.wrap_angle(estimate.dyaw - truth[2])) * 1e3
        errors.append([yaw_mdeg, (estimate.dx - truth[0]) * 1e3])
    return np.array(errors)


def _straight_starts(n_drives: int) -> tuple[Scene, list[FloatArray]]:
    """`loop`'s scene and up to `n_drives` start poses on straight pieces of its route."""
    from radar_slam.sim.scenarios import get_scenario

    scene = build_scene(get_scenario("loop"))
    route = scene.trajectory
    starts = []
    for t0 in np.arange(5.0, route.duration_s - 5.0, 1.5):
        i, j = np.searchsorted(route.t_s, [t0 - 0.5, t0 + 1.5])
        if np.ptp(route.poses[i:j, 2]) < np.radians(1.0):  # a straight piece of the route
            starts.append(route.base_poses(np.array([t0]))[0])
    return scene, starts[:n_drives]


def sim(n_drives: int) -> None:
    """Paired simulator experiments on straight drives through `loop`'s town."""
    from radar_slam.sim.scatterers import no_traffic

    scene, starts = _straight_starts(n_drives)
    phys = scene.scenario.physics
    off = dataclasses.replace
    still = off(phys, motion_distortion=off(phys.motion_distortion, enabled=False))
    flat = off(still, elevation=off(phys.elevation, enabled=False))
    moving_flat = off(phys, elevation=off(phys.elevation, enabled=False))
    quiet = off(scene.world, traffic=no_traffic())
    runs: dict[str, Callable[[], FloatArray]] = {
        "undistorted": lambda: _sim_errors(starts, scene.world, still, scene)[:, 0],
        "undistorted, no traffic": lambda: _sim_errors(starts, quiet, still, scene)[:, 0],
        "undistorted, no traffic, no slant range": lambda: _sim_errors(starts, quiet, flat, scene)[
            :, 0
        ],
        "distorted + exact de-skew, no traffic, no slant range": lambda: _sim_errors(
            starts, quiet, moving_flat, scene
        )[:, 0],
    }
    results = {name: run() for name, run in runs.items()}
    names = list(results)
    print(f"{len(starts)} straight 10 m registrations at 10 m/s; yaw error [mdeg] mean +- s.e.")
    for name in names:
        print(f"{name} | {_mean_se(results[name])}")
    for a, b, label in ((0, 1, "traffic"), (1, 2, "slant range"), (3, 2, "distortion + de-skew")):
        print(f"paired: {label} | {_mean_se(results[names[a]] - results[names[b]])}")


def forward(n_drives: int) -> None:
    """Forward translation error against the baseline on straight drives through `loop`'s
    town: the whole simulator, and without traffic, motion distortion and slant range, then
    also without each of multipath ghosts and the range point-spread."""
    from radar_slam.sim.scatterers import no_traffic

    scene, starts = _straight_starts(n_drives)
    phys = scene.scenario.physics
    off = dataclasses.replace
    plain = off(
        phys,
        motion_distortion=off(phys.motion_distortion, enabled=False),
        elevation=off(phys.elevation, enabled=False),
    )
    quiet = off(scene.world, traffic=no_traffic())
    cases = {
        "whole simulator (de-skewed with the exact twist)": (scene.world, phys),
        "no traffic, distortion, slant range": (quiet, plain),
        "... and no multipath": (quiet, off(plain, multipath=off(plain.multipath, enabled=False))),
        "... and no range point-spread": (
            quiet,
            off(plain, range_psf=off(plain.range_psf, enabled=False)),
        ),
    }
    baselines = (1.0, 2.5, 5.0, 7.5, 10.0)
    print(f"{len(starts)} straight drives at 10 m/s; forward error [mm] mean +- s.e. per baseline")
    print("case | " + " | ".join(f"{b:g} m" for b in baselines))
    for name, (world, physics) in cases.items():
        cells = [_mean_se(_sim_errors(starts, world, physics, scene, b)[:, 1]) for b in baselines]
        print(f"{name} | " + " | ".join(cells), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "what", choices=["timestamps", "geometry", "rotation", "deskew", "sim", "forward"]
    )
    parser.add_argument("--scenes", type=int, default=8, help="scenes / drives per case")
    parser.add_argument("--full", action="store_true", help="rotation: at MulRan's 3360 bins")
    parser.add_argument(
        "--shared-data",
        type=Path,
        default=Path(__file__).resolve().parents[1] / ".." / "shared" / "data",
    )
    args = parser.parse_args()
    if args.what == "timestamps":
        timestamps(args.shared_data)
    elif args.what == "geometry":
        geometry(4000)
    elif args.what == "rotation":
        rotation(args.scenes, args.full)
    elif args.what == "deskew":
        deskew(args.scenes)
    elif args.what == "sim":
        sim(args.scenes)
    else:
        forward(args.scenes)


if __name__ == "__main__":
    main()
