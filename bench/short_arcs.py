"""Short arcs on the cylinder: profiles used and hand-eye error, radius free and given.

Cases (each a simulator preset with overrides, several seeds):

- ``cluttered_camera``: a coarse camera-based profiler about 1 m from a Ø25 mm bar (arcs of
  about 120° of the circle, 5-10 % of each profile);
- ``camera_inc20``: the same with returns lost beyond 20° of incidence: arcs of about 40° of
  the circle (35-45 points), as short as a real recording of such a profiler showed (at 12°,
  25° arcs of 25 points, the profiles hold fewer points than cleaning asks for);
- ``gocator_inc25`` / ``gocator_inc12``: ``cylinder_gocator`` whose returns are lost beyond
  25° / 12° of incidence (arcs of about 50° / 25°), ``min_arc_fraction`` lowered so that
  such poses are kept.

Per case and radius setting (``free``, ``given``), both methods: profiles used of those
recorded (all seeds pooled), runs refused, hand-eye error RMS over seeds (deg, mm) and, with
the radius free, the RMS radius error (mm).

Run: ``.venv/bin/python bench/short_arcs.py [--seeds N] [--cases A,B]`` (default 2 seeds).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.pipeline import Method, PipelineConfig, run_pipeline
from linelaser_calib.core.targets.cylinder import CylinderConfig, CylinderSection
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.simulate import simulate

CASES: dict[str, tuple[str, dict[str, Any]]] = {
    "cluttered_camera": ("cluttered_camera", {}),
    "camera_inc20": (
        "cluttered_camera",
        {"max_incidence_rad": math.radians(20.0), "min_arc_fraction": 0.005},
    ),
    "gocator_inc25": (
        "cylinder_gocator",
        {"max_incidence_rad": math.radians(25.0), "min_arc_fraction": 0.02},
    ),
    "gocator_inc12": (
        "cylinder_gocator",
        {"max_incidence_rad": math.radians(12.0), "min_arc_fraction": 0.02},
    ),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--cases", default=",".join(CASES))
    args = parser.parse_args()
    print(
        f"{'case':<18}{'radius':<7}{'method':<9}{'used':>10}{'refused':>8}"
        f"{'rot RMS deg':>12}{'trans RMS mm':>13}{'radius RMS mm':>14}"
    )
    for case in args.cases.split(","):
        preset, overrides = CASES[case]
        runs = [
            simulate(scenario_from_preset(preset, **overrides), seed) for seed in range(args.seeds)
        ]
        for given in (False, True):
            for method in (Method.PAPER, Method.DEFAULT):
                used = recorded = refused = 0
                rot: list[float] = []
                trans: list[float] = []
                radius: list[float] = []
                for data in runs:
                    truth_radius = data.truth.cylinder.radius
                    target_config = CylinderConfig(radius_m=truth_radius if given else None)
                    config = PipelineConfig(
                        method=method, target_config=target_config, self_check_folds=0
                    )
                    recorded += len(data.profiles)
                    try:
                        result = run_pipeline(data.profiles, data.poses, config)
                    except CalibrationError:
                        refused += 1
                        continue
                    used += len(result.samples_used)
                    r, t = transform_error(result.T_flange_sensor, data.truth.T_flange_sensor)
                    rot.append(math.degrees(r))
                    trans.append(t * 1e3)
                    section = result.target
                    if not given and isinstance(section, CylinderSection):
                        radius.append((section.cylinder.radius - truth_radius) * 1e3)

                def rms(values: list[float]) -> float:
                    return float(np.sqrt(np.mean(np.square(values)))) if values else math.nan

                print(
                    f"{case:<18}{'given' if given else 'free':<7}{method.value:<9}"
                    f"{f'{used}/{recorded}':>10}{refused:>8}{rms(rot):>12.4f}"
                    f"{rms(trans):>13.4f}{rms(radius):>14.4f}"
                )


if __name__ == "__main__":
    main()
