"""Live replay over DDS, repeated: does every profile end used, rejected or counted as skipped?

Each run starts a fresh collector and calibration_service on a private ROS domain, replays a
recording (by default ``bags/paper``: 50 profiles, a 125 Hz pose stream) from this process on
non-default topic names that the collector remaps, as organised clouds padded with NaN
returns and carrying an intensity field, starting as soon as the player's publishers see the
collector's subscriptions (no settling time), then calls ``/calibrate``. A profile is
accounted for when the collector counts it as accepted, rejected or skipped, or counts it as
lost in transport (publisher sequence gaps, and profiles published before the first one
received); the calibration must then use or reject every accepted sample. Prints one row
per run (with the poses lost in transport, which explain rejections for want of a pose) and
the total of unaccounted profiles (which must be 0).

Run from the repository root (not part of the test suite; ~15 s per run)::

    .venv/bin/python bench/live_replay.py [--runs 10] [--rate 10] [--bag bags/paper]
        [--mode continuous] [--reliable]
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))

from ros_helpers import (
    Recording,
    RosProbe,
    module_command,
    new_domain_id,
    params,
    processes,
    wait_for,
)

from linelaser_calib.io import read_bag
from linelaser_calib.nodes.collection import (
    KEY_ACCEPTED,
    KEY_PENDING,
    KEY_POSES_LOST,
    KEY_PROFILES_BEFORE,
    KEY_PROFILES_LOST,
    KEY_RECEIVED,
    KEY_REJECTED,
    KEY_SKIPPED,
)
from msg_adapters import pointcloud2_from_points, rclpy_types

PROFILE_TOPIC = "/bench/scanner/points"
POSE_TOPIC = "/bench/robot/tcp_pose"
#: Points per organised cloud (valid returns first, NaN rows after).
WIDTH = 1024


def organised_recording(bag: Path) -> Recording:
    """The bag's profiles as organised clouds with NaN padding and intensity, and its poses."""
    contents = read_bag(bag)
    recording = Recording.from_data(
        contents.profiles, contents.poses, contents.sensor_frame, contents.base_frame
    )
    types = rclpy_types()
    by_stamp = {p.stamp_ns: p for p in contents.profiles}
    messages = []
    for stamp, is_profile, msg in recording.messages:
        if is_profile:
            points = by_stamp[stamp].points
            padded = np.full((max(WIDTH, len(points)), 3), np.nan)
            padded[: len(points)] = points
            msg = pointcloud2_from_points(
                padded,
                stamp,
                contents.sensor_frame,
                types=types,
                intensity=np.linspace(0.0, 1.0, len(padded)),
                organised=True,
            )
        messages.append((stamp, is_profile, msg))
    return Recording(messages)


def counted(values: dict[str, str], key: str) -> int:
    return int(values.get(key, 0))


def one_run(recording: Recording, args: argparse.Namespace, workdir: Path) -> dict[str, int]:
    """Replay once through fresh nodes; the counts of the run."""
    workdir.mkdir(parents=True)
    domain = new_domain_id()
    probe = RosProbe(domain)
    try:
        with processes(workdir, domain) as procs:
            procs.start(
                "collector",
                module_command(
                    "linelaser_calib.nodes.collector",
                    "-r",
                    f"profile:={PROFILE_TOPIC}",
                    "-r",
                    f"flange_pose:={POSE_TOPIC}",
                    *params(
                        session_dir=str(workdir / "sessions"),
                        diagnostics_period_s=0.2,
                        mode=args.mode,
                        reliable_inputs=args.reliable,
                    ),
                ),
            )
            procs.start(
                "calibration_service",
                module_command(
                    "linelaser_calib.nodes.calibration_service",
                    *params(output_path=str(workdir / "hand_eye.yaml"), diagnostics_period_s=0.2),
                ),
            )
            player = probe.player(PROFILE_TOPIC, POSE_TOPIC)
            player.wait_matched(settle_s=0.0)
            sent = player.play(recording, rate=args.rate)

            def settled() -> dict[str, str] | None:
                values = probe.diagnostics()
                if values is None or values.get(KEY_PENDING) != "0":
                    return None
                seen = counted(values, KEY_RECEIVED) + counted(values, KEY_PROFILES_LOST)
                return values if seen + counted(values, KEY_PROFILES_BEFORE) >= sent else None

            try:
                values = wait_for(settled, 20.0, "the collector's counts")
            except AssertionError:
                values = probe.diagnostics() or {}
            accepted = counted(values, KEY_ACCEPTED)
            wait_for(
                lambda: (
                    (probe.diagnostics("calibration_service") or {}).get("samples") == str(accepted)
                ),
                20.0,
                "the service's samples",
            )
            answer = probe.call("/calibrate")
            found = re.search(r"(\d+) of (\d+) samples used", answer.message)
            used, total = (int(found[1]), int(found[2])) if found else (0, 0)
            session = sorted((workdir / "sessions").glob("session_*"))[-1]
            stored = len(read_bag(session).profiles) if accepted else 0
    finally:
        probe.close()
    lost = counted(values, KEY_PROFILES_LOST) + counted(values, KEY_PROFILES_BEFORE)
    return {
        "sent": sent,
        "received": counted(values, KEY_RECEIVED),
        "lost (counted)": lost,
        "accepted": accepted,
        "rejected": counted(values, KEY_REJECTED),
        "poses lost": counted(values, KEY_POSES_LOST),
        "skipped": counted(values, KEY_SKIPPED),
        "stored": stored,
        "used": used,
        "rejected in result": total - used,
        "unaccounted": sent
        - lost
        - counted(values, KEY_REJECTED)
        - counted(values, KEY_SKIPPED)
        - total,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--rate", type=float, default=10.0, help="replay speed factor")
    parser.add_argument("--bag", type=Path, default=Path("bags/paper"))
    parser.add_argument(
        "--mode", default="continuous", choices=("continuous", "stop_and_go", "on_demand")
    )
    parser.add_argument("--reliable", action="store_true", help="collector reliable_inputs")
    args = parser.parse_args()

    recording = organised_recording(args.bag)
    root = Path(tempfile.mkdtemp(prefix="live_replay_"))
    print(
        f"live replay: {args.bag} at {args.rate:g}x, {args.runs} runs, collector mode "
        f"{args.mode}, {'reliable' if args.reliable else 'best-effort'} inputs"
    )
    rows = []
    for run in range(args.runs):
        start = time.monotonic()
        row = one_run(recording, args, root / f"run_{run:02d}")
        rows.append(row)
        if run == 0:
            print("run  " + "  ".join(f"{key:>10}" for key in row) + "   time")
        cells = "  ".join(f"{value:>10}" for value in row.values())
        print(f"{run:>3}  {cells}   {time.monotonic() - start:.1f} s", flush=True)
    unaccounted = sum(row["unaccounted"] for row in rows)
    lost = sum(row["lost (counted)"] for row in rows)
    print(
        f"unaccounted profiles: {unaccounted} in {len(rows)} runs; lost in transport and "
        f"counted: {lost}; logs in {root}"
    )
    return 0 if unaccounted == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
