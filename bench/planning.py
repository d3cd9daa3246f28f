"""Pose planning on the simulator: planned poses against random rule-abiding ones.

Sections (each simulates scans with the package simulator's ray caster, sensor noise and
robot pose errors, then calibrates them with the package pipeline, default method, radius
known):

``curve``
    ``ur_scancontrol`` at the cylinder paper's noise (robot 0.1 mm and 0.01 deg, sensor 5 um,
    1 sigma). Random: the simulator's own sampler (the paper's rules, ``sim/poses.py``), 50
    poses, calibrated on the first k. Planned: 3 exploratory scans (the first 3 random
    poses) and an initial hand-eye 2 mm / 1 deg off (a CAD guess), then rounds of planned
    poses (5, then 4 at a time), each round planned from the calibration of all scans so far.
    RMS over seeds of the true hand-eye error and of the predicted 1 sigma against the
    number of poses. Rows "best possible N, perfect sensor": the planner's predicted 1 sigma
    of the best N poses it finds when the sensor is perfect (below).
``sphere``
    The same on the ``sphere`` preset (a 2 in tooling ball on a table) at the paper's noise;
    random: the simulator's sphere views (tilted up to 35 deg, any line direction).
``cold``
    Random upright scenes (``random_scenario`` with a vertical shaft on a table, the
    paper's cut-angle rules, random hand-eye, profiler, noise): 3 exploratory scans and an
    initial hand-eye 2 mm / 1 deg off, then 17 planned poses in rounds. Success: a result
    within 0.5 mm and 0.1 deg of the truth (the right solution; the paper's own accuracy
    claim); also counted: within 0.1 mm and 0.02 deg.
``speed``
    Median time of planning 10 poses (from a result and 20 scans; and from a given axis with
    no scan).

How well can N poses do on the cylinder?
----------------------------------------
Within one pose the robot's pose error E_i and the hand-eye X enter only through the
sensor's pose T_base_flange · E_i · X, and a profile of a cylinder shows only 4 of that pose's
6 degrees of freedom: the sensor's offset from the axis across it (2) and its tilt against the
axis (2); a shift along the axis and a turn about it change nothing. Give the calibration
more than it has: a perfect sensor, the true cylinder, and every rotation (of X and of each
E_i) known. Each profile then measures y_i = Q_i (t + e_i) exactly, where t is the hand-eye
translation, e_i ~ N(0, σ_t² I) the robot's translation error (isotropic, so in any frame),
and Q_i (2×3, orthonormal rows) the two directions across the axis, in the flange frame.
The information on t is (1/σ_t²) Σ_i Q_iᵀ Q_i, a sum of N rank-2 projectors, whose trace is
2N/σ_t². For any positive definite 3×3 matrix, the trace of its inverse is at least 9 over
its trace, so the covariance C of t obeys

    E|t̂ − t|² ≥ tr C ≥ 9 σ_t² / (2N),   i.e.  RMS translation error ≥ 3 σ_t / √(2N),

with equality when the axis directions in the flange frame are spread evenly (Σ a_i a_iᵀ =
N/3 · I). Knowing less only loses information, so this holds for any set of N poses, planned
or random, and for any sensor. At the paper's robot noise (σ_t = 0.1 mm) it is 0.047 mm for
N = 20 and 0.030 mm for N = 50. The rotation obeys the same bound with σ_r (3 σ_r / √(2N):
0.0047 deg for N = 20) up to the small information the sensor's offset adds through the
lever of the hand-eye.

The rows "best possible N, perfect sensor" compute the same limit without the extra
knowledge: the planner (greedy D-optimal plus the exchange pass) on the true placement and
hand-eye, choosing from BOUND_CANDIDATES feasible candidates, with the sensor's σ times
PERFECT_SENSOR. For 20 poses they give 0.048 mm and 0.0047 deg (1 sigma norm; for these
poses the RMS true error), against 0.029 mm and 0.0035 deg measured for 50 random poses: at
this robot noise no 20 poses reach 50 random ones, which already sit at the bound for 50.
The robot's pose error, not the choice of poses, limits the hand-eye; planned poses can only
make the rotation's sensor share small and spread the axis directions evenly. Where the
sensor dominates (a 1 um robot), 20 planned poses do match 50 random ones.

Run from the repository root (not part of the test suite)::

    .venv/bin/python bench/planning.py                # 20 seeds, 50 scenes
    .venv/bin/python bench/planning.py --quick        # 4 seeds, 8 scenes
    .venv/bin/python bench/planning.py --only sphere --figures /tmp   # and the 1 sigma plot
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import (
    FloatArray,
    invert_transform,
    transform_error,
    transform_from_rotvec_translation,
)
from linelaser_calib.core.pipeline import PipelineConfig, calibrate_samples
from linelaser_calib.core.planning import (
    PlanConstraints,
    SigmaPoint,
    plan_for_target,
    plan_poses,
    plannable,
    predicted_curve,
    with_noise_levels,
)
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.cylinder import CylinderConfig
from linelaser_calib.core.targets.cylinder.plan import placement
from linelaser_calib.core.targets.sphere import SphereConfig
from linelaser_calib.core.targets.sphere.plan import SpherePlacement
from linelaser_calib.core.types import Sample
from linelaser_calib.sim import Scenario, random_scenario, scenario_from_preset
from linelaser_calib.sim.poses import sample_sensor_poses
from linelaser_calib.sim.profiler import Trace, measure, trace
from linelaser_calib.sim.robot import draw_errors
from linelaser_calib.sim.scene import Scene
from linelaser_calib.sim.sphere import (
    Ball,
    SphereScenario,
    sphere_scenario_from_preset,
    sphere_views,
    trace_ball,
)

PAPER_NOISE = {
    "sigma_depth_m": 5e-6,
    "sigma_lateral_m": 5e-6,
    "robot_sigma_translation_m": 1e-4,
    "robot_sigma_rotation_rad": math.radians(0.01),
}
RANDOM_COUNTS = (8, 12, 16, 20, 30, 50)
#: Planned poses per round after the 3 exploratory scans: totals 8, 12, 16, 20.
ROUNDS = (5, 4, 4, 4)
EXPLORATORY = 3
INITIAL_ERROR = (2e-3, math.radians(1.0))
SUCCESS = (0.5e-3, math.radians(0.1))
FINE = (0.1e-3, math.radians(0.02))
#: Pose counts of the best possible sets.
BOUND_COUNTS = (8, 12, 16, 20, 30, 50)
#: The perfect sensor's σ as a share of the real one: the information has converged (1/10
#: and 1/30 agree within 1 %), whereas below 1/30 the Schur complement of each profile's pose
#: loses precision (the directions the cylinder cannot see carry no information at all).
PERFECT_SENSOR = 1.0 / 20.0
#: Feasible candidates the best possible sets are chosen from.
BOUND_CANDIDATES = 2000
#: Seeds (reach boxes) of the best possible sets: they differ by less than 1 %.
BOUND_SEEDS = 3


@dataclass
class Point:
    """One calibration: poses used, true errors (deg, mm), its 1 sigma (deg, mm), and the
    planner's prediction of that 1 sigma before the poses were scanned (deg, mm)."""

    poses: int
    error_deg: float
    error_mm: float
    sigma_deg: float
    sigma_mm: float
    planner_deg: float = math.nan
    planner_mm: float = math.nan


@dataclass(frozen=True)
class Setup:
    """A simulated set-up: its rig (profiler, robot, true hand-eye), its target and how the
    simulator casts rays at it and draws its random rule-abiding views."""

    rig: Scenario
    target: str
    config: Any
    radius_m: float
    table_height_m: float
    extent: Any
    trace: Callable[[FloatArray], Trace]
    views: Callable[[np.random.Generator, int], FloatArray]
    placement: Any

    def constraints(self, reach_centre: FloatArray) -> PlanConstraints:
        """The planner's constraints for the simulated profiler."""
        rig = self.rig
        return PlanConstraints(
            z_min_m=rig.z_min_m,
            z_max_m=rig.z_max_m,
            fan_half_angle_rad=rig.fan_half_angle_rad,
            resolution=rig.resolution,
            reach_centre_m=(float(reach_centre[0]), float(reach_centre[1]), float(reach_centre[2])),
            table_height_m=self.table_height_m,
            clearance_m=rig.clearance_m,
        )


def _robot(rig: Scenario) -> dict[str, float]:
    """The robot prior of the calibration: the simulated robot's 1 sigma, as a user who knows
    the arm's repeatability sets it."""
    return {
        "robot_sigma_t_m": rig.robot_sigma_translation_m,
        "robot_sigma_r_rad": rig.robot_sigma_rotation_rad,
    }


def cylinder_setup(scenario: Scenario) -> Setup:
    scene = Scene.from_scenario(scenario)
    return Setup(
        scenario,
        "cylinder",
        with_noise_levels(CylinderConfig(radius_m=scenario.cylinder_radius_m), _robot(scenario)),
        scenario.cylinder_radius_m,
        float(scenario.cylinder_base_m[2]),
        (0.0, scenario.cylinder_length_m),
        lambda T: trace(scene, scenario, T),
        lambda rng, n: sample_sensor_poses(rng, replace(scenario, n_poses=n), scene).T_base_sensor,
        placement(scenario.cylinder(), (0.0, scenario.cylinder_length_m)),
    )


def sphere_setup(scenario: SphereScenario) -> Setup:
    ball = Ball.from_scenario(scenario)
    rig = scenario.rig
    return Setup(
        rig,
        "sphere",
        with_noise_levels(SphereConfig(radius_m=scenario.radius_m), _robot(rig)),
        scenario.radius_m,
        scenario.centre_m[2] - scenario.radius_m - scenario.table_gap_m,
        None,
        lambda T: trace_ball(ball, rig, T),
        lambda rng, n: sphere_views(replace(scenario, rig=replace(rig, n_poses=n)), ball, rng),
        SpherePlacement(scenario.centre, scenario.radius_m, scenario.centre_side),
    )


def scan(
    rng: np.random.Generator, setup: Setup, T_base_flange: FloatArray, first_index: int
) -> list[Sample]:
    """Profiles at commanded flange poses (K, 4, 4): the robot misses each by its random
    error, the recorded pose is the commanded one."""
    rig = setup.rig
    errors = draw_errors(rng, rig, len(T_base_flange))
    E = np.stack([transform_from_rotvec_translation(e[3:], e[:3]) for e in errors])
    true_flange = T_base_flange @ np.stack([invert_transform(e) for e in E])
    measured = measure(rng, rig, setup.trace(true_flange @ rig.T_flange_sensor))
    return [
        Sample(
            first_index + k,
            (first_index + k) * 1_000_000_000,
            T_base_flange[k],
            measured.points[k][measured.valid[k]],
        )
        for k in range(len(T_base_flange))
    ]


def calibrate(samples: list[Sample], setup: Setup, seed: int) -> CalibrationResult | None:
    config = PipelineConfig(target=setup.target, target_config=setup.config, seed=seed)
    try:
        return calibrate_samples(samples, config)
    except CalibrationError:
        return None


def point(result: CalibrationResult | None, T_true: FloatArray, poses: int) -> Point:
    if result is None:
        return Point(poses, math.nan, math.nan, math.nan, math.nan)
    rotation, translation = transform_error(result.T_flange_sensor, T_true)
    assert result.uncertainty_rotation_rad is not None
    assert result.uncertainty_translation_m is not None
    return Point(
        poses,
        math.degrees(rotation),
        translation * 1e3,
        math.degrees(float(np.linalg.norm(result.uncertainty_rotation_rad))),
        float(np.linalg.norm(result.uncertainty_translation_m)) * 1e3,
    )


def initial_guess(rng: np.random.Generator, T_true: FloatArray) -> FloatArray:
    """The truth moved by INITIAL_ERROR in random directions (a CAD hand-eye)."""
    t_dir, r_dir = rng.normal(size=(2, 3))
    bump = transform_from_rotvec_translation(
        r_dir / np.linalg.norm(r_dir) * INITIAL_ERROR[1],
        t_dir / np.linalg.norm(t_dir) * INITIAL_ERROR[0],
    )
    return np.asarray(T_true @ bump)


@dataclass
class PlannedRun:
    """A planned run: a point after each round, the last result, and the 1 sigma curves
    predicted by each round's plan and achieved by each round's calibration."""

    points: list[Point]
    result: CalibrationResult | None
    predicted: list[SigmaPoint]
    achieved: list[SigmaPoint]


def planned_run(setup: Setup, seed: int, rounds: tuple[int, ...]) -> PlannedRun:
    """3 exploratory scans, then rounds of planned poses; a point after each round."""
    rng = np.random.default_rng(seed)
    T_true = setup.rig.T_flange_sensor
    explore = setup.views(rng, EXPLORATORY)
    samples = scan(rng, setup, explore @ invert_transform(T_true), 0)
    constraints = setup.constraints(samples[0].T_base_flange[:3, 3])
    T_estimate, section = initial_guess(rng, T_true), None
    run = PlannedRun([], None, [], [])
    for n in rounds:
        plan = plan_for_target(
            get_target(setup.target),
            setup.config,
            T_estimate,
            n,
            samples=samples,
            section=section,
            extent=setup.extent,
            constraints=constraints,
            seed=seed + len(samples),
        )
        run.predicted += predicted_curve(plan)
        T_flange = np.stack([p.T_base_flange for p in plan.poses])
        samples += scan(rng, setup, T_flange, len(samples))
        result = run.result = calibrate(samples, setup, seed)
        last = point(result, T_true, len(samples))
        last.planner_deg = math.degrees(float(np.linalg.norm(plan.poses[-1].sigma_rotation_rad)))
        last.planner_mm = float(np.linalg.norm(plan.poses[-1].sigma_translation_m)) * 1e3
        run.points.append(last)
        if result is not None:
            T_estimate, section = result.T_flange_sensor, result.target
            sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
            if sigma_t is not None and sigma_r is not None:
                run.achieved.append((len(samples), sigma_t, sigma_r))
    return run


def random_run(setup: Setup, seed: int) -> list[Point]:
    rng = np.random.default_rng(seed)
    T_true = setup.rig.T_flange_sensor
    views = setup.views(rng, max(RANDOM_COUNTS))
    samples = scan(rng, setup, views @ invert_transform(T_true), 0)
    return [point(calibrate(samples[:k], setup, seed), T_true, k) for k in RANDOM_COUNTS]


def best_possible(setup: Setup, seed: int, n: int) -> tuple[FloatArray, FloatArray]:
    """Predicted 1σ (translation (3,) m, rotation (3,) rad) of the best ``n`` poses for a
    perfect sensor: the planner on the true placement and hand-eye, the sensor's σ times
    PERFECT_SENSOR, BOUND_CANDIDATES feasible candidates, the reach box of the seed's planned
    run."""
    rng = np.random.default_rng(seed)
    T_true = setup.rig.T_flange_sensor
    first = setup.views(rng, EXPLORATORY)[0] @ invert_transform(T_true)
    sensor_sigma = setup.config.refine.sensor_sigma_m * PERFECT_SENSOR
    plan = plan_poses(
        plannable(get_target(setup.target)),
        setup.placement,
        T_true,
        with_noise_levels(setup.config, {"sensor_sigma_m": sensor_sigma}),
        n,
        rng,
        setup.constraints(first[:3, 3]),
        candidates=BOUND_CANDIDATES,
    )
    last = plan.poses[-1]
    return last.sigma_translation_m, last.sigma_rotation_rad


def _rms(values: list[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return float(np.sqrt(np.mean(np.square(finite)))) if finite else math.nan


def curve(setup: Setup, label: str, seeds: int, figure_dir: Path | None) -> None:
    runs = [planned_run(setup, seed, ROUNDS) for seed in range(seeds)]
    planned = [run.points for run in runs]
    if figure_dir is not None:
        from linelaser_calib.report.figures import DPI, sigma_curve_figure

        path = figure_dir / f"planning_{label}.png"
        sigma_curve_figure(runs[0].predicted, runs[0].achieved).savefig(path, dpi=DPI)
        print(f"\nWrote {path} (seed 0: predicted and achieved 1 sigma against poses)")
    randoms = [random_run(setup, seed) for seed in range(seeds)]
    print(f"\n### Hand-eye accuracy against poses ({seeds} seeds, {label}, paper noise)\n")
    print(
        "RMS over seeds; 1 sigma is the norm of the per-axis 1 sigma of the calibration; "
        "planner: the planner's prediction of it before the scans (configured noise, then the last "
        "calibration's re-estimated noise); best "
        "possible: the predicted 1 sigma of the best poses for a perfect sensor.\n"
    )
    print(
        "| poses | kind | error deg | error mm | 1 sigma deg | 1 sigma mm | planner deg | "
        "planner mm | failed |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    rows = [("planned", [run[i] for run in planned]) for i in range(len(ROUNDS))]
    rows += [("random", [run[i] for run in randoms]) for i in range(len(RANDOM_COUNTS))]
    for n in BOUND_COUNTS:
        best = [best_possible(setup, seed, n) for seed in range(min(seeds, BOUND_SEEDS))]
        rows.append(
            (
                f"best possible {n}, perfect sensor",
                [
                    Point(
                        n,
                        math.nan,
                        math.nan,
                        math.degrees(float(np.linalg.norm(sigma_r))),
                        float(np.linalg.norm(sigma_t)) * 1e3,
                    )
                    for sigma_t, sigma_r in best
                ],
            )
        )
    for kind, runs in sorted(rows, key=lambda r: (r[1][0].poses, r[0])):
        failed = "-" if kind.startswith("best") else sum(not np.isfinite(p.error_deg) for p in runs)
        print(
            f"| {runs[0].poses} | {kind} | {_rms([p.error_deg for p in runs]):.4f} | "
            f"{_rms([p.error_mm for p in runs]):.4f} | {_rms([p.sigma_deg for p in runs]):.4f} | "
            f"{_rms([p.sigma_mm for p in runs]):.4f} | {_rms([p.planner_deg for p in runs]):.4f} | "
            f"{_rms([p.planner_mm for p in runs]):.4f} | {failed} |"
        )
    if setup.target == "cylinder":
        sigma_t = setup.rig.robot_sigma_translation_m
        print(
            "\nNo set of N poses can do better in translation than 3 sigma_t / sqrt(2 N) (the "
            "module docstring): "
            + ", ".join(
                f"{n}: {3.0 * sigma_t / math.sqrt(2.0 * n) * 1e3:.4f} mm" for n in BOUND_COUNTS
            )
        )


def upright_scene(rng: np.random.Generator) -> Scenario:
    """A random scene with a vertical shaft standing on a table 0.35-0.6 m from the robot."""
    distance, bearing = rng.uniform(0.35, 0.6), rng.uniform(-math.pi, math.pi)
    base = (distance * math.cos(bearing), distance * math.sin(bearing), 0.0)
    return random_scenario(
        rng,
        axis_direction=(0.0, 0.0, 1.0),
        cylinder_base_m=base,
        background="table",
        pose_mode="paper",
        n_poses=EXPLORATORY,
    )


def cold(scenes: int) -> None:
    rng = np.random.default_rng(1000)
    right, fine, notes = 0, 0, []
    for k in range(scenes):
        scenario = upright_scene(rng)
        noise = (
            f"robot {scenario.robot_sigma_translation_m * 1e3:.3f} mm, sensor "
            f"{scenario.sigma_depth_m * 1e6:.0f} um"
        )
        try:
            run = planned_run(cylinder_setup(scenario), k, ROUNDS)
            points, result = run.points, run.result
        except CalibrationError as exc:
            notes.append(f"FAILED scene {k}: {exc}"[:200])
            continue
        if result is None:
            notes.append(f"FAILED scene {k}: no result ({noise})")
            continue
        rotation, translation = transform_error(result.T_flange_sensor, scenario.T_flange_sensor)
        last = points[-1]
        text = (
            f"scene {k}: {last.error_mm:.4f} mm, {last.error_deg:.4f} deg (its 1 sigma "
            f"{last.sigma_mm:.4f} mm, {last.sigma_deg:.4f} deg; {noise})"
        )
        if translation <= SUCCESS[0] and rotation <= SUCCESS[1]:
            right += 1
            if translation <= FINE[0] and rotation <= FINE[1]:
                fine += 1
            else:
                notes.append(f"coarse {text}")
        else:
            notes.append(f"WRONG {text}")
    print(f"\n### Cold start: 3 exploratory scans + 17 planned poses, {scenes} random scenes\n")
    print(
        f"success (error <= {SUCCESS[0] * 1e3:.1f} mm and {math.degrees(SUCCESS[1]):.1f} deg): "
        f"{right}/{scenes} = {100.0 * right / scenes:.0f} %; within {FINE[0] * 1e3:.1f} mm "
        f"and {math.degrees(FINE[1]):.2f} deg: {fine}/{scenes}"
    )
    for note in notes:
        print(f"  {note}")


def speed() -> None:
    scenario = scenario_from_preset("ur_scancontrol", **PAPER_NOISE)
    setup = cylinder_setup(scenario)
    rng = np.random.default_rng(0)
    T_true = scenario.T_flange_sensor
    samples = scan(rng, setup, setup.views(rng, 20) @ invert_transform(T_true), 0)
    result = calibrate(samples, setup, 0)
    assert result is not None
    config = setup.config
    constraints = setup.constraints(samples[0].T_base_flange[:3, 3])
    span = setup.extent
    cases = {
        "from a result and 20 scans": {"samples": samples, "section": result.target},
        "from a given axis, no scan": {"numbers": [0.45, 0.15, 0.0, 0.0, 0.0, 1.0]},
    }
    print("\n### Planning 10 poses (median of 5, s)\n")
    for name, inputs in cases.items():
        times = []
        for _ in range(5):
            started = time.perf_counter()
            plan_for_target(
                get_target("cylinder"),
                config,
                result.T_flange_sensor,
                10,
                extent=span,
                constraints=constraints,
                **inputs,  # type: ignore[arg-type]
            )
            times.append(time.perf_counter() - started)
        print(f"- {name}: {np.median(times):.3f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--only", choices=("curve", "sphere", "cold", "speed"))
    parser.add_argument(
        "--figures",
        type=Path,
        metavar="DIR",
        help="write the predicted and achieved 1 sigma curves of seed 0 as PNG files into DIR",
    )
    parser.add_argument(
        "--robot-noise",
        metavar="T_M,R_DEG",
        help="robot 1 sigma per axis of the curve and sphere sections instead of the paper's "
        "0.0001,0.01 (translation m, rotation deg); e.g. 1e-6,1e-4 for a sensor-limited "
        "recording, as the paper's own noise study (noise on the centres only)",
    )
    args = parser.parse_args()
    noise = dict(PAPER_NOISE)
    if args.robot_noise is not None:
        t_m, r_deg = (float(v) for v in args.robot_noise.split(","))
        noise["robot_sigma_translation_m"] = t_m
        noise["robot_sigma_rotation_rad"] = math.radians(r_deg)
    seeds, scenes = (4, 8) if args.quick else (20, 50)
    if args.only in (None, "speed"):
        speed()
    if args.only in (None, "curve"):
        curve(
            cylinder_setup(scenario_from_preset("ur_scancontrol", **noise)),
            "ur_scancontrol",
            seeds,
            args.figures,
        )
    if args.only in (None, "sphere"):
        sphere = sphere_setup(sphere_scenario_from_preset("sphere", **noise))
        curve(sphere, "sphere", seeds, args.figures)
    if args.only in (None, "cold"):
        cold(scenes)


if __name__ == "__main__":
    main()
