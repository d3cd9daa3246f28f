"""Helpers of the ROS tests: private DDS domains, node processes, a colcon install, a player.

Every test gets its own ``ROS_DOMAIN_ID`` (100-200) and ``ROS_AUTOMATIC_DISCOVERY_RANGE=
LOCALHOST`` so parallel runs never hear each other. Node processes write to a log file and
are always stopped (SIGINT, then SIGKILL by pid after a timeout). :class:`RosProbe` is the
test's side of the graph, in the test process: it replays a recording, listens to the
collector's diagnostics, calls services and reads latched topics.
"""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TransformStamped
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger

from linelaser_calib.core.geometry import transform_from_translation_quaternion
from linelaser_calib.core.robot.kinematics import JointStates
from linelaser_calib.core.types import FlangePose, Profile
from msg_adapters import (
    joint_state_msg,
    pointcloud2_from_points,
    pose_stamped_from_flange_pose,
    rclpy_types,
)

REPO_ROOT = Path(__file__).resolve().parents[1]
VENV_BIN = Path(sys.executable).parent
PACKAGE = "linelaser_calib"

_domain_counter = itertools.count()


#: Domain ids for the tests: 100 .. 199 (the ids of ROS 2 on one host go up to 232).
_FIRST_DOMAIN, _DOMAINS = 100, 100


def new_domain_id() -> int:
    """A ROS domain id in 100..199 for each call of this process, never one that another
    pytest-xdist worker uses: each worker (``PYTEST_XDIST_WORKER`` gw0, gw1, ... of
    ``PYTEST_XDIST_WORKER_COUNT``) takes its own share of the range and steps through it, so
    tests running side by side in two workers never hear each other."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    index = int(worker[2:]) if worker.startswith("gw") and worker[2:].isdigit() else 0
    share = _DOMAINS // max(count, 1)
    start = (os.getpid() * 13) % share
    return _FIRST_DOMAIN + index * share + (start + next(_domain_counter)) % share


def ros_env(domain_id: int, extra: dict[str, str] | None = None) -> dict[str, str]:
    """Environment of a node process on a private, localhost-only DDS domain."""
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        PYTHONUNBUFFERED="1",
        RCUTILS_COLORIZED_OUTPUT="0",
        RCUTILS_CONSOLE_OUTPUT_FORMAT="[{severity}] [{name}]: {message}",
    )
    env.update(extra or {})
    return env


def wait_for(
    predicate: Callable[[], Any], timeout_s: float, what: str, poll_s: float = 0.05
) -> Any:
    """Poll ``predicate`` until it returns a truthy value; fail the test after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")
        time.sleep(poll_s)


class NodeProcess:
    """One node in its own process group, its output in ``log_path``."""

    def __init__(self, argv: list[str], env: dict[str, str], log_path: Path) -> None:
        self.argv = argv
        self.log_path = log_path
        self._log = log_path.open("ab")
        self.process = subprocess.Popen(
            argv, env=env, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True
        )

    @property
    def pid(self) -> int:
        return self.process.pid

    def alive(self) -> bool:
        return self.process.poll() is None

    def log(self) -> str:
        return self.log_path.read_text(encoding="utf-8", errors="replace")

    def stop(self, timeout_s: float = 5.0) -> int:
        """SIGINT (a clean rclpy shutdown), then SIGKILL after ``timeout_s``; the exit code."""
        if self.alive():
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.kill()
        self._log.close()
        return int(self.process.returncode)

    def kill(self) -> None:
        """SIGKILL, as a crash would."""
        if self.alive():
            os.kill(self.pid, signal.SIGKILL)
        self.process.wait(10.0)


class Processes:
    """Starts node processes and stops every one of them in :meth:`stop_all`."""

    def __init__(self, directory: Path, env: dict[str, str]) -> None:
        self.directory = directory
        self.env = env
        self.started: list[NodeProcess] = []

    def start(self, name: str, argv: list[str], env: dict[str, str] | None = None) -> NodeProcess:
        node = NodeProcess(argv, env or self.env, self.directory / f"{name}.log")
        self.started.append(node)
        return node

    def stop_all(self) -> None:
        for node in self.started:
            node.stop()

    def logs(self) -> str:
        """Every process's output, for assertion messages."""
        return "\n".join(f"--- {n.log_path.name}\n{n.log()[-4000:]}" for n in self.started)


@contextmanager
def processes(directory: Path, domain_id: int) -> Iterator[Processes]:
    """A :class:`Processes` whose nodes are stopped however the test ends."""
    group = Processes(directory, ros_env(domain_id, {"ROS_LOG_DIR": str(directory / "ros_log")}))
    try:
        yield group
    finally:
        group.stop_all()


def module_command(module: str, *ros_args: str) -> list[str]:
    """``python -m module --ros-args ...`` with the test's interpreter."""
    return [sys.executable, "-m", module, "--ros-args", *ros_args]


def params(**values: Any) -> list[str]:
    """``-p name:=value`` arguments (strings quoted, as the values are read as YAML; a list
    or tuple of numbers becomes a double array)."""
    out: list[str] = []
    for name, value in values.items():
        if isinstance(value, bool):
            text = str(value).lower()
        elif isinstance(value, int | float):
            text = repr(value)
        elif isinstance(value, list | tuple):
            text = "[" + ",".join(repr(float(v)) for v in value) + "]"
        else:
            text = f"'{value}'"
        out += ["-p", f"{name}:={text}"]
    return out


def settled(values: dict[str, str]) -> int:
    """Accepted samples, after checking that every received profile is accounted for."""
    received, accepted = int(values["profiles received"]), int(values["samples accepted"])
    rejected, skipped = int(values["profiles rejected"]), int(values["profiles skipped"])
    assert int(values["profiles pending"]) == 0
    assert received == accepted + rejected + skipped, values
    return accepted


# -- colcon --------------------------------------------------------------------------------

_colcon_lock = threading.Lock()
_colcon_installs: dict[str, Path] = {}


@dataclass(frozen=True)
class ColconInstall:
    """A colcon workspace install of the package."""

    install_base: Path

    @property
    def prefix(self) -> Path:
        return self.install_base / PACKAGE

    def env(self, base: dict[str, str]) -> dict[str, str]:
        """``base`` with the workspace sourced (what ``install/setup.sh`` sets)."""
        env = dict(base)
        site = self.prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
        env["AMENT_PREFIX_PATH"] = os.pathsep.join(
            filter(None, [str(self.prefix), env.get("AMENT_PREFIX_PATH", "")])
        )
        env["PYTHONPATH"] = os.pathsep.join(
            filter(None, [str(site / "site-packages"), env.get("PYTHONPATH", "")])
        )
        env["PATH"] = os.pathsep.join([str(VENV_BIN), env.get("PATH", "")])
        return env

    def executable(self, name: str, env: dict[str, str]) -> Path:
        """What ``ros2 run linelaser_calib <name>`` runs: ``get_package_prefix`` + lib/pkg."""
        script = (
            "import sys\n"
            "from ament_index_python.packages import get_package_prefix\n"
            f"print(get_package_prefix({PACKAGE!r}))\n"
        )
        prefix = subprocess.run(
            [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
        ).stdout.strip()
        return Path(prefix) / "lib" / PACKAGE / name


def colcon_build(workspace: Path) -> subprocess.CompletedProcess[str]:
    """``colcon build`` of the repository into ``workspace`` (build, install and log there).

    One build at a time across processes (pytest-xdist workers): the build writes the
    package's egg-info into the source tree."""
    env = dict(os.environ)
    env["PATH"] = os.pathsep.join([str(VENV_BIN), env.get("PATH", "")])
    lock_path = Path(tempfile.gettempdir()) / "linelaser_calib_colcon_build.lock"
    with lock_path.open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return _colcon_build_unlocked(workspace, env)


def _colcon_build_unlocked(
    workspace: Path, env: dict[str, str]
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [
            str(VENV_BIN / "colcon"),
            "--log-base",
            str(workspace / "log"),
            "build",
            "--base-paths",
            str(REPO_ROOT),
            "--build-base",
            str(workspace / "build"),
            "--install-base",
            str(workspace / "install"),
            "--packages-select",
            PACKAGE,
        ],
        cwd=workspace,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def colcon_install(workspace: Path) -> ColconInstall:
    """A colcon install, built once per test session (the first caller's ``workspace``)."""
    with _colcon_lock:
        if "install" not in _colcon_installs:
            workspace.mkdir(parents=True, exist_ok=True)
            done = colcon_build(workspace)
            assert done.returncode == 0, f"colcon build failed:\n{done.stdout}\n{done.stderr}"
            _colcon_installs["install"] = workspace / "install"
        return ColconInstall(_colcon_installs["install"])


# -- the test's side of the graph ------------------------------------------------------------


def reliable_qos(depth: int, latched: bool = False) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


@dataclass(frozen=True)
class Recording:
    """Profiles and flange poses (PoseStamped, or JointState) to replay, as rclpy messages
    in stamp order."""

    messages: list[tuple[int, bool, Any]]  # (stamp ns, is_profile, message)

    @classmethod
    def from_data(
        cls,
        profiles: list[Profile],
        poses: list[FlangePose],
        sensor_frame: str = "laser",
        base_frame: str = "base_link",
        joint_states: JointStates | None = None,
    ) -> Recording:
        """With ``joint_states`` these are replayed instead of ``poses``."""
        types = rclpy_types()
        items = [
            (
                p.stamp_ns,
                True,
                pointcloud2_from_points(p.points, p.stamp_ns, sensor_frame, types=types),
            )
            for p in profiles
        ]
        if joint_states is None:
            items += [
                (
                    q.stamp_ns,
                    False,
                    pose_stamped_from_flange_pose(
                        FlangePose(q.stamp_ns, q.T_base_flange, base_frame), types=types
                    ),
                )
                for q in poses
            ]
        else:
            items += [
                (int(t), False, joint_state_msg(int(t), joint_states.names, q, types=types))
                for t, q in zip(joint_states.stamps_ns, joint_states.positions, strict=True)
            ]
        items.sort(key=lambda item: (item[0], item[1]))
        return cls(items)


def init_context(domain_id: int, args: list[str] | None = None) -> Context:
    """An initialised rclpy context on ``domain_id``, discovering on localhost only.

    rcl reads ``ROS_AUTOMATIC_DISCOVERY_RANGE`` when the context is initialised; it is set
    for that moment only, so the test process's environment is left as it was. No log file
    is written (``--disable-external-lib-logs``).
    """
    context = Context()
    previous = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    try:
        rclpy.init(
            args=["--ros-args", "--disable-external-lib-logs", *(args or [])],
            context=context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
    finally:
        if previous is None:
            del os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"]
        else:
            os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = previous
    return context


class RosProbe:
    """An rclpy node in the test process on the test's domain, spun in a background thread."""

    def __init__(self, domain_id: int) -> None:
        self.context = init_context(domain_id)
        self.node = rclpy.create_node("e2e_probe", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._lock = threading.Lock()
        self._diagnostics: dict[str, dict[str, str]] = {}
        self.node.create_subscription(
            DiagnosticArray, "/diagnostics", self._on_diagnostics, reliable_qos(100)
        )
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        with contextlib.suppress(Exception):  # the context shut down while spinning
            self.executor.spin()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()
        self._thread.join(5.0)

    # -- diagnostics ---------------------------------------------------------------------

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        with self._lock:
            for status in msg.status:
                node = status.name.split(":")[0]
                self._diagnostics[node] = {kv.key: kv.value for kv in status.values}

    def diagnostics(self, node: str = "collector") -> dict[str, str] | None:
        """The latest diagnostic values of ``node`` (None before the first)."""
        with self._lock:
            values = self._diagnostics.get(node)
            return None if values is None else dict(values)

    def wait_counts(
        self, timeout_s: float, node: str = "collector", **expected: int
    ) -> dict[str, str]:
        """Wait until ``node`` reports the expected counts (``_`` in a key stands for a space)."""

        def reached() -> dict[str, str] | None:
            values = self.diagnostics(node)
            if values is None:
                return None
            ok = all(int(values.get(k.replace("_", " "), -1)) == v for k, v in expected.items())
            return values if ok else None

        try:
            return wait_for(reached, timeout_s, f"{node} counts {expected}")  # type: ignore[no-any-return]
        except AssertionError as err:
            raise AssertionError(f"{err}; last diagnostics: {self.diagnostics(node)}") from None

    # -- publishing ----------------------------------------------------------------------

    def player(
        self,
        profile_topic: str = "profile",
        pose_topic: str = "flange_pose",
        pose_type: type = PoseStamped,
    ) -> Player:
        """A player; ``pose_type`` JointState replays joint states on ``pose_topic``."""
        return Player(self, profile_topic, pose_topic, pose_type)

    # -- services and latched topics -----------------------------------------------------

    def call(self, service: str, timeout_s: float = 180.0) -> Trigger.Response:
        """Call a std_srvs/Trigger service and wait for the answer."""
        client = self.node.create_client(Trigger, service)
        try:
            wait_for(client.service_is_ready, 30.0, f"service {service}", poll_s=0.1)
            future = client.call_async(Trigger.Request())
            wait_for(future.done, timeout_s, f"the answer of {service}")
            return future.result()
        finally:
            self.node.destroy_client(client)

    def call_async(self, service: str) -> Any:
        """Start a Trigger call; returns the future (the client stays alive)."""
        client = self.node.create_client(Trigger, service)
        wait_for(client.service_is_ready, 30.0, f"service {service}", poll_s=0.1)
        return client.call_async(Trigger.Request())

    def latched(self, msg_type: type, topic: str, timeout_s: float = 10.0) -> Any:
        """The message a late-joining transient_local subscriber receives on ``topic``."""
        received: list[Any] = []
        sub = self.node.create_subscription(
            msg_type, topic, received.append, reliable_qos(1, latched=True)
        )
        try:
            wait_for(lambda: received, timeout_s, f"a latched message on {topic}")
            return received[-1]
        finally:
            self.node.destroy_subscription(sub)

    def hand_eye(self) -> np.ndarray:
        """T_flange_sensor (4, 4) from ``linelaser_calib/hand_eye`` (late-joining subscriber)."""
        msg: TransformStamped = self.latched(TransformStamped, "linelaser_calib/hand_eye")
        t, q = msg.transform.translation, msg.transform.rotation
        return transform_from_translation_quaternion([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])


class Player:
    """Replays a :class:`Recording` on the collector's input topics (reliable, deep)."""

    def __init__(
        self, probe: RosProbe, profile_topic: str, pose_topic: str, pose_type: type = PoseStamped
    ) -> None:
        self.probe = probe
        qos = reliable_qos(10000)
        self.profile_pub = probe.node.create_publisher(PointCloud2, profile_topic, qos)
        self.pose_pub = probe.node.create_publisher(pose_type, pose_topic, qos)

    def wait_matched(self, timeout_s: float = 30.0, settle_s: float = 0.5) -> None:
        """Wait until the collector subscribes to both topics, then ``settle_s`` more (the
        collector's side of the discovery may still be under way)."""
        wait_for(
            lambda: (
                self.profile_pub.get_subscription_count() > 0
                and self.pose_pub.get_subscription_count() > 0
            ),
            timeout_s,
            "the collector's subscriptions",
        )
        time.sleep(settle_s)

    def play(
        self, recording: Recording, rate: float, start: int = 0, stop: int | None = None
    ) -> int:
        """Publish messages ``start:stop`` at ``rate`` times their stamp spacing; profiles sent."""
        items = recording.messages[start:stop]
        if not items:
            return 0
        first = items[0][0]
        t0 = time.monotonic()
        sent = 0
        for stamp_ns, is_profile, msg in items:
            delay = (stamp_ns - first) / 1e9 / rate - (time.monotonic() - t0)
            if delay > 0:
                time.sleep(delay)
            if is_profile:
                self.profile_pub.publish(msg)
                sent += 1
            else:
                self.pose_pub.publish(msg)
        return sent

    def publish_profile(self, msg: PointCloud2) -> None:
        self.profile_pub.publish(msg)

    def publish_pose(self, msg: PoseStamped) -> None:
        self.pose_pub.publish(msg)


class ServiceUnderTest:
    """A calibration_service node spun in-process (its own MultiThreadedExecutor thread), with
    a probe to call it; ``overrides`` are its parameters besides ``output_path``."""

    def __init__(self, context: Context, domain: int, output: Path, **overrides: Any) -> None:
        from linelaser_calib.nodes.calibration_service import CalibrationServiceNode

        parameters = {"output_path": str(output), **overrides}
        self.node = CalibrationServiceNode(
            context=context,
            parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()],
        )
        self.executor = MultiThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.probe = RosProbe(domain)

    def send(self, samples: list[tuple[Profile, FlangePose]], timeout_s: float = 20.0) -> None:
        """Publish the samples as the collector does (latched, deep enough to lose none) and
        wait until the node holds them all."""
        types = rclpy_types()
        node = self.probe.node
        qos = reliable_qos(max(100, len(samples)), latched=True)
        profiles = node.create_publisher(PointCloud2, "linelaser_calib/samples/profile", qos)
        poses = node.create_publisher(PoseStamped, "linelaser_calib/samples/flange_pose", qos)
        for p, pose in samples:
            profiles.publish(pointcloud2_from_points(p.points, p.stamp_ns, "laser", types=types))
            poses.publish(pose_stamped_from_flange_pose(pose, types=types))
        wait_for(lambda: self.node.sample_count == len(samples), timeout_s, "the samples")

    def close(self) -> None:
        self.probe.close()
        self.executor.shutdown()
        self.node.destroy_node()
