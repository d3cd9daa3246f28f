"""Calibration on the simulator's real-profiler presets, beside their white-noise twins.

Each preset (``cylinder_keyence``, ``cylinder_scancontrol``, ``cylinder_gocator``,
``sphere_sszn``) scans its target with a profiler's smooth shape errors (linearity bow, smooth
depth error, correlated speckle, output steps, weak returns:
:mod:`linelaser_calib.sim.sensor_models`); its twin is the same scene with the sensor model
zeroed (white point noise only). Per preset and method, over seeds:

- ``used %``: profiles used of those recorded (all seeds pooled);
- ``refused``: runs that gave no result;
- ``rot/trans RMS``: hand-eye error against truth, RMS over seeds (deg, mm);
- ``x twin``: that translation RMS over the twin's (same method);
- ``max |e|/σ``: the largest per-axis error over its predicted 1σ (default method only);
- ``RMS e/σ``, ``in 1σ %``: the RMS of the per-axis error over its 1σ (1 when the 1σ is
  honest) and the share of per-axis errors within it (68 % for a Gaussian error);
- ``x paper``: the default method's translation RMS over the paper method's;
- ``CRB mm``: the Cramér–Rao bound of the translation (RMS over seeds of √trace) for the
  points and poses the default method used, under the sensor model's random terms (white,
  smooth shape error, speckle, quantisation; the fixed linearity bow is a systematic and
  left out): what the best unbiased estimator of these data could reach
  (:mod:`_bound`; cylinder presets only);
- ``x CRB``: the default method's translation RMS over that bound;
- ``twin CRB``: the same bound for the white-noise twin.

Run: ``.venv/bin/python bench/realistic_sensors.py [--seeds N] [--presets A,B]
[--independent-points] [--no-bound] [--faces F,G]`` (default 20 seeds, all four presets; a
few seconds per calibration). ``--faces`` adds faces of a real profiler that the field showed
(:data:`~linelaser_calib.sim.sensor_models.REAL_FACES`: grazing, gaps, scales, shape) to
each preset's sensor; the twin stays white. ``--independent-points`` runs the cylinder's
default method without the learned line noise (``RefineConfig.learn_line_noise`` off), as it
was before.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from _bound import hand_eye_bound, rms_of

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import FloatArray, rotvec_from_matrix
from linelaser_calib.core.pipeline import Method, PipelineConfig, run_pipeline
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.targets.cylinder.config import CylinderConfig, RefineConfig
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.sensor_models import SensorModel, with_faces
from linelaser_calib.sim.simulate import simulate
from linelaser_calib.sim.sphere import simulate_sphere, sphere_scenario_from_preset

PRESETS = ("cylinder_keyence", "cylinder_scancontrol", "cylinder_gocator", "sphere_sszn")


@dataclass
class Tally:
    """Outcomes of one preset and method over seeds."""

    used: int = 0
    recorded: int = 0
    refused: list[str] = field(default_factory=list)
    errors: list[FloatArray] = field(default_factory=list)  # (6,) rotvec rad, translation m
    sigmas: list[FloatArray] = field(default_factory=list)  # (6,) 1σ, or empty
    bounds: list[FloatArray] = field(default_factory=list)  # (6, 6) Cramér–Rao, or empty

    def rms(self) -> tuple[float, float]:
        """Rotation (deg) and translation (mm) RMS over the seeds."""
        if not self.errors:
            return math.nan, math.nan
        e = np.array(self.errors)
        rot = np.linalg.norm(e[:, :3], axis=1)
        trans = np.linalg.norm(e[:, 3:], axis=1)
        return math.degrees(float(np.sqrt(np.mean(rot**2)))), float(
            np.sqrt(np.mean(trans**2)) * 1e3
        )

    def bound_mm(self) -> float:
        """Translation RMS (mm) the Cramér–Rao bounds allow, over the seeds."""
        if not self.bounds:
            return math.nan
        return float(np.sqrt(np.mean([rms_of(b)[1] ** 2 for b in self.bounds])))

    def worst_ratio(self) -> float:
        """Largest |error| / 1σ over axes and seeds."""
        ratios = [np.max(np.abs(e) / s) for e, s in zip(self.errors, self.sigmas, strict=True)]
        return float(np.max(ratios)) if ratios else math.nan

    def z(self) -> FloatArray:
        """error / 1σ per seed and axis (seeds with a 1σ), shape (S, 6)."""
        return np.array([e / s for e, s in zip(self.errors, self.sigmas, strict=True)])

    def rms_ratio(self) -> float:
        """RMS of error / 1σ over axes and seeds: 1 for an honest 1σ."""
        return float(np.sqrt(np.mean(self.z() ** 2))) if self.sigmas else math.nan

    def within_sigma(self) -> float:
        """Share of per-axis errors within their 1σ, %: 68 for an honest Gaussian 1σ."""
        return float(100.0 * np.mean(np.abs(self.z()) < 1.0)) if self.sigmas else math.nan


def _data(
    preset: str, seed: int, white: bool, faces: tuple[str, ...] = ()
) -> tuple[Any, FloatArray, str]:
    """Profiles, poses, true hand-eye (4, 4) and target of one simulated run (with
    ``faces`` added to the sensor unless ``white``)."""
    if preset.startswith("sphere"):
        sphere = sphere_scenario_from_preset(preset)
        sensor = SensorModel() if white else with_faces(sphere.rig.sensor, *faces)
        data = simulate_sphere(replace(sphere, rig=replace(sphere.rig, sensor=sensor)), seed)
        return data, data.truth.T_flange_sensor, "sphere"
    scenario = scenario_from_preset(preset)
    scenario = replace(
        scenario, sensor=SensorModel() if white else with_faces(scenario.sensor, *faces)
    )
    cylinder = simulate(scenario, seed)
    return cylinder, cylinder.truth.T_flange_sensor, "cylinder"


def _error(result: CalibrationResult, truth: FloatArray) -> FloatArray:
    X = result.T_flange_sensor
    rotation = rotvec_from_matrix(truth[:3, :3].T @ X[:3, :3])
    return np.concatenate([rotation, X[:3, 3] - truth[:3, 3]])


def run(
    preset: str,
    seeds: int,
    white: bool,
    independent: bool = False,
    bound: bool = True,
    faces: tuple[str, ...] = (),
) -> dict[str, Tally]:
    """Both methods on ``seeds`` simulated runs of a preset (or its white-noise twin);
    ``independent`` weighs a cylinder's points as independent (no learned line noise);
    ``bound`` computes the Cramér–Rao bound of each (minutes per recording)."""
    tallies = {"paper": Tally(), "default": Tally()}
    for seed in range(seeds):
        data, truth, target = _data(preset, seed, white, faces)
        for method in (Method.PAPER, Method.DEFAULT):
            tally = tallies[method.value]
            tally.recorded += len(data.profiles)
            config = PipelineConfig(method=method, target=target)
            if independent and target == "cylinder":
                refine = RefineConfig(learn_line_noise=False)
                config = replace(config, target_config=CylinderConfig(refine=refine))
            try:
                result = run_pipeline(data.profiles, data.poses, config)
            except CalibrationError as exc:
                tally.refused.append(f"seed {seed}: {str(exc)[:160]}")
                continue
            tally.used += len(result.samples_used)
            tally.errors.append(_error(result, truth))
            if bound and method is Method.DEFAULT and target == "cylinder":
                scenario = data.truth.scenario
                tally.bounds.append(
                    hand_eye_bound(
                        scenario, scenario.sensor, result.sample_fits, truth, data.truth.cylinder
                    )
                )
            if result.uncertainty_rotation_rad is not None:
                tally.sigmas.append(
                    np.concatenate(
                        [
                            np.asarray(result.uncertainty_rotation_rad),
                            np.asarray(result.uncertainty_translation_m),
                        ]
                    )
                )
    return tallies


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--presets", default=",".join(PRESETS))
    parser.add_argument(
        "--independent-points",
        action="store_true",
        help="weigh a cylinder's points as independent (the method before the learned line "
        "noise), for comparison",
    )
    parser.add_argument(
        "--no-bound",
        action="store_true",
        help="skip the Cramér–Rao bound (its dense covariances take most of the run)",
    )
    parser.add_argument("--faces", default="", help="faces of a real profiler to add, F,G")
    args = parser.parse_args()
    faces = tuple(f for f in args.faces.split(",") if f)
    print(
        f"{'preset':<22}{'method':<9}{'used %':>8}{'refused':>8}{'rot RMS deg':>12}"
        f"{'trans RMS mm':>13}{'x twin':>8}{'max |e|/σ':>10}{'RMS e/σ':>8}{'in 1σ %':>8}"
        f"{'x paper':>8}"
        f"{'CRB mm':>8}{'x CRB':>7}{'twin CRB':>9}"
    )
    notes, twin_notes = [], []
    for preset in args.presets.split(","):
        bound = not args.no_bound
        real = run(preset, args.seeds, False, args.independent_points, bound, faces)
        twin = run(preset, args.seeds, True, args.independent_points, bound)
        for name, tally in real.items():
            rot, trans = tally.rms()
            ratio_twin = trans / twin[name].rms()[1]
            vs_paper = f"{trans / real['paper'].rms()[1]:.2f}" if name == "default" else "-"
            worst = f"{tally.worst_ratio():.2f}" if tally.sigmas else "-"
            honesty = (
                f"{tally.rms_ratio():>8.2f}{tally.within_sigma():>8.0f}"
                if tally.sigmas
                else f"{'-':>8}{'-':>8}"
            )
            bound, twin_bound = tally.bound_mm(), twin[name].bound_mm()
            bounds = (
                f"{bound:>8.4f}{trans / bound:>7.2f}{twin_bound:>9.4f}"
                if tally.bounds
                else f"{'-':>8}{'-':>7}{'-':>9}"
            )
            print(
                f"{preset:<22}{name:<9}{100.0 * tally.used / tally.recorded:>8.1f}"
                f"{len(tally.refused):>8}{rot:>12.4f}{trans:>13.4f}{ratio_twin:>8.2f}"
                f"{worst:>10}{honesty}{vs_paper:>8}{bounds}"
            )
            if name == "default" and twin[name].sigmas:
                twin_notes.append(
                    f"{preset} twin, default: RMS e/σ {twin[name].rms_ratio():.2f}, "
                    f"in 1σ {twin[name].within_sigma():.0f} %, max |e|/σ "
                    f"{twin[name].worst_ratio():.2f}"
                )
            notes.extend(f"{preset} {name}: {text}" for text in tally.refused)
            notes.extend(f"{preset} {name} twin: {text}" for text in twin[name].refused)
    print(f"{args.seeds} seeds per preset; twin: the same scenes with white point noise only")
    for line in twin_notes:
        print(line)
    for note in notes:
        print("refused:", note)


if __name__ == "__main__":
    main()
