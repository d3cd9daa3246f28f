"""The line's and the known point's self-check, and where every target's 1σ comes from.

Each row calibrates one simulated recording as the command line does (the default method,
self-check on; a swept seam's latency given): ``line_ridge`` (the line preset with every
face of a real profiler), ``line`` (the stress matrix's 24-waypoint scene), the known
point's ``weld_seam_general`` preset (20 poses, the stress matrix's scene) and, for
comparison, the sphere's stress-matrix scene. Per row and seed:
profiles used of those recorded, the largest per-axis |error| / 1σ, the verdict's level,
whether the self-check called the robot's error systematic, its region dispersion ratio,
the halves' disagreement in combined sigma of the noise model, and the 1σ's budget
(``quality.sigma_budget``: each widening's largest factor over the axes).

Run: ``.venv/bin/python bench/sigma_sources.py [--seeds 3] [--rows line_ridge,weld_seam_general]``
(a calibration takes 10-60 s on a loaded 2-core machine).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from realism import _error, _face_data, command_line_result

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.verdict import verdict_of
from linelaser_calib.settings import Front, render
from linelaser_calib.sim.line import line_scenario_from_preset, simulate_line
from linelaser_calib.sim.weld import simulate_weld, weld_scenario_from_preset

#: Row -> (target, the recording of a seed).
ROWS: dict[str, tuple[str, Any]] = {
    "line_ridge": (
        "line",
        lambda seed: simulate_line(line_scenario_from_preset("line_ridge"), seed),
    ),
    "line (stress scene)": ("line", lambda seed: _face_data("line", (), seed)),
    "weld_seam_general": (
        "known_point",
        lambda seed: simulate_weld(weld_scenario_from_preset("weld_seam_general"), seed),
    ),
    "sphere (stress scene)": ("sphere", lambda seed: _face_data("sphere", (), seed)),
}


def _budget_text(result: CalibrationResult) -> str:
    """Each widening of the result's 1σ above 1.005: its name and largest factor."""
    budget = result.sigma_budget
    if budget is None:
        return "-"
    return " ".join(
        f"{name}x{float(np.max(factors)):.2f}"
        for name, factors in budget.factors
        if float(np.max(factors)) > 1.005
    )


def run_row(name: str, seeds: int) -> None:
    """One line per seed of the row ``name`` (see the module docstring)."""
    target, recording = ROWS[name]
    for seed in range(seeds):
        data = recording(seed)
        label = f"{name} {seed}"
        try:
            result = command_line_result(data, target)
        except CalibrationError as exc:
            print(f"{label:<32} refused: {render(str(exc), Front.CLI)[:120]}", flush=True)
            continue
        assert result.uncertainty_rotation_rad is not None
        assert result.uncertainty_translation_m is not None
        sigma = np.r_[result.uncertainty_rotation_rad, result.uncertainty_translation_m]
        ratio = float(
            np.max(np.abs(_error(result.T_flange_sensor, data.truth.T_flange_sensor)) / sigma)
        )
        check = result.self_check
        used = f"{len(result.samples_used)}/{len(data.profiles)}"
        if check is None:
            stats = "no self-check"
        else:
            region = "-" if check.region_ratio is None else f"{check.region_ratio:.2f}"
            halves = (
                "-"
                if check.halves_model_sigmas is None
                else f"{float(np.max(check.halves_model_sigmas)):.2f}"
            )
            stats = f"{'syst' if check.systematic else 'indep':<6}{region:>7}{halves:>7}"
        print(
            f"{label:<32}{used:>8}{ratio:>7.2f}  {verdict_of(result).level.value:<14}{stats}  "
            f"{_budget_text(result)}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--rows", default=",".join(ROWS))
    args = parser.parse_args()
    print(
        f"{'row seed':<32}{'used':>8}{'|e|/σ':>7}  {'verdict':<14}{'robot':<6}{'region':>7}"
        f"{'halves':>7}  1σ budget (largest factor)"
    )
    for name in args.rows.split(","):
        run_row(name, args.seeds)


if __name__ == "__main__":
    main()
