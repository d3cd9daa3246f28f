"""Throughput of the collector node: high-rate profiles and flange poses, CPU, latency, drops.

Starts ``python -m linelaser_calib.nodes.collector`` on a private ROS domain and streams, from
this process, 2048-point profiles at 100 Hz and flange poses at 500 Hz for 20 s, stamped with
the wall clock. The simulated robot rests at one of a few scan poses for a second, then jumps
to the next (the profiles around a jump are rejected as taken in motion). Prints:

- CPU of the collector process (all threads, from /proc/<pid>/stat), % of one core;
- latency from a profile's stamp to the publication of its sample, as received here;
- drops: profiles published here minus profiles the collector counted (must be 0);
- the collector's own counts (accepted, rejected and skipped per reason).

Run from the repository root (not part of the test suite)::

    .venv/bin/python bench/collector_throughput.py [--duration 20] [--min-sample-interval 0.1]
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
from linelaser_calib.nodes.collection import KEY_PENDING, KEY_RECEIVED
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
    """Publish poses and profiles on a fixed schedule for ``args.duration`` s; profiles sent."""
    types = rclpy_types()
    tick_s = 1.0 / args.pose_rate
    profile_every = round(args.pose_rate / args.profile_rate)
    ticks = round(args.duration / tick_s)
    start = time.monotonic()
    sent = 0
    for k in range(ticks):
        delay = start + k * tick_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        waypoint = int(k * tick_s / args.dwell) % len(poses)
        stamp = time_msg_from_ns(time.time_ns(), types)
        pose = poses[waypoint]
        pose.header.stamp = stamp
        bench.pose_pub.publish(pose)
        if k % profile_every == 0:
            cloud = clouds[waypoint]
            cloud.header.stamp = stamp
            bench.profile_pub.publish(cloud)
            sent += 1
    return sent


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=20.0, help="streaming time, s")
    parser.add_argument("--profile-rate", type=float, default=100.0, help="Hz")
    parser.add_argument("--pose-rate", type=float, default=500.0, help="Hz")
    parser.add_argument("--points", type=int, default=2048, help="points per profile")
    parser.add_argument("--dwell", type=float, default=1.0, help="time at each scan pose, s")
    parser.add_argument(
        "--min-sample-interval", type=float, default=0.0, help="collector parameter, s"
    )
    parser.add_argument("--reliable", action="store_true", help="collector reliable_inputs")
    parser.add_argument("--domain", type=int, default=150 + os.getpid() % 50)
    args = parser.parse_args()

    clouds, poses = scan_poses(args.points, 12)
    workdir = Path(tempfile.mkdtemp(prefix="collector_bench_"))
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(args.domain),
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
        f"min_sample_interval_s:={args.min_sample_interval}",
        "-p",
        f"reliable_inputs:={str(args.reliable).lower()}",
        "-p",
        "diagnostics_period_s:=0.2",
    ]
    log = (workdir / "collector.log").open("wb")
    collector = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT)
    bench = Bench(args.domain)
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
        sent = stream(bench, clouds, poses, args)
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
    received = int(counts.get(KEY_RECEIVED, 0))
    print(
        f"collector throughput: {args.duration:g} s of {args.profile_rate:g} Hz profiles x "
        f"{args.points} points + {args.pose_rate:g} Hz poses, min_sample_interval_s "
        f"{args.min_sample_interval:g}, {'reliable' if args.reliable else 'best-effort'} inputs"
    )
    print(f"  profiles published            {sent}")
    print(f"  profiles counted by collector {received}")
    print(f"  drops                         {sent - received}")
    print(f"  collector CPU                 {100 * (cpu1 - cpu0) / wall:.0f} % of one core")
    print(f"  bench (publisher) CPU         {100 * (bench_cpu1 - bench_cpu0) / wall:.0f} %")
    if latencies.size:
        p50, p95, p99 = np.percentile(latencies * 1e3, [50, 95, 99])
        print(
            f"  latency stamp -> sample       median {p50:.1f} ms, p95 {p95:.1f} ms, "
            f"p99 {p99:.1f} ms, max {latencies.max() * 1e3:.1f} ms ({latencies.size} samples)"
        )
    print("  collector counts:")
    for key, value in counts.items():
        print(f"    {key:<70} {value}")
    print(f"  (session and log in {workdir})")
    return 0 if sent == received else 1


if __name__ == "__main__":
    raise SystemExit(main())
