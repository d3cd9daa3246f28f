"""Wall time and peak memory of ``linelaser-calib calibrate`` against the recording's length.

Simulates recordings of the stop-and-go ``ur_scancontrol`` preset and of the ``continuous``
preset (the same cell scanned while the arm moves without stopping) at several ``--poses``,
then calibrates each in a fresh process (default method, output to a temporary YAML) and
prints, per recording (the continuous preset with ``--max-speed 0 --max-angular-speed 0
--clock-offset auto``, as docs/recording.md says for a scan in motion):

- ``profiles``, ``poses``: profiles and flange poses in the recording;
- ``raw MB``: the raw data, counting each valid point as float32 x, y, z and each flange pose
  as 7 float64;
- ``wall s``, ``x paper``: the calibration's wall time and its ratio to ``calibrate
  bags/paper`` timed in the same run (the median of three; the yardstick of the goals);
- ``CPU s``, ``x paper``: the same for its CPU time (user + system, the forked child's
  included), which the machine's other load disturbs less;
- ``peak MB``: the process's peak resident memory (``ru_maxrss``);
- ``above MB``, ``x raw``: the peak above the start-up baseline (the peak of a process that
  imports what ``calibrate`` imports and stops) and its ratio to the raw data;
- ``rot deg``, ``trans mm``: the hand-eye's error against the simulator's truth;
- ``max e/σ``: the largest per-axis error over its reported 1σ.

The machine's other load moves the wall times by tens of per cent: compare rows of one run.
The goals (issue 32): ``continuous`` at 2,000 poses within 20x ``calibrate bags/paper`` and
500 MB peak; ``ur_scancontrol`` at 1,600 poses within 4x and 5x the raw data above the
baseline.

Run from the repository root (not part of the test suite)::

    .venv/bin/python bench/scale.py [--sizes ur_scancontrol:100,continuous:1000] [--large]
        [--recordings DIR] [--source DIR]

The default sizes take a few minutes; ``--large`` adds ``ur_scancontrol`` at 1,600 and
``continuous`` at 2,000 poses (the goals' sizes, several minutes more).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from linelaser_calib.core.geometry import rotvec_from_matrix
from linelaser_calib.io.bags import read_bag

DEFAULT_SIZES = "ur_scancontrol:100,ur_scancontrol:400,continuous:1000"
LARGE_SIZES = "ur_scancontrol:1600,continuous:2000"
#: The calibrate options of each preset: a scan in motion opens the speed gate and estimates
#: the clock offset (docs/recording.md).
OPTIONS = {
    "continuous": ["--max-speed", "0", "--max-angular-speed", "0", "--clock-offset", "auto"],
}
BASELINE_IMPORTS = (
    "import linelaser_calib.cli.parser, linelaser_calib.cli.calibrate, linelaser_calib.offline, "
    "linelaser_calib.core.targets.cylinder.target, linelaser_calib.io.results"
)


@dataclass(frozen=True)
class Run:
    """One child process: wall and CPU (user + system) time, s, and peak resident memory,
    MB."""

    wall_s: float
    cpu_s: float
    peak_mb: float


def measured(argv: list[str], env: dict[str, str] | None = None, cwd: str | None = None) -> Run:
    """Run ``argv`` to completion (it must succeed) and measure it alone (``wait4``)."""
    started = time.perf_counter()
    child = subprocess.Popen(
        argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=cwd
    )
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - started
    child.returncode = os.waitstatus_to_exitcode(status)
    stderr = child.stderr.read().decode() if child.stderr else ""
    if child.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed ({child.returncode}): {stderr}")
    cpu = usage.ru_utime + usage.ru_stime
    return Run(wall, cpu, usage.ru_maxrss / 1024.0)  # ru_maxrss is in KiB on Linux


def raw_mb(bag: Path) -> tuple[int, int, float]:
    """Profiles, flange poses and raw data (float32 xyz per valid point, 7 float64 per
    pose), MB."""
    contents = read_bag(bag)
    points = sum(int(np.isfinite(p.points).all(axis=1).sum()) for p in contents.profiles)
    poses = len(contents.poses)
    return len(contents.profiles), poses, (points * 3 * 4 + poses * 7 * 8) / 1e6


def errors(result_path: Path, truth_path: Path) -> tuple[float, float, float]:
    """Rotation error (deg), translation error (mm) and the largest per-axis |error|/1σ."""
    result = yaml.safe_load(result_path.read_text())["hand_eye"]
    truth = yaml.safe_load(truth_path.read_text())["hand_eye"]
    X, T = np.array(result["matrix"]), np.array(truth["matrix"])
    rotation = rotvec_from_matrix(T[:3, :3].T @ X[:3, :3])
    translation = X[:3, 3] - T[:3, 3]
    sigma = result.get("uncertainty") or {}
    ratio = math.nan
    if sigma:
        e = np.concatenate([np.abs(rotation), np.abs(translation)])
        s = np.concatenate([sigma["rotation_rad"], sigma["translation_m"]])
        ratio = float(np.max(e / s))
    return (
        math.degrees(float(np.linalg.norm(rotation))),
        float(np.linalg.norm(translation)) * 1e3,
        ratio,
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default=DEFAULT_SIZES, help="PRESET:POSES, comma-separated")
    parser.add_argument("--large", action="store_true", help="add " + LARGE_SIZES)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--source",
        help="calibrate with the package in this directory (e.g. an export of an earlier "
        "commit: git archive COMMIT | tar -x -C DIR) instead of the installed one",
    )
    parser.add_argument(
        "--recordings",
        help="directory to simulate the recordings into and reuse them from (default: a "
        "temporary one)",
    )
    args = parser.parse_args()
    cli = str(Path(sys.executable).parent / "linelaser-calib")
    calibrate, env, cwd = [cli, "calibrate"], None, None
    if args.source:  # run there: the current directory comes first on the module path
        cwd = str(Path(args.source).resolve())
        entry = "import sys; from linelaser_calib.entry import main; sys.exit(main())"
        calibrate = [sys.executable, "-c", entry, "calibrate"]
        env = {**os.environ, "PYTHONPATH": str(Path(args.source).resolve())}
    sizes = args.sizes + ("," + LARGE_SIZES if args.large else "")
    baseline = measured([sys.executable, "-c", BASELINE_IMPORTS], env, cwd).peak_mb
    paper_bag = str(Path("bags/paper").resolve())
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "result.yaml"
        paper = [measured([*calibrate, paper_bag, "--output", str(out)], env, cwd) for _ in "abc"]
        paper_wall = statistics.median(r.wall_s for r in paper)
        paper_cpu = statistics.median(r.cpu_s for r in paper)
        print(
            f"start-up baseline {baseline:.0f} MB; calibrate bags/paper {paper_wall:.2f} s wall, "
            f"{paper_cpu:.2f} s CPU"
        )
        print(
            f"{'preset':<16}{'--poses':>8}{'profiles':>9}{'poses':>8}{'raw MB':>8}{'wall s':>8}"
            f"{'x paper':>8}{'CPU s':>7}{'x paper':>8}{'peak MB':>8}{'above MB':>9}{'x raw':>7}"
            f"{'rot deg':>9}{'trans mm':>9}{'max e/σ':>8}"
        )
        for item in sizes.split(","):
            preset, n = item.split(":")
            bag = Path(args.recordings or tmp).resolve() / f"{preset}_{n}_seed{args.seed}"
            if not bag.exists():
                simulate = [cli, "simulate", str(bag), "--scenario", preset, "--poses", n]
                subprocess.run(
                    [*simulate, "--seed", str(args.seed)], check=True, capture_output=True
                )
            profiles, poses, raw = raw_mb(bag)
            out.unlink(missing_ok=True)
            try:
                options = OPTIONS.get(preset, [])
                run = measured([*calibrate, str(bag), "--output", str(out), *options], env, cwd)
            except RuntimeError as refused:
                print(f"{preset:<16}{n:>8}{profiles:>9}{poses:>8}{raw:>8.1f}  refused: {refused}")
                continue
            rot, trans, ratio = errors(out, bag / "truth.yaml")
            above = run.peak_mb - baseline
            print(
                f"{preset:<16}{n:>8}{profiles:>9}{poses:>8}{raw:>8.1f}{run.wall_s:>8.1f}"
                f"{run.wall_s / paper_wall:>8.1f}{run.cpu_s:>7.1f}{run.cpu_s / paper_cpu:>8.1f}"
                f"{run.peak_mb:>8.0f}{above:>9.0f}"
                f"{above / raw:>7.1f}{rot:>9.4f}{trans:>9.3f}{ratio:>8.2f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
