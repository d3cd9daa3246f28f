"""The near-duplicate rule (``--per-neighbourhood``) on long continuous recordings.

Simulates ``continuous`` recordings (the preset as it is, and a 100-200 Hz profiler on an arm
sweeping at 50 mm/s and 0.3 rad/s, as real cells record) and calibrates each in a fresh
process (``--max-speed 0 --max-angular-speed 0 --clock-offset auto``, docs/recording.md)
with every ``--per-neighbourhood`` asked for (0 keeps every profile), printing per run:

- ``kept``: the profiles kept of the paired ones (the result's ``quality.thinning``);
- ``wall s``, ``CPU s``, ``peak MB``: as in ``bench/scale.py``;
- ``rot deg``, ``trans mm``: the hand-eye's error against the simulator's truth;
- ``1σ deg``, ``1σ mm``: the reported 1σ, its largest axis;
- ``max e/σ``: the largest per-axis error over its 1σ (honest: mostly below 1, rarely 3);
- ``Δ/1σ``: the largest per-axis difference from the first run of the recording (the first
  ``--per-neighbourhood``, 0 by default: every profile) over that run's 1σ.

The machine's other load moves the times by tens of per cent: compare rows of one run.

Run from the repository root (not part of the test suite)::

    .venv/bin/python bench/thinning.py [--recordings DIR] [--caps 0,40,10]
        [--sizes continuous:1000,fast:100:6]

A size is ``continuous:POSES`` (the preset) or ``fast:RATE_HZ:POSES`` (the sweep above at
that profile rate through that many waypoints).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml
from scale import OPTIONS, errors, measured

from linelaser_calib.core.geometry import rotvec_from_matrix
from linelaser_calib.sim.bag_writer import simulate_to_bag

DEFAULT_SIZES = "continuous:1000,fast:100:6"
#: The sweep of a real cell: 50 mm/s and 0.3 rad/s (17 deg/s) on average.
FAST = {"move_speed_m_s": 0.05, "move_angular_speed_rad_s": 0.3}


def recording(root: Path, size: str, seed: int) -> Path:
    """The bag of ``size`` under ``root``, simulated when absent."""
    words = size.split(":")
    bag = root / f"{'_'.join(words)}_seed{seed}"
    if not bag.exists():
        if words[0] == "continuous":
            overrides: dict[str, object] = {"n_poses": int(words[1])}
        else:
            overrides = {**FAST, "profile_rate_hz": float(words[1]), "n_poses": int(words[2])}
        simulate_to_bag(bag, "continuous", seed, overrides)
    return bag


def read(result_path: Path) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """A result's hand-eye (4, 4), its 1σ per axis (rotation rad, translation m) and its
    ``quality.thinning`` (empty when off)."""
    result = yaml.safe_load(result_path.read_text())
    sigma = result["hand_eye"]["uncertainty"]
    return (
        np.array(result["hand_eye"]["matrix"]),
        np.concatenate([sigma["rotation_rad"], sigma["translation_m"]]),
        result["quality"].get("thinning") or {},
    )


def difference(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Per-axis difference of two hand-eyes: rotation vector (rad), translation (m)."""
    return np.concatenate([rotvec_from_matrix(Y[:3, :3].T @ X[:3, :3]), X[:3, 3] - Y[:3, 3]])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default=DEFAULT_SIZES, help="comma-separated, see above")
    parser.add_argument("--caps", default="0,40", help="--per-neighbourhood values")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--recordings", help="directory to simulate into and reuse from")
    args = parser.parse_args()
    cli = str(Path(sys.executable).parent / "linelaser-calib")
    print(
        f"{'recording':<20}{'cap':>5}{'kept':>13}{'wall s':>8}{'CPU s':>7}{'peak MB':>8}"
        f"{'rot deg':>9}{'trans mm':>9}{'1σ deg':>8}{'1σ mm':>8}{'max e/σ':>8}{'Δ/1σ':>6}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.recordings or tmp).resolve()
        root.mkdir(parents=True, exist_ok=True)
        out = Path(tmp) / "result.yaml"
        for size in args.sizes.split(","):
            bag = recording(root, size, args.seed)
            first = None
            for cap in args.caps.split(","):
                out.unlink(missing_ok=True)
                options = [*OPTIONS["continuous"], "--per-neighbourhood", cap]
                run = measured([cli, "calibrate", str(bag), "--output", str(out), *options])
                estimate, sigma, thin = read(out)
                rot, trans, ratio = errors(out, bag / "truth.yaml")
                first = first or (estimate, sigma)
                shift = np.max(np.abs(difference(estimate, first[0])) / first[1])
                kept = f"{thin['samples_kept']}/{thin['samples_given']}" if thin else "all"
                print(
                    f"{size:<20}{cap:>5}{kept:>13}{run.wall_s:>8.1f}{run.cpu_s:>7.1f}"
                    f"{run.peak_mb:>8.0f}{rot:>9.4f}{trans:>9.4f}"
                    f"{math.degrees(float(np.max(sigma[:3]))):>8.4f}"
                    f"{float(np.max(sigma[3:])) * 1e3:>8.4f}{ratio:>8.2f}{shift:>6.2f}",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
