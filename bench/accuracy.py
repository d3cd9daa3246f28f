"""Goals of issues #3 and #4 on full simulator data through the real pipeline.

Every section simulates profiles and the streamed flange poses with the package simulator
(ray-cast profiles, robot and sensor noise), then calibrates them with the package pipeline:

``accuracy``
    Through real bags: simulate → ``write_bag`` → ``calibrate_bag`` (read, pair, fit, solve),
    ``--method paper`` and ``default``; RMS over seeds of the hand-eye rotation error (deg)
    and translation error (mm) on the ``paper`` preset (the paper's §4.1.1 noise) and on
    ``ur_scancontrol``.
``robustness``
    ``random_scenario`` scenes (random hand-eye, axis anywhere in any direction, cuts
    40-75 deg, 12-100 poses), no initial guess: simulate → ``run_pipeline`` (no bag).
``honesty``
    Share of seeds whose true error lies within the predicted 1σ, per axis: simulate →
    ``run_pipeline`` (no bag), ``paper`` preset.
``speed``
    Through real bags, one process: the time of each stage (read the bag, pair, clean and
    fit the ellipses, seed solve, refine) against the number of profiles.
``outliers``
    5 % spike points per profile and 10 % of the samples paired with a wrong flange pose:
    simulate → ``pair_profiles`` → poses swapped among the corrupted samples →
    ``calibrate_samples`` (no bag).
``cluttered``
    The ``cluttered_camera`` preset (a coarse camera profiler, background plane, fixture,
    clustered poses, a robot error field): share of the profiles used, hand-eye error,
    |error| / predicted 1σ, the free radius: simulate → ``run_pipeline`` (no bag).
``scale``
    The sensor's along-line scale fixed against estimated (``--scale fixed|free``), radius free
    and given, on ``cluttered_camera`` (a 0.5 % scale error) and on the presets without one
    (they must not move): hand-eye error, |error| / 1σ per axis, share within 1σ, the
    estimated scale against the truth: simulate → ``run_pipeline`` (no bag).

A summary table of every goal with its measured value and PASS/FAIL ends the run. Timings
are medians (the machine is shared); ``--workers`` runs the seeds of the non-timing sections
in parallel processes. Not part of the test suite.

Run from the repository root::

    .venv/bin/python bench/accuracy.py               # everything, goal-sized counts
    .venv/bin/python bench/accuracy.py --quick       # small counts, a minute or two
    .venv/bin/python bench/accuracy.py --only speed --profiles 12 50 500
    .venv/bin/python bench/accuracy.py --only scale --scale-seeds 20
"""

from __future__ import annotations

import argparse
import multiprocessing
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import FloatArray, rotvec_from_matrix, transform_error
from linelaser_calib.core.pairing import pair_profiles
from linelaser_calib.core.pipeline import (
    Method,
    PipelineConfig,
    calibrate_samples,
    run_pipeline,
)
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder import CylinderConfig, CylinderSection
from linelaser_calib.core.types import Sample
from linelaser_calib.io import read_bag, write_bag
from linelaser_calib.offline import calibrate_bag
from linelaser_calib.sim import SimulatedData, random_scenario, scenario_from_preset, simulate

T = TypeVar("T")
R = TypeVar("R")

#: Goals (issue #4; issue #3 for the paper method's robustness).
GOAL_ROT_DEG, GOAL_TRANS_MM, GOAL_RATIO = 0.01, 0.06, 10.0
SUCCESS_DEFAULT = (0.1, 0.2)  # deg, mm
SUCCESS_PAPER = (2.0, 5.0)  # deg, mm: "the accuracy this method can give"
HONEST_SHARE, HONEST_TOLERANCE = 0.6827, 0.10
#: The band around HONEST_SHARE is at least this many binomial standard deviations of a
#: share over the seeds: ±0.10 is 2.6 of them at 150 seeds, but only 0.9 at --quick's 16,
#: where an honest 1σ then fails the check by chance one run in three.
HONEST_BINOMIAL_SIGMAS = 2.5
GOAL_TIME_50_S, GOAL_TIME_500_S = 0.5, 5.0
OUTLIER_ERROR_FACTOR = 2.0
SPIKE_FRACTION, WRONG_POSE_FRACTION = 0.05, 0.10
#: Seeds of the random scenes start here (scene i draws from default_rng(RANDOM_BASE + i)).
RANDOM_BASE = 40_000
AXES = ("θx", "θy", "θz", "ρx", "ρy", "ρz")


@dataclass(frozen=True)
class Goal:
    """One line of the summary."""

    name: str
    measured: str
    passed: bool


# ----------------------------------------------------------------------------- helpers


def errors_deg_mm(result: CalibrationResult, T_true: FloatArray) -> tuple[float, float]:
    """Hand-eye rotation error (deg) and translation error (mm)."""
    rotation, translation = transform_error(result.T_flange_sensor, T_true)
    return float(np.degrees(rotation)), translation * 1e3


def axis_errors(result: CalibrationResult, T_true: FloatArray) -> FloatArray:
    """[θ (rad, sensor axes), ρ (m, flange axes)], truth = estimate ∘ (Exp θ, +ρ): the
    parametrisation of the predicted 1σ (``core.targets.cylinder.refine``)."""
    T_est = result.T_flange_sensor
    theta = rotvec_from_matrix(T_est[:3, :3].T @ T_true[:3, :3])
    return np.concatenate([theta, T_true[:3, 3] - T_est[:3, 3]])


def rms(values: Iterable[float]) -> float:
    return float(np.sqrt(np.mean(np.square(list(values)))))


def parallel_map(function: Callable[[T], R], items: Sequence[T], workers: int) -> list[R]:
    """``map`` over processes (fork), in order; inline with one worker."""
    if workers <= 1 or len(items) <= 1:
        return [function(item) for item in items]
    context = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        return list(pool.map(function, items, chunksize=1))


def print_table(title: str, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """A markdown table."""
    print(f"\n### {title}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(_cell(v) for v in row) + " |")


def _cell(value: object) -> str:
    if isinstance(value, float):
        if value == 0.0 or not np.isfinite(value):
            return f"{value:g}"
        return f"{value:.3g}" if abs(value) < 1e-3 or abs(value) >= 1e4 else f"{value:.4f}"
    return str(value)


# ---------------------------------------------------------------------------- accuracy


def _accuracy_run(job: tuple[str, int]) -> dict[str, Any]:
    """One seed of one preset through a bag, both methods."""
    preset, seed = job
    data = simulate(scenario_from_preset(preset), seed)
    workdir = Path(tempfile.mkdtemp(prefix="accuracy_"))
    try:
        bag = write_bag(
            workdir / "bag",
            data.profiles,
            data.poses,
            organised=data.scenario.organised,
            intensities=data.intensities,
        )
        out: dict[str, Any] = {"preset": preset, "seed": seed}
        for method in Method:
            start = time.perf_counter()
            run = calibrate_bag(bag, PipelineConfig(method=method, seed=seed))
            out[method.value] = (
                *errors_deg_mm(run.result, data.truth.T_flange_sensor),
                time.perf_counter() - start,
            )
        return out
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def accuracy(seeds: int, workers: int) -> list[Goal]:
    jobs = [(preset, seed) for preset in ("paper", "ur_scancontrol") for seed in range(seeds)]
    runs = parallel_map(_accuracy_run, jobs, workers)
    rows: list[list[object]] = []
    ratios: dict[str, tuple[float, float]] = {}
    rms_default: dict[str, tuple[float, float]] = {}
    for preset in ("paper", "ur_scancontrol"):
        mine = [r for r in runs if r["preset"] == preset]
        summary = {}
        for method in ("paper", "default"):
            rot = [r[method][0] for r in mine]
            trans = [r[method][1] for r in mine]
            summary[method] = (rms(rot), rms(trans))
            rows.append(
                [
                    preset,
                    method,
                    len(mine),
                    rms(rot),
                    rms(trans),
                    max(rot),
                    max(trans),
                    float(np.median([r[method][2] for r in mine])),
                ]
            )
        ratios[preset] = (
            summary["paper"][0] / summary["default"][0],
            summary["paper"][1] / summary["default"][1],
        )
        rms_default[preset] = summary["default"]
        rows.append([preset, "ratio paper/default", "", *ratios[preset], "", "", ""])
    print_table(
        "Accuracy: simulate → write_bag → calibrate_bag; hand-eye error over seeds",
        [
            "preset",
            "method",
            "seeds",
            "RMS rot (deg)",
            "RMS trans (mm)",
            "max rot (deg)",
            "max trans (mm)",
            "median time (s)",
        ],
        rows,
    )
    rot_rms, trans_rms = rms_default["paper"]
    ratio_rot, ratio_trans = ratios["paper"]
    return [
        Goal(
            f"accuracy paper preset, default RMS rot ≤ {GOAL_ROT_DEG} deg ({seeds} seeds)",
            f"{rot_rms:.4f} deg",
            rot_rms <= GOAL_ROT_DEG,
        ),
        Goal(
            f"accuracy paper preset, default RMS trans ≤ {GOAL_TRANS_MM} mm",
            f"{trans_rms:.4f} mm",
            trans_rms <= GOAL_TRANS_MM,
        ),
        Goal(
            f"accuracy ratio paper/default rot ≥ {GOAL_RATIO:g}",
            f"{ratio_rot:.1f}",
            ratio_rot >= GOAL_RATIO,
        ),
        Goal(
            f"accuracy ratio paper/default trans ≥ {GOAL_RATIO:g}",
            f"{ratio_trans:.1f}",
            ratio_trans >= GOAL_RATIO,
        ),
    ]


# -------------------------------------------------------------------------- robustness


def _describe(data: SimulatedData) -> str:
    s = data.scenario
    return (
        f"{s.n_poses} poses, R {s.cylinder_radius_m * 1e3:.1f} mm, |t| "
        f"{np.linalg.norm(s.hand_eye_translation_m) * 1e3:.0f} mm, sensor σ "
        f"{s.sigma_depth_m * 1e6:.0f} µm, robot σ {s.robot_sigma_translation_m * 1e3:.3f} mm / "
        f"{np.degrees(s.robot_sigma_rotation_rad):.4f} deg, {s.background}"
    )


def _robustness_run(job: tuple[int, tuple[str, ...]]) -> dict[str, Any]:
    """One random scene: the outcome of each method (errors, or the failure reason)."""
    index, methods = job
    scenario = random_scenario(np.random.default_rng(RANDOM_BASE + index))
    out: dict[str, Any] = {"index": index}
    try:
        data = simulate(scenario, index)
    except CalibrationError as err:
        out["scene"] = f"simulator: {err}"
        return out
    out["scene_text"] = _describe(data)
    out["profiles"] = len(data.profiles)
    for name in methods:
        start = time.perf_counter()
        try:
            result = run_pipeline(
                data.profiles, data.poses, PipelineConfig(method=Method(name), seed=index)
            )
        except CalibrationError as err:
            out[name] = {"error": f"{type(err).__name__}: {err}"}
            continue
        rot, trans = errors_deg_mm(result, data.truth.T_flange_sensor)
        entry: dict[str, Any] = {
            "rot": rot,
            "trans": trans,
            "time": time.perf_counter() - start,
            "used": len(result.samples_used),
        }
        if result.uncertainty_rotation_rad is not None:
            assert result.uncertainty_translation_m is not None
            sigma = np.concatenate(
                [result.uncertainty_rotation_rad, result.uncertainty_translation_m]
            )
            entry["max_z"] = float(
                np.max(np.abs(axis_errors(result, data.truth.T_flange_sensor)) / sigma)
            )
        out[name] = entry
    return out


def _verdict(entry: dict[str, Any], limits: tuple[float, float]) -> str | None:
    """None on success, else why not."""
    if "error" in entry:
        return str(entry["error"])[:300]
    if entry["rot"] < limits[0] and entry["trans"] < limits[1]:
        return None
    return f"error {entry['rot']:.4f} deg / {entry['trans']:.4f} mm"


def robustness(scenes: int, paper_scenes: int, workers: int) -> list[Goal]:
    jobs = [
        (i, ("default", "paper") if i < paper_scenes else ("default",))
        for i in range(max(scenes, paper_scenes))
    ]
    runs = parallel_map(_robustness_run, jobs, workers)
    impossible = [r for r in runs if "scene" in r]
    goals = []
    rows: list[list[object]] = []
    notes: list[str] = []  # printed after the table
    for name, limits, count in (
        ("default", SUCCESS_DEFAULT, scenes),
        ("paper", SUCCESS_PAPER, paper_scenes),
    ):
        mine = [r for r in runs if name in r][:count]
        failures = [(r, _verdict(r[name], limits)) for r in mine]
        failures = [(r, why) for r, why in failures if why is not None]
        ok = [r[name] for r in mine if "rot" in r[name]]
        rows.append(
            [
                name,
                f"< {limits[0]:g} deg and < {limits[1]:g} mm",
                f"{len(mine) - len(failures)}/{len(mine)}",
                float(np.median([e["rot"] for e in ok])) if ok else float("nan"),
                float(np.max([e["rot"] for e in ok])) if ok else float("nan"),
                float(np.median([e["trans"] for e in ok])) if ok else float("nan"),
                float(np.max([e["trans"] for e in ok])) if ok else float("nan"),
                float(np.median([e["time"] for e in ok])) if ok else float("nan"),
                float(np.max([e["time"] for e in ok])) if ok else float("nan"),
            ]
        )
        notes += [
            f"FAIL {name} scene {r['index']} ({r.get('scene_text', '')}): {why}"
            for r, why in failures
        ]
        if name == "default":
            ratios = [e["max_z"] for e in ok if "max_z" in e]
            beyond = [r for r in mine if r[name].get("max_z", 0.0) > 5.0]
            notes += [
                f"note default scene {r['index']}: an axis error is {r[name]['max_z']:.1f} x "
                f"its predicted 1σ ({r['scene_text']})"
                for r in beyond
            ]
            if ratios:
                notes.append(
                    "default: largest axis error / predicted 1σ per scene: median "
                    f"{np.median(ratios):.2f}, max {np.max(ratios):.2f}, above 5: {len(beyond)}"
                )
        goals.append(
            Goal(
                f"robustness {name}: success on random scenes ({rows[-1][1]})",
                f"{rows[-1][2]}",
                not failures and len(mine) == count,
            )
        )
    print_table(
        "Robustness: random_scenario → simulate → run_pipeline, no initial guess",
        [
            "method",
            "success",
            "succeeded",
            "median rot (deg)",
            "max rot (deg)",
            "median trans (mm)",
            "max trans (mm)",
            "median time (s)",
            "max time (s)",
        ],
        rows,
    )
    notes += [f"scene {r['index']} could not be simulated: {r['scene']}" for r in impossible]
    print("\n" + "\n".join(notes))
    if impossible:
        goals.append(
            Goal(
                "robustness: random_scenario gives simulable scenes",
                f"{len(runs) - len(impossible)}/{len(runs)}",
                False,
            )
        )
    return goals


# ----------------------------------------------------------------------------- honesty


def _honesty_run(seed: int) -> tuple[FloatArray, FloatArray] | str:
    data = simulate(scenario_from_preset("paper"), 1000 + seed)
    try:
        result = run_pipeline(data.profiles, data.poses, PipelineConfig(seed=seed))
    except CalibrationError as err:
        return f"seed {seed}: {err}"
    assert result.uncertainty_rotation_rad is not None
    assert result.uncertainty_translation_m is not None
    sigma = np.concatenate([result.uncertainty_rotation_rad, result.uncertainty_translation_m])
    return axis_errors(result, data.truth.T_flange_sensor), sigma


def honesty(seeds: int, workers: int) -> list[Goal]:
    outcomes = parallel_map(_honesty_run, list(range(seeds)), workers)
    for failure in (o for o in outcomes if isinstance(o, str)):
        print(f"FAIL honesty {failure}")
    pairs = [o for o in outcomes if not isinstance(o, str)]
    errors = np.array([e for e, _ in pairs])
    sigmas = np.array([s for _, s in pairs])
    inside = np.abs(errors) <= sigmas
    share = inside.mean(axis=0)
    ratio = errors.std(axis=0) / np.sqrt(np.mean(sigmas**2, axis=0))
    scale = [1e3 * 180 / np.pi] * 3 + [1e6] * 3  # mdeg, µm
    rows = [
        [
            axis,
            f"{100 * share[i]:.0f} %",
            float(np.sqrt(np.mean(sigmas[:, i] ** 2)) * scale[i]),
            float(errors[:, i].std() * scale[i]),
            float(ratio[i]),
        ]
        for i, axis in enumerate(AXES)
    ]
    print_table(
        f"Honest uncertainty: paper preset, {len(pairs)} seeds, simulate → run_pipeline; "
        "θ in mdeg (sensor axes), ρ in µm (flange axes)",
        ["axis", "within 1σ (68 % expected)", "RMS predicted σ", "empirical std", "std / σ"],
        rows,
    )
    spread = HONEST_BINOMIAL_SIGMAS * np.sqrt(
        HONEST_SHARE * (1.0 - HONEST_SHARE) / max(len(pairs), 1)
    )
    tolerance = max(HONEST_TOLERANCE, float(spread))
    low, high = HONEST_SHARE - tolerance, HONEST_SHARE + tolerance
    shares = " ".join(f"{a} {100 * s:.0f}%" for a, s in zip(AXES, share, strict=True))
    return [
        Goal(
            f"honesty: every axis within 1σ in {100 * low:.0f}-{100 * high:.0f} % "
            f"({len(pairs)} seeds)",
            shares,
            bool(np.all((share >= low) & (share <= high))) and len(pairs) == seeds,
        )
    ]


# ------------------------------------------------------------------------------- speed


STAGES = ("read", "pair", "ellipse", "seed solve", "refine", "total")
#: Rays per profile of the speed runs: 2100 put ~790 points on the paper preset's Ø40 mm
#: cylinder (the goal's "800 points per profile"); the preset's own 800 rays put ~300.
SPEED_RESOLUTION = 2100


def _timed_calibration(bag: Path) -> dict[str, float]:
    """Stage times (s) of one calibration of a bag: read_bag, then run_pipeline's stages.

    ``calibrate_bag`` is exactly ``read_bag`` followed by ``run_pipeline``; the pipeline's
    own progress callbacks mark the ends of its stages.
    """
    start = time.perf_counter()
    contents = read_bag(bag)
    marks: dict[str, float] = {}

    def progress(stage: str, done: int, total: int) -> None:
        if done == total:
            marks[stage] = time.perf_counter()

    begin = time.perf_counter()
    run_pipeline(contents.profiles, contents.poses, PipelineConfig(), progress)
    end = time.perf_counter()
    return {
        "read": begin - start,
        "pair": marks["pairing"] - begin,
        "ellipse": marks["ellipse"] - marks["pairing"],
        "seed solve": marks["global solve"] - marks["ellipse"],
        "refine": marks["refine"] - marks["global solve"],
        "total": end - start,
    }


def speed(profile_counts: Sequence[int], repeats: int, resolution: int) -> list[Goal]:
    rows: list[list[object]] = []
    totals: dict[int, float] = {}
    with tempfile.TemporaryDirectory(prefix="speed_") as workdir:
        for n in profile_counts:
            scenario = scenario_from_preset("paper", n_poses=n, resolution=resolution)
            data = simulate(scenario, 0)
            points = float(np.mean([np.isfinite(p.points[:, 0]).sum() for p in data.profiles]))
            bag = write_bag(Path(workdir) / f"bag_{n}", data.profiles, data.poses)
            runs = repeats if n <= 100 else 1 + repeats // 2
            times = [_timed_calibration(bag) for _ in range(runs)]
            median = {s: float(np.median([t[s] for t in times])) for s in STAGES}
            totals[n] = median["total"]
            rows.append([n, len(data.poses), round(points), *(median[s] for s in STAGES)])
    print_table(
        f"Speed: paper preset, {resolution}-ray profiler, bag → read_bag → run_pipeline "
        "(default method), median s per stage",
        ["profiles", "poses in bag", "points/profile", *(f"{s} (s)" for s in STAGES)],
        rows,
    )
    goals = []
    for n, limit in ((50, GOAL_TIME_50_S), (500, GOAL_TIME_500_S)):
        if n in totals:
            goals.append(
                Goal(
                    f"speed: {n} profiles, whole pipeline ≤ {limit:g} s (median)",
                    f"{totals[n]:.3f} s",
                    totals[n] <= limit,
                )
            )
    return goals


# ---------------------------------------------------------------------------- outliers


def _paired(data: SimulatedData) -> list[Sample]:
    return pair_profiles(data.profiles, data.poses, PipelineConfig().pairing).samples


def _outlier_run(seed: int) -> dict[str, Any]:
    """Clean and corrupted calibration of one seed (different noise draws, same preset)."""
    scenario = scenario_from_preset("paper")
    clean = calibrate_samples(_paired(simulate(scenario, 2000 + seed)), PipelineConfig(seed=seed))
    data = simulate(replace(scenario, spike_fraction=SPIKE_FRACTION), 2000 + seed)
    samples = _paired(data)
    rng = np.random.default_rng(seed)
    count = max(2, round(WRONG_POSE_FRACTION * len(samples)))
    chosen = rng.choice(len(samples), count, replace=False)
    # Each chosen sample gets the flange pose of the next chosen one: all are wrong.
    donors = np.roll(chosen, 1)
    wrong = {int(j): samples[int(k)].T_base_flange for j, k in zip(chosen, donors, strict=True)}
    corrupted = [
        replace(s, T_base_flange=wrong[j]) if j in wrong else s for j, s in enumerate(samples)
    ]
    out: dict[str, Any] = {
        "seed": seed,
        "clean": errors_deg_mm(clean, data.truth.T_flange_sensor),
        "corrupted_indices": sorted(samples[j].index for j in wrong),
    }
    try:
        result = calibrate_samples(corrupted, PipelineConfig(seed=seed))
    except CalibrationError as err:
        out["error"] = f"{type(err).__name__}: {err}"
        return out
    out["outlier"] = errors_deg_mm(result, data.truth.T_flange_sensor)
    dropped = [r for r in result.samples_rejected if r.stage == "outlier"]
    out["dropped"] = sorted(r.index for r in dropped)
    out["reasons"] = [f"#{r.index}: {r.reason}" for r in dropped]
    out["unfitted"] = sorted(
        r.index for r in result.samples_rejected if r.stage in ("cleaning", "ellipse")
    )
    out["spikes"] = int(data.truth.spike.sum()) / max(1, int(data.truth.valid.sum()))
    return out


def outliers(seeds: int, workers: int) -> list[Goal]:
    runs = parallel_map(_outlier_run, list(range(seeds)), workers)
    failed = [r for r in runs if "error" in r]
    for r in failed:
        print(f"FAIL outliers seed {r['seed']}: {r['error'][:300]}")
    done = [r for r in runs if "error" not in r]
    hits = dropped = corrupted = exact = 0
    for r in done:
        bad = set(r["corrupted_indices"]) - set(r["unfitted"])
        got = set(r["dropped"])
        hits += len(bad & got)
        dropped += len(got)
        corrupted += len(bad)
        exact += got == bad
        if got != bad:
            print(
                f"seed {r['seed']}: corrupted {sorted(bad)}, dropped {sorted(got)} "
                f"(not fitted: {r['unfitted']})"
            )
    if done:
        print(f"\nsamples the result lists as outliers, seed {done[0]['seed']}:")
        print("\n".join(f"  {reason}" for reason in done[0]["reasons"]))
    precision = hits / dropped if dropped else 1.0
    recall = hits / corrupted if corrupted else 1.0
    clean_rot, clean_trans = rms(r["clean"][0] for r in done), rms(r["clean"][1] for r in done)
    bad_rot, bad_trans = rms(r["outlier"][0] for r in done), rms(r["outlier"][1] for r in done)
    print_table(
        f"Outliers: paper preset, {100 * SPIKE_FRACTION:g} % spike points per profile and "
        f"{100 * WRONG_POSE_FRACTION:g} % of the samples with a wrong flange pose; "
        "simulate → pair_profiles → swap poses → calibrate_samples (default)",
        ["data", "seeds", "RMS rot (deg)", "RMS trans (mm)"],
        [
            ["clean", len(done), clean_rot, clean_trans],
            ["spikes + wrong poses", len(done), bad_rot, bad_trans],
            ["ratio", "", bad_rot / clean_rot, bad_trans / clean_trans],
        ],
    )
    print(
        f"\nwrong-pose samples dropped as outliers: precision {100 * precision:.1f} %, recall "
        f"{100 * recall:.1f} % ({hits} of {corrupted} corrupted samples found, {dropped} "
        f"dropped); dropped set equal to the corrupted set in {exact}/{len(done)} seeds; "
        f"mean spike share {100 * np.mean([r['spikes'] for r in done]):.1f} % of the points"
    )
    factor = max(bad_rot / clean_rot, bad_trans / clean_trans)
    return [
        Goal(
            f"outliers: error ≤ {OUTLIER_ERROR_FACTOR:g}x the clean case ({len(done)} seeds)",
            f"{factor:.2f}x",
            factor <= OUTLIER_ERROR_FACTOR and not failed,
        ),
        Goal(
            "outliers: dropped samples = corrupted samples",
            f"precision {100 * precision:.0f} %, recall {100 * recall:.0f} %, exact "
            f"{exact}/{len(runs)}",
            exact == len(runs),
        ),
    ]


# -------------------------------------------------------------------------------- main


# --------------------------------------------------------------------------- cluttered

#: Share of the profiles a cluttered camera recording must use.
GOAL_CLUTTERED_SHARE = 0.95


def _cluttered_run(seed: int) -> dict[str, Any]:
    """One ``cluttered_camera`` run (free radius): profiles used, errors, 1σ, warnings."""
    data = simulate(scenario_from_preset("cluttered_camera"), seed)
    try:
        result = run_pipeline(data.profiles, data.poses, PipelineConfig(seed=seed))
    except CalibrationError as err:
        return {"seed": seed, "failure": str(err), "used": 0, "profiles": len(data.profiles)}
    assert result.uncertainty_rotation_rad is not None
    assert result.uncertainty_translation_m is not None
    sigma = np.concatenate([result.uncertainty_rotation_rad, result.uncertainty_translation_m])
    return {
        "seed": seed,
        "used": len(result.samples_used),
        "profiles": len(data.profiles),
        "errors": errors_deg_mm(result, data.truth.T_flange_sensor),
        "ratio": np.abs(axis_errors(result, data.truth.T_flange_sensor)) / sigma,
        "radius_mm": result.target.cylinder.radius * 1e3,
        "trimmed": any(w.startswith("trimmed the grazing") for w in result.warnings),
    }


def cluttered(seeds: int, workers: int) -> list[Goal]:
    runs = parallel_map(_cluttered_run, list(range(seeds)), workers)
    for failure in (r for r in runs if "failure" in r):
        print(f"FAIL cluttered seed {failure['seed']}: {failure['failure']}")
    done = [r for r in runs if "failure" not in r]
    share = sum(r["used"] for r in runs) / sum(r["profiles"] for r in runs)
    rows = [
        [
            r["seed"],
            f"{r['used']}/{r['profiles']}",
            r["errors"][0],
            r["errors"][1],
            float(np.max(r["ratio"])),
            r["radius_mm"],
            "yes" if r["trimmed"] else "no",
        ]
        for r in done
    ]
    print_table(
        "Cluttered camera recording (cluttered_camera preset: background plane, fixture fin, "
        "clustered poses, robot error field, 0.5 % x scale, grazing-angle bias), "
        "simulate → run_pipeline, free radius (truth 12.5 mm)",
        [
            "seed",
            "profiles used",
            "rot err (deg)",
            "trans err (mm)",
            "max |err|/σ",
            "radius (mm)",
            "ends trimmed",
        ],
        rows,
    )
    return [
        Goal(
            f"cluttered: ≥ {100 * GOAL_CLUTTERED_SHARE:.0f} % of the profiles used ({seeds} seeds)",
            f"{100 * share:.1f} %",
            share >= GOAL_CLUTTERED_SHARE,
        )
    ]


# ------------------------------------------------------------------------------- scale

#: Presets of the scale comparison; only ``cluttered_camera`` has a scale error (0.5 %).
SCALE_PRESETS = ("paper", "ur_scancontrol", "ur5e_kinematic", "cluttered_camera")


def _scale_run(job: tuple[str, int]) -> list[dict[str, Any]]:
    """One seed of one preset: scale fixed and estimated, radius free and given."""
    preset, seed = job
    data = simulate(scenario_from_preset(preset), seed)
    out = []
    for radius in (None, data.scenario.cylinder_radius_m):
        for free in (False, True):
            variant = {
                "preset": preset,
                "seed": seed,
                "radius": "free" if radius is None else "given",
                "variant": "free" if free else "fixed",
            }
            config = CylinderConfig(radius_m=radius, scale="free" if free else "fixed")
            try:
                result = run_pipeline(
                    data.profiles, data.poses, PipelineConfig(seed=seed, target_config=config)
                )
            except CalibrationError as err:
                out.append({**variant, "failure": str(err)})
                continue
            assert result.uncertainty_rotation_rad is not None
            assert result.uncertainty_translation_m is not None
            sigma = np.concatenate(
                [result.uncertainty_rotation_rad, result.uncertainty_translation_m]
            )
            section = result.target
            assert isinstance(section, CylinderSection)
            out.append(
                {
                    **variant,
                    "errors": errors_deg_mm(result, data.truth.T_flange_sensor),
                    "ratio": np.abs(axis_errors(result, data.truth.T_flange_sensor)) / sigma,
                    "radius_mm": section.cylinder.radius * 1e3,
                    "scale": section.scale,
                    "scale_sigma": section.scale_sigma,
                    "truth_scale": data.scenario.lateral_scale_error,
                }
            )
            row = out[-1]
            print(
                f"scale {preset} seed {seed} radius {row['radius']} scale {row['variant']}: "
                f"{row['errors'][0]:.4f} deg {row['errors'][1]:.3f} mm, max |err|/σ "
                f"{np.max(row['ratio']):.2f}, scale {row['scale']}",
                flush=True,
            )
    return out


def scale(seeds: int, workers: int, presets: Sequence[str] = SCALE_PRESETS) -> list[Goal]:
    jobs = [(preset, seed) for preset in presets for seed in range(seeds)]
    runs = [run for runs in parallel_map(_scale_run, jobs, workers) for run in runs]
    for failure in (r for r in runs if "failure" in r):
        print(f"FAIL scale {failure['preset']} seed {failure['seed']}: {failure['failure']}")
    rows: list[list[object]] = []
    summary: dict[tuple[str, str, str], tuple[float, float]] = {}
    for preset in presets:
        for radius in ("free", "given"):
            for variant in ("fixed", "free"):
                mine = [
                    r
                    for r in runs
                    if (r["preset"], r["radius"], r["variant"]) == (preset, radius, variant)
                    and "failure" not in r
                ]
                if not mine:
                    continue
                ratio = np.array([r["ratio"] for r in mine])
                rot, trans = rms(r["errors"][0] for r in mine), rms(r["errors"][1] for r in mine)
                summary[preset, radius, variant] = (rot, trans)
                scale_cell = ""
                if variant == "free":
                    s = np.array([r["scale"] for r in mine])
                    z = (s - mine[0]["truth_scale"]) / np.array([r["scale_sigma"] for r in mine])
                    scale_cell = (
                        f"{100 * np.median(s):+.3f} % [{100 * s.min():+.3f}, {100 * s.max():+.3f}]"
                        f" (truth {100 * mine[0]['truth_scale']:+.1f} %), |z| median "
                        f"{np.median(np.abs(z)):.1f} max {np.max(np.abs(z)):.1f}"
                    )
                rows.append(
                    [
                        preset,
                        radius,
                        variant,
                        len(mine),
                        rot,
                        trans,
                        f"{100 * np.mean(ratio <= 1.0):.0f} %",
                        " ".join(f"{v:.1f}" for v in ratio.max(axis=0)),
                        float(np.median(ratio)),
                        float(np.median([r["radius_mm"] for r in mine])),
                        scale_cell,
                    ]
                )
    print_table(
        "Along-line scale fixed vs estimated: simulate → run_pipeline (self-check included); "
        "|err|/σ per axis θx θy θz ρx ρy ρz",
        [
            "preset",
            "radius",
            "scale",
            "seeds",
            "RMS rot (deg)",
            "RMS trans (mm)",
            "axes within 1σ",
            "max |err|/σ per axis",
            "median |err|/σ",
            "median radius (mm)",
            "estimated scale: median [range], |(est − truth)/σ|",
        ],
        rows,
    )
    goals = []
    for preset in presets:
        for radius in ("free", "given"):
            fixed, free = (
                summary.get((preset, radius, "fixed")),
                summary.get((preset, radius, "free")),
            )
            if fixed is None or free is None:
                continue
            goals.append(
                Goal(
                    f"scale {preset}, radius {radius}: estimating the scale raises the RMS "
                    "trans error by ≤ 20 % or lowers it",
                    f"{fixed[1]:.4f} → {free[1]:.4f} mm",
                    free[1] <= 1.2 * fixed[1],
                )
            )
    return goals


SECTIONS = ("accuracy", "robustness", "honesty", "speed", "outliers", "cluttered", "scale")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--only", nargs="*", choices=SECTIONS, help="run only these sections")
    parser.add_argument("--quick", action="store_true", help="small counts for a quick look")
    parser.add_argument("--seeds", type=int, help="accuracy seeds per preset (default 20)")
    parser.add_argument("--random", type=int, help="random scenes, default method (200)")
    parser.add_argument("--random-paper", type=int, help="random scenes, paper method (50)")
    parser.add_argument("--honesty", type=int, help="honesty seeds (default 150)")
    parser.add_argument("--outlier-seeds", type=int, help="outlier seeds (default 20)")
    parser.add_argument("--cluttered-seeds", type=int, help="cluttered seeds (default 20)")
    parser.add_argument("--scale-seeds", type=int, help="scale seeds per preset (default 20)")
    parser.add_argument(
        "--scale-presets",
        nargs="*",
        choices=SCALE_PRESETS,
        default=SCALE_PRESETS,
        help="scale: presets to compare (default all)",
    )
    parser.add_argument("--profiles", type=int, nargs="*", help="speed: profile counts")
    parser.add_argument("--repeats", type=int, help="speed: repeats per count (default 5)")
    parser.add_argument(
        "--resolution",
        type=int,
        default=SPEED_RESOLUTION,
        help=f"speed: rays per profile (default {SPEED_RESOLUTION}: ~800 points on the cylinder)",
    )
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    args = parser.parse_args(argv)
    quick = args.quick

    def count(value: int | None, full: int, small: int) -> int:
        return value if value is not None else (small if quick else full)

    selected = args.only or SECTIONS
    goals: list[Goal] = []
    start = time.perf_counter()
    if "accuracy" in selected:
        goals += accuracy(count(args.seeds, 20, 4), args.workers)
    if "robustness" in selected:
        goals += robustness(
            count(args.random, 200, 12), count(args.random_paper, 50, 6), args.workers
        )
    if "honesty" in selected:
        goals += honesty(count(args.honesty, 150, 16), args.workers)
    if "speed" in selected:
        profiles = args.profiles or ([12, 50] if quick else [12, 25, 50, 100, 200, 500])
        goals += speed(profiles, count(args.repeats, 5, 2), args.resolution)
    if "outliers" in selected:
        goals += outliers(count(args.outlier_seeds, 20, 4), args.workers)
    if "cluttered" in selected:
        goals += cluttered(count(args.cluttered_seeds, 20, 4), args.workers)
    if "scale" in selected:
        goals += scale(count(args.scale_seeds, 20, 3), args.workers, args.scale_presets)
    if quick:
        print(
            "\n--quick: counts below the goals' (20 seeds, 200 and 50 scenes, 150 honesty "
            "seeds); the honesty shares in particular are too noisy to judge"
        )
    print_table(
        "Summary",
        ["goal", "measured", "result"],
        [[g.name, g.measured, "PASS" if g.passed else "FAIL"] for g in goals],
    )
    print(f"\nbench time {time.perf_counter() - start:.0f} s")
    return 0 if all(g.passed for g in goals) else 1


if __name__ == "__main__":
    sys.exit(main())
