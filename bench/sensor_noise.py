"""Local noise and circle residual of sphere profiles: the real SR7140 scans beside the
simulator's SSZN-class presets.

For each profile: ``local``, the RMS of the depth's second differences / √6 (the white
point noise, nearly blind to smooth shape error), um; ``circle``, the RMS distance of the
points from their best circle in the laser plane (centre and radius free), um; ``pitch``,
the median point spacing along the line, mm.

- ``real``: the 15 RobCalibrator profiles (``../shared/external/robcalibrator``, an SSZN
  SR7140 on a FANUC arm, 40 mm-radius ball; MIT licence, see the folder's LICENSE), all
  points of each profile.
- ``sphere_sszn``: the simulator's FANUC-cell preset (facts it reproduces: 3.5-4.5 um local
  noise, 20-40 um circle residual at 0.05 mm pitch), the ball's points of each profile.
- ``sszn_sr7140``: the same scene with the ``sszn_sr7140`` profiler (3200 points).

Run: ``.venv/bin/python bench/sensor_noise.py [--seeds N] [--real DIR]`` (default 2 seeds).
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from linelaser_calib.core.types import FloatArray
from linelaser_calib.io.robcalibrator import read_robcalibrator
from linelaser_calib.sim.scene import Surface
from linelaser_calib.sim.sensor_models import (
    PROFILERS,
    circle_rms_m,
    profiler_fields,
    second_difference_noise_m,
)
from linelaser_calib.sim.sphere import SPHERE_PRESETS, SphereScenario, simulate_sphere

REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "external" / "robcalibrator"


def _row(label: str, profiles: list[FloatArray]) -> None:
    local = np.array([second_difference_noise_m(p) for p in profiles]) * 1e6
    circle = np.array([circle_rms_m(p) for p in profiles]) * 1e6
    pitch = np.median([np.nanmedian(np.abs(np.diff(p[:, 0]))) for p in profiles]) * 1e3
    print(
        f"{label:<22} {len(profiles):>3} {pitch:>6.3f} "
        f"{np.median(local):>6.2f} {local.min():>6.2f}-{local.max():<6.2f} "
        f"{np.median(circle):>7.1f} {circle.min():>6.1f}-{circle.max():<6.1f}"
    )


def _ball_profiles(scenario: SphereScenario, seed: int) -> list[FloatArray]:
    """The ball's points of each (dense) profile of a simulated sphere run."""
    data = simulate_sphere(scenario, seed)
    return [
        profile.points[data.truth.surface[k][data.truth.valid[k]] == Surface.SIDE]
        for k, profile in enumerate(data.profiles)
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--real", type=Path, default=REAL)
    args = parser.parse_args()
    print(
        f"{'profiles':<22} {'n':>3} {'pitch':>6} {'local (um) median, range':>26} "
        f"{'circle (um) median, range':>26}"
    )
    if args.real.is_dir():
        scans = read_robcalibrator(args.real)
        _row("real SR7140 (FANUC)", [p.points for p in scans.profiles])
    fanuc = SPHERE_PRESETS["sphere_sszn"]
    sr7140 = replace(fanuc, rig=replace(fanuc.rig, **profiler_fields(PROFILERS["sszn_sr7140"])))
    for seed in range(args.seeds):
        _row(f"sphere_sszn seed {seed}", _ball_profiles(fanuc, seed))
        _row(f"sszn_sr7140 seed {seed}", _ball_profiles(sr7140, seed))


if __name__ == "__main__":
    main()
