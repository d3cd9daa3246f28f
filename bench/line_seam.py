"""The straight-line target (teach-free seam) against the weld-seam paper's correction.

For every seed a straight-seam S-sweep is simulated (:mod:`linelaser_calib.sim.line`, preset
``line``: a 90 deg fillet, 60 waypoints swept continuously at 0.1 m/s, profiles at 25 Hz
stamped 12 ms late, a 4 ms pose stream with 0.25 ms stamp jitter, robot error 0.02 mm and
0.002 deg per axis). Through the pipeline, as ``linelaser-calib calibrate --target line
--max-speed 0 --max-angular-speed 0 --clock-offset auto`` does:

- the clock offset is estimated (:func:`~linelaser_calib.core.offset_search.search_clock_offset`,
  the line target's maximum-likelihood cost);
- ``default``: closed form, then maximum likelihood with the robot's pose error;
- ``paper``: the weld-seam paper's grid correction with the line's closest point, from the
  true hand-eye bumped as by a re-assembled mount (1-2 deg, 1-3 mm), at the same offset;
- ``default, offset 0``: the default solve with the profiles paired at their stamps, the
  latency ignored (the pipeline refuses this result; the line target is called directly to
  show the error an S-sweep makes without the offset).

Metrics: hand-eye rotation (deg) and translation (mm) error, clock offset error (ms; the
truth is −12 ms), wall time (s). Refused runs are counted, not averaged.

Run: ``.venv/bin/python bench/line_seam.py [--seeds N] [--preset line|line_features|line_ridge]``
(defaults 10 seeds and ``line``; ~30 s per seed, most of it the paper's grid).
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import replace

import numpy as np

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.geometry import transform_error
from linelaser_calib.core.offset_search import search_clock_offset
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.pipeline import Method, PipelineConfig, run_pipeline
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import SolveContext, configure
from linelaser_calib.sim.line import LINE_PRESETS, line_scenario_from_preset, simulate_line
from linelaser_calib.sim.weld import bumped_hand_eye

ROWS = ("default", "paper", "default, offset 0")
MOVING = PairingConfig(max_linear_speed_m_s=0.0, max_angular_speed_rad_s=0.0)


def run(seeds: int, preset: str) -> dict[str, dict[str, list[float]]]:
    """Per row, lists of rotation (deg), translation (mm), offset error (ms), time (s)."""
    target = get_target("line")
    table: dict[str, dict[str, list[float]]] = {
        row: {"rotation": [], "translation": [], "offset": [], "time": [], "refused": []}
        for row in ROWS
    }
    for seed in range(seeds):
        data = simulate_line(line_scenario_from_preset(preset), seed)
        truth = data.truth
        latency = truth.scenario.rig.latency_s
        started = time.perf_counter()
        offset, _ = search_clock_offset(
            data.profiles, data.poses, PipelineConfig(target="line", pairing=MOVING)
        )
        offset_seconds = time.perf_counter() - started
        pairing = replace(MOVING, clock_offset_s=offset)
        initial = bumped_hand_eye(truth.T_flange_sensor, np.random.default_rng(seed))
        for row in ROWS:
            started = time.perf_counter()
            try:
                if row == "default, offset 0":
                    samples = pair_profiles(data.profiles, data.poses, MOVING).samples
                    config = target.config_type()
                    features, _ = target.extract(samples, config, seed, lambda *_: None)
                    T = target.solve_default(
                        features, config, SolveContext(n_samples=len(samples))
                    ).T_flange_sensor
                    offset_error = -latency
                else:
                    method = Method(row)
                    settings = {"initial": initial} if method is Method.PAPER else {}
                    config = PipelineConfig(
                        method=method,
                        target="line",
                        target_config=configure(target, method.value, settings, {}),
                        seed=seed,
                        pairing=pairing,
                        initial_T_flange_sensor=initial if method is Method.PAPER else None,
                    )
                    T = run_pipeline(data.profiles, data.poses, config).T_flange_sensor
                    offset_error = offset + latency
            except CalibrationError:
                table[row]["refused"].append(seed)
                continue
            seconds = time.perf_counter() - started + (0.0 if row.endswith("0") else offset_seconds)
            rotation, translation = transform_error(T, truth.T_flange_sensor)
            table[row]["rotation"].append(math.degrees(rotation))
            table[row]["translation"].append(translation * 1e3)
            table[row]["offset"].append(abs(offset_error) * 1e3)
            table[row]["time"].append(seconds)
    return table


def print_table(table: dict[str, dict[str, list[float]]], seeds: int, preset: str) -> None:
    print(
        f"Straight-seam S-sweep (preset {preset}), {seeds} seeds: mean / RMS / max; the offset "
        "error is |estimated - true| (true -12 ms)\n"
    )
    print("| method | rotation deg | translation mm | clock offset error ms | time s | refused |")
    print("|---|---|---|---|---|---|")
    for row, values in table.items():
        cells = []
        for key, digits in (("rotation", 4), ("translation", 4), ("offset", 3), ("time", 2)):
            v = np.array(values[key])
            if v.size == 0:
                cells.append("-")
                continue
            rms = float(np.sqrt(np.mean(v**2)))
            cells.append(f"{v.mean():.{digits}f} / {rms:.{digits}f} / {v.max():.{digits}f}")
        print(f"| {row} | " + " | ".join(cells) + f" | {len(values['refused'])} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--preset", default="line", choices=sorted(LINE_PRESETS))
    args = parser.parse_args()
    print_table(run(args.seeds, args.preset), args.seeds, args.preset)


if __name__ == "__main__":
    main()
