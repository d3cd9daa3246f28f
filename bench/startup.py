"""Start-up time of ``linelaser-calib calibrate``, as a ratio to a bare import of its libraries.

Runs, as fresh processes, each of:

- ``bare``: ``python -c "import numpy, scipy.optimize, scipy.spatial.transform,
  rosbags.rosbag2"``, the least any calibration must load;
- ``import cli``: ``python -c "import linelaser_calib.cli"``;
- ``calibrate``: ``linelaser-calib calibrate bags/paper`` end to end (50 profiles, default
  method), output discarded;

interleaved (one of each per round, so that a change of machine load hits all alike), with
Python's bytecode cache on as a user has it (``PYTHONDONTWRITEBYTECODE`` is dropped for the
runs; a warm-up run of each writes the cache), and prints the wall time of each (median,
min, max over the rounds) and the ratio of the medians of ``calibrate`` to ``bare``. The goal
is a ratio of at most 1.5.

Run from the repository root (not part of the test suite)::

    .venv/bin/python bench/startup.py [--rounds 10] [--bag bags/paper]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

GOAL = 1.5


def wall_time(argv: list[str]) -> float:
    """Wall time of one run of ``argv``, s; the run must succeed."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    started = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, env=env)
    return time.perf_counter() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--bag", default="bags/paper")
    args = parser.parse_args()
    python = sys.executable
    commands = {
        "bare": [
            python,
            "-c",
            "import numpy, scipy.optimize, scipy.spatial.transform, rosbags.rosbag2",
        ],
        "import cli": [python, "-c", "import linelaser_calib.cli"],
        "calibrate": [str(Path(python).parent / "linelaser-calib"), "calibrate", args.bag],
    }
    for argv in commands.values():  # warm the file cache and the bytecode
        wall_time(argv)
    times: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(args.rounds):
        for name, argv in commands.items():
            times[name].append(wall_time(argv))
    print(f"Wall time over {args.rounds} interleaved rounds, s")
    print(f"  {'run':<12}{'median':>8}{'min':>8}{'max':>8}")
    for name, values in times.items():
        median = statistics.median(values)
        print(f"  {name:<12}{median:>8.3f}{min(values):>8.3f}{max(values):>8.3f}")
    ratio = statistics.median(times["calibrate"]) / statistics.median(times["bare"])
    verdict = "within" if ratio <= GOAL else "above"
    print(f"calibrate / bare (medians): {ratio:.2f} ({verdict} the goal of {GOAL})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
