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
min, max over the rounds) and its CPU time (user + system; less disturbed by other load on
the machine), and the ratios of the medians of ``calibrate`` to ``bare``. The goal is a wall
ratio of at most 1.5.

Run from the repository root (not part of the test suite)::

    .venv/bin/python bench/startup.py [--rounds 10] [--bag bags/paper]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

GOAL = 1.5


def timed(argv: list[str]) -> tuple[float, float]:
    """Wall and CPU (user + system) time of one run of ``argv``, s; the run must succeed."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, env=env)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


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
        timed(argv)
    wall: dict[str, list[float]] = {name: [] for name in commands}
    cpu: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(args.rounds):
        for name, argv in commands.items():
            w, c = timed(argv)
            wall[name].append(w)
            cpu[name].append(c)
    print(f"Time over {args.rounds} interleaved rounds, s")
    print(f"  {'run':<12}{'wall median':>12}{'min':>8}{'max':>8}{'CPU median':>12}")
    for name in commands:
        w = wall[name]
        print(
            f"  {name:<12}{statistics.median(w):>12.3f}{min(w):>8.3f}{max(w):>8.3f}"
            f"{statistics.median(cpu[name]):>12.3f}"
        )
    for label, table in (("wall", wall), ("CPU", cpu)):
        ratio = statistics.median(table["calibrate"]) / statistics.median(table["bare"])
        verdict = "within" if ratio <= GOAL else "above"
        print(f"calibrate / bare, {label} medians: {ratio:.2f} ({verdict} the goal of {GOAL})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
