"""Throughput of the collector node: high-rate profiles and flange poses, CPU, latency, drops.

For each profile rate (default 100, 200 and 500 Hz), starts ``python -m
linelaser_calib.nodes.collector`` (``continuous`` mode, store first) on a private ROS domain
and streams, from this process, 2048-point profiles and flange poses at 500 Hz for 10 s,
stamped with the wall clock. The simulated robot rests at one of a few scan poses for a
second, then jumps to the next (the profiles around a jump are rejected as taken in motion).
Prints the collector's counts per rate, then a table:

- sent, received by the collector, lost in transport as the collector counted it;
- stored: samples in the session file afterwards, and per second of streaming;
- skipped and rejected (with the reasons in the counts above);
- CPU of the collector process (all threads, from /proc/<pid>/stat) and of this publisher,
  % of one core;
- latency from a profile's stamp to the publication of its sample (stored and flushed
  first), as received here.

Run from the repository root (not part of the test suite)::

    .venv/bin/python bench/collector_throughput.py [--duration 10] [--profile-rates 100 200]
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import PointCloud2

from linelaser_calib.core.types import FlangePose
from linelaser_calib.io import read_bag
from linelaser_calib.nodes.collection import (
    KEY_PENDING,
    KEY_PROFILES_BEFORE,
    KEY_PROFILES_LOST,
    KEY_RECEIVED,
    KEY_REJECTED,
    KEY_SKIPPED,
)
from linelaser_calib.nodes.common import SAMPLE_PROFILE_TOPIC
from linelaser_calib.sim import scenario_from_preset, simulate
from msg_adapters import (
    pointcloud2_from_points,
    pose_stamped_from_flange_pose,
    rclpy_types,
    time_msg_from_ns,
)

CLK_TCK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (all threads), s."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


class Bench:
    """The bench's node: publishers, a sample listener and a diagnostics listener."""

    def __init__(self, domain_id: int) -> None:
        self.context = Context()
        rclpy.init(
            args=["--ros-args", "--disable-external-lib-logs"],
            context=self.context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self.node = rclpy.create_node("throughput_bench", context=self.context)
        reliable = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE
        )
        latched = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=10000,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        self.profile_pub = self.node.create_publisher(PointCloud2, "profile", reliable)
        self.pose_pub = self.node.create_publisher(PoseStamped, "flange_pose", reliable)
        self.latencies_s: list[float] = []
        self.diagnostics: dict[str, str] = {}
        self._lock = threading.Lock()
        self.node.create_subscription(PointCloud2, SAMPLE_PROFILE_TOPIC, self._on_sample, latched)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, reliable)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _on_sample(self, msg: PointCloud2) -> None:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        with self._lock:
            self.latencies_s.append((time.time_ns() - stamp_ns) / 1e9)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith("collector"):
                with self._lock:
                    self.diagnostics = {kv.key: kv.value for kv in status.values}

    def counts(self) -> dict[str, str]:
        with self._lock:
            return dict(self.diagnostics)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def scan_poses(points: int, count: int) -> tuple[list[PointCloud2], list[PoseStamped]]:
    """Simulated profiles (``points`` rays) and their flange poses, as rclpy messages."""
    data = simulate(scenario_from_preset("ur_scancontrol", resolution=points, n_poses=count), 1)
    types = rclpy_types()
    clouds = [pointcloud2_from_points(p.points, 0, "laser", types=types) for p in data.profiles]
    poses = [
        pose_stamped_from_flange_pose(FlangePose(0, T, "base_link"), types=types)
        for T in data.truth.T_base_flange_recorded
    ]
    return clouds, poses


def stream(
    bench: Bench, clouds: list[PointCloud2], poses: list[PoseStamped], args: argparse.Namespace
) -> int:
    """Publish poses and profiles, each at its own rate, for ``args.duration`` s (stamped with
    the wall clock at publication); profiles sent."""
    types = rclpy_types()
    events = sorted(
        [(k / args.pose_rate, False) for k in range(round(args.duration * args.pose_rate))]
        + [(k / args.profile_rate, True) for k in range(round(args.duration * args.profile_rate))]
    )
    start = time.monotonic()
    sent = 0
    for t, is_profile in events:
        delay = start + t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        waypoint = int(t / args.dwell) % len(poses)
        stamp = time_msg_from_ns(time.time_ns(), types)
        if is_profile:
            cloud = clouds[waypoint]
            cloud.header.stamp = stamp
            bench.profile_pub.publish(cloud)
            sent += 1
        else:
            pose = poses[waypoint]
            pose.header.stamp = stamp
            bench.pose_pub.publish(pose)
    return sent


def run_rate(
    profile_rate: float,
    clouds: list[PointCloud2],
    poses: list[PoseStamped],
    args: argparse.Namespace,
) -> dict[str, int | float]:
    """Stream at one profile rate to a fresh collector; the row of the table."""
    workdir = Path(tempfile.mkdtemp(prefix=f"collector_bench_{profile_rate:g}hz_"))
    domain = args.domain + int(profile_rate) % 50
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(domain),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_LOG_DIR=str(workdir / "ros_log"),
    )
    os.environ.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    command = [
        sys.executable,
        "-m",
        "linelaser_calib.nodes.collector",
        "--ros-args",
        "-p",
        f"session_dir:={workdir / 'sessions'}",
        "-p",
        f"mode:={args.mode}",
        "-p",
        f"max_rate_hz:={args.max_rate}",
        "-p",
        f"reliable_inputs:={str(args.reliable).lower()}",
        "-p",
        "diagnostics_period_s:=0.2",
    ]
    log = (workdir / "collector.log").open("wb")
    collector = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)
    bench = Bench(domain)
    rate_args = argparse.Namespace(**{**vars(args), "profile_rate": profile_rate})
    try:
        deadline = time.monotonic() + 60.0
        while not (
            bench.profile_pub.get_subscription_count() and bench.pose_pub.get_subscription_count()
        ):
            if time.monotonic() > deadline or collector.poll() is not None:
                raise SystemExit(f"the collector did not start; see {workdir / 'collector.log'}")
            time.sleep(0.1)
        time.sleep(1.0)
        cpu0, wall0 = cpu_seconds(collector.pid), time.monotonic()
        bench_cpu0 = time.process_time()
        sent = stream(bench, clouds, poses, rate_args)
        cpu1, wall1 = cpu_seconds(collector.pid), time.monotonic()
        bench_cpu1 = time.process_time()
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            counts = bench.counts()
            if counts.get(KEY_PENDING) == "0" and int(counts.get(KEY_RECEIVED, -1)) >= sent:
                break
            time.sleep(0.2)
        time.sleep(1.0)
        counts = bench.counts()
        latencies = np.array(bench.latencies_s)
    finally:
        bench.close()
        collector.send_signal(signal.SIGINT)
        try:
            collector.wait(10.0)
        except subprocess.TimeoutExpired:
            collector.kill()
        log.close()
    wall = wall1 - wall0
    stored = len(read_bag(sorted((workdir / "sessions").glob("session_*"))[-1]).profiles)
    received = int(counts.get(KEY_RECEIVED, 0))
    p50, p95 = np.percentile(latencies * 1e3, [50, 95]) if latencies.size else (np.nan, np.nan)
    print(f"  {profile_rate:g} Hz: collector counts (session and log in {workdir}):")
    for key, value in counts.items():
        print(f"    {key:<70} {value}")
    return {
        "Hz": profile_rate,
        "sent": sent,
        "received": received,
        "lost (counted)": int(counts.get(KEY_PROFILES_LOST, 0))
        + int(counts.get(KEY_PROFILES_BEFORE, 0)),
        "stored": stored,
        "stored/s": stored / args.duration,
        "skipped": int(counts.get(KEY_SKIPPED, 0)),
        "rejected": int(counts.get(KEY_REJECTED, 0)),
        "CPU %": 100 * (cpu1 - cpu0) / wall,
        "bench CPU %": 100 * (bench_cpu1 - bench_cpu0) / wall,
        "latency p50 ms": float(p50),
        "latency p95 ms": float(p95),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=10.0, help="streaming time, s")
    parser.add_argument(
        "--profile-rates", type=float, nargs="+", default=[100.0, 200.0, 500.0], help="Hz"
    )
    parser.add_argument("--pose-rate", type=float, default=500.0, help="Hz")
    parser.add_argument("--points", type=int, default=2048, help="points per profile")
    parser.add_argument("--dwell", type=float, default=1.0, help="time at each scan pose, s")
    parser.add_argument("--mode", default="continuous", help="collector mode")
    parser.add_argument("--max-rate", type=float, default=0.0, help="collector max_rate_hz")
    parser.add_argument("--reliable", action="store_true", help="collector reliable_inputs")
    parser.add_argument("--domain", type=int, default=150 + os.getpid() % 50)
    args = parser.parse_args()

    clouds, poses = scan_poses(args.points, 12)
    load = os.getloadavg()
    print(
        f"collector throughput: {args.duration:g} s of profiles x {args.points} points + "
        f"{args.pose_rate:g} Hz poses, mode {args.mode}, max_rate_hz {args.max_rate:g}, "
        f"{'reliable' if args.reliable else 'best-effort'} inputs; {os.cpu_count()} cores, "
        f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} at the start"
    )
    rows = [run_rate(rate, clouds, poses, args) for rate in args.profile_rates]
    print("| " + " | ".join(rows[0]) + " |")
    print("|" + "---|" * len(rows[0]))
    for row in rows:
        cells = [f"{v:.0f}" if isinstance(v, float) else str(v) for v in row.values()]
        print("| " + " | ".join(cells) + " |")
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} at the end")
    lost = sum(int(row["sent"]) - int(row["received"]) - int(row["lost (counted)"]) for row in rows)
    return 0 if lost == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
