"""One realistic preset seed by seed: where :mod:`realism`'s ``presets`` table pools the seeds,
this prints each one's row, to find the seeds whose error leaves its 1σ and on which axis.

Per seed: profiles used of those recorded (or the refusal), the hand-eye error (mm, deg), its
reported 1σ (the length over the axes, mm and deg), error / 1σ per axis (rotation about the
sensor x, y, z; translation along flange x, y, z) and the largest |error| / 1σ.

Run: ``.venv/bin/python bench/preset_seeds.py [--preset line_ridge] [--seeds 0-9]`` (a few
seconds a seed).
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from realism import PRESETS, _preset_data, calibrate
from realistic_sensors import Tally

AXES = ("rx", "ry", "rz", "tx", "ty", "tz")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="line_ridge", choices=sorted(PRESETS))
    parser.add_argument("--seeds", default="0-9", help="first-last, inclusive")
    args = parser.parse_args()
    first, _, last = args.seeds.partition("-")
    print(
        f"{'seed':>4}{'used':>8}{'err mm':>9}{'err deg':>9}{'1σ mm':>9}{'1σ deg':>9}"
        + "".join(f"{axis + ' e/σ':>9}" for axis in AXES)
        + f"{'max':>7}"
    )
    worst = 0.0
    for seed in range(int(first), int(last or first) + 1):
        tally = Tally()
        calibrate(_preset_data(args.preset, False, seed), PRESETS[args.preset], tally, seed)
        if not tally.errors:
            print(f"{seed:>4}  refused: {tally.refused[0]}")
            continue
        e, s = tally.errors[0], tally.sigmas[0]
        z = e / s
        worst = max(worst, float(np.max(np.abs(z))))
        print(
            f"{seed:>4}{f'{tally.used}/{tally.recorded}':>8}"
            f"{np.linalg.norm(e[3:]) * 1e3:>9.4f}{math.degrees(np.linalg.norm(e[:3])):>9.4f}"
            f"{np.linalg.norm(s[3:]) * 1e3:>9.4f}{math.degrees(np.linalg.norm(s[:3])):>9.4f}"
            + "".join(f"{v:>9.2f}" for v in z)
            + f"{np.max(np.abs(z)):>7.2f}",
            flush=True,
        )
    print(f"largest |error| / 1σ: {worst:.2f}")


if __name__ == "__main__":
    main()
