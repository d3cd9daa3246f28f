"""/tf in and /tf_static out over DDS, with the tf2_msgs that ``make venv`` builds.

A simulated robot_state_publisher in the test process sends the UR chain base_link -> ... ->
tool0 on /tf at 500 Hz (of recording time) and its fixed links on /tf_static, beside a
committed recording's profiles, into the collector (pose_source tf) and calibration_service
processes; the service's /tf_static is read by a subscriber that starts after /calibrate.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
import yaml
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_helpers import (
    REPO_ROOT,
    Processes,
    RosProbe,
    colcon_install,
    init_context,
    module_command,
    new_domain_id,
    params,
    processes,
    reliable_qos,
    settled,
    wait_for,
)
from scipy.spatial.transform import Rotation, Slerp
from tf2_msgs.msg import TFMessage

from linelaser_calib.core.tf import StampedTransform
from linelaser_calib.io import read_bag, read_result_yaml, read_truth_yaml
from linelaser_calib.sim.tf_chain import ur_tf_tree
from linelaser_calib.summary import truth_error
from msg_adapters import pointcloud2_from_points, rclpy_types, transform_stamped_from_matrix

#: The type hash every ROS 2 Jazzy node advertises for tf2_msgs/msg/TFMessage.
JAZZY_TFMESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
#: A committed UR cell recording (stop and go, 125 Hz flange poses) whose pose-topic
#: calibration lands within 3 of its 1 sigma of the truth (the benches' bound).
BAG = REPO_ROOT / "bags" / "ur_scancontrol"
#: robot_state_publisher's rate here (of recording time), Hz.
TF_RATE_HZ = 500
#: How long the arm rests after the recording's last pose, ns.
REST_NS = 100_000_000
#: Replay speed: 1,500 /tf messages a second of wall time. The collector spends about 0.5 ms
#: on each (rclpy's executor most of it); a loaded runner's collector catches up afterwards.
RATE = 3.0
COLLECTOR = "linelaser_calib.nodes.collector"
SERVICE = "linelaser_calib.nodes.calibration_service"
#: The fixed links sent before the collector starts, the others after (see ur_tf_tree).
EARLY_STATIC = {"base_link_inertia", "base"}


def test_built_tf2_msgs_has_jazzys_type_hash() -> None:
    """The hash a node advertises for the TFMessage built by make venv is Jazzy's."""
    context = init_context(new_domain_id())
    try:
        node = rclpy.create_node("hash_probe", context=context)
        node.create_publisher(TFMessage, "/tf", 1)
        (info,) = node.get_publishers_info_by_topic("/tf")
        assert info.topic_type == "tf2_msgs/msg/TFMessage"
        assert str(info.topic_type_hash) == JAZZY_TFMESSAGE_HASH
        node.destroy_node()
    finally:
        context.try_shutdown()


# -- the simulated cell ------------------------------------------------------------------


def tf_message(transforms: list[StampedTransform], types: Any) -> TFMessage:
    return TFMessage(
        transforms=[
            transform_stamped_from_matrix(
                t.T_parent_child, t.stamp_ns, t.parent, t.child, types=types
            )
            for t in transforms
        ]
    )


class Cell:
    """The bag's profiles and its flange poses as robot_state_publisher's /tf and /tf_static.

    The bag's poses are split into the UR chain (:func:`ur_tf_tree`) and each moving link is
    interpolated to 500 Hz, as the links of an arm sampled from its joint states; every
    profile is taken at a standstill, where the chain's product is the recorded pose.
    """

    def __init__(self) -> None:
        contents = read_bag(BAG)
        self.profiles = contents.profiles
        self.truth = read_truth_yaml(BAG / "truth.yaml")
        dynamic, self.static = ur_tf_tree(contents.poses, "base_link", "tool0")
        recorded = np.array([q.stamp_ns for q in contents.poses])
        step = 1_000_000_000 // TF_RATE_HZ
        # The arm rests 0.1 s past the last recorded pose, so that the last profile is paired
        # as soon as the poses after it arrive (not after the pose stream's silence).
        self.stamps = np.arange(recorded[0], recorded[-1] + REST_NS, step)
        self.links: list[tuple[str, str]] = []
        translations, quaternions = [], []
        for parent, child in dict.fromkeys((d.parent, d.child) for d in dynamic):
            T = np.array([d.T_parent_child for d in dynamic if d.child == child])
            seconds = (recorded - recorded[0]) / 1e9
            at = np.minimum(self.stamps - recorded[0], recorded[-1] - recorded[0]) / 1e9
            rotations = Slerp(seconds, Rotation.from_matrix(T[:, :3, :3]))(at)
            quaternions.append(rotations.as_quat())
            translations.append(
                np.stack([np.interp(at, seconds, T[:, i, 3]) for i in range(3)], axis=1)
            )
            self.links.append((parent, child))
        self.translations = np.stack(translations, axis=1)  # (stamps, links, 3)
        self.quaternions = np.stack(quaternions, axis=1)  # (stamps, links, 4) xyzw
        self.types = rclpy_types()
        self.clouds = [
            (p.stamp_ns, pointcloud2_from_points(p.points, p.stamp_ns, "laser", types=self.types))
            for p in self.profiles
        ]
        self._tf = tf_message(
            [StampedTransform(0, a, b, np.eye(4)) for a, b in self.links], self.types
        )

    def tf(self, k: int) -> TFMessage:
        """The /tf message at the k-th 500 Hz stamp (one message reused: publish serialises)."""
        sec, nanosec = divmod(int(self.stamps[k]), 1_000_000_000)
        for j, transform in enumerate(self._tf.transforms):
            transform.header.stamp.sec, transform.header.stamp.nanosec = sec, nanosec
            t, q = transform.transform.translation, transform.transform.rotation
            t.x, t.y, t.z = (float(v) for v in self.translations[k, j])
            q.x, q.y, q.z, q.w = (float(v) for v in self.quaternions[k, j])
        return self._tf

    def static_message(self, children: set[str], keep: bool) -> TFMessage:
        """The fixed links whose child is in ``children`` (``keep``) or is not."""
        chosen = [t for t in self.static if (t.child in children) == keep]
        return tf_message(chosen, self.types)

    def items(self, start_ns: int, stop_ns: int, tf: bool = True) -> list[tuple[int, str, Any]]:
        """(stamp, topic, message or /tf index) in stamp order in [start, stop); /tf with ``tf``."""
        chosen: list[tuple[int, str, Any]] = [
            (s, "profile", m) for s, m in self.clouds if start_ns <= s < stop_ns
        ]
        if tf:
            chosen += [
                (int(s), "/tf", k) for k, s in enumerate(self.stamps) if start_ns <= s < stop_ns
            ]
        return sorted(chosen, key=lambda item: (item[0], item[1]))


@pytest.fixture(scope="module")
def cell() -> Cell:
    return Cell()


def play(
    cell: Cell, publishers: dict[str, Any], items: list[tuple[int, str, Any]], rate: float
) -> int:
    """Publish ``items`` at ``rate`` times their stamp spacing; the profiles sent."""
    if not items:
        return 0
    first, t0 = items[0][0], time.monotonic()
    for stamp_ns, topic, msg in items:
        delay = (stamp_ns - first) / 1e9 / rate - (time.monotonic() - t0)
        if delay > 0:
            time.sleep(delay)
        publishers[topic].publish(cell.tf(msg) if topic == "/tf" else msg)
    return sum(topic == "profile" for _, topic, _ in items)


def latched(probe: RosProbe, msg: TFMessage) -> Any:
    """A /tf_static publisher of its own (as each static_transform_publisher is) holding ``msg``."""
    publisher = probe.node.create_publisher(TFMessage, "/tf_static", reliable_qos(1, latched=True))
    publisher.publish(msg)
    return publisher


@pytest.fixture
def graph(tmp_path: Path) -> Iterator[tuple[RosProbe, Processes]]:
    domain = new_domain_id()
    probe = RosProbe(domain)
    try:
        with processes(tmp_path, domain) as procs:
            yield probe, procs
    finally:
        probe.close()


def node_args(tmp_path: Path, **collector: Any) -> tuple[list[str], list[str]]:
    """The two nodes' parameters: pose_source tf, and output under ``tmp_path``."""
    return (
        params(
            pose_source="tf",
            session_dir=str(tmp_path / "sessions"),
            diagnostics_period_s=0.2,
            **collector,
        ),
        params(output_path=str(tmp_path / "hand_eye.yaml"), diagnostics_period_s=0.2),
    )


# -- over DDS ------------------------------------------------------------------------------


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.serial
def test_live_tf_chain_calibrates_the_bag_and_the_hand_eye_reaches_tf_static(
    graph: tuple[RosProbe, Processes],
    cell: Cell,
    tmp_path: Path,
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    """The colcon-built nodes (as ``ros2 run`` starts them): base_link's fixed links are on
    /tf_static before the collector starts (latched), the wrist's after; every profile is
    paired through the chain, and /calibrate lands within 3 of its 1 sigma of the truth."""
    probe, procs = graph
    install = colcon_install(tmp_path_factory.mktemp("colcon"))
    env = install.env(procs.env)
    exe = {
        name: str(install.executable(name, env)) for name in ("collector", "calibration_service")
    }
    early = latched(probe, cell.static_message(EARLY_STATIC, keep=True))
    collector_args, service_args = node_args(tmp_path, reliable_inputs=True, pose_window_s=10.0)
    procs.start("collector", [exe["collector"], "--ros-args", *collector_args], env)
    procs.start(
        "calibration_service", [exe["calibration_service"], "--ros-args", *service_args], env
    )
    publishers = {
        "profile": probe.node.create_publisher(
            type(cell.clouds[0][1]), "profile", reliable_qos(10000)
        ),
        "/tf": probe.node.create_publisher(TFMessage, "/tf", reliable_qos(10000)),
    }
    wait_for(
        lambda: all(p.get_subscription_count() > 0 for p in publishers.values()),
        30.0,
        "the collector's subscriptions",
    )
    late = latched(probe, cell.static_message(EARLY_STATIC, keep=False))
    time.sleep(0.5)
    sent = play(cell, publishers, cell.items(0, 2**63), RATE)
    assert sent == len(cell.profiles)
    values = probe.wait_counts(90.0, profiles_received=sent, profiles_pending=0)
    assert settled(values) == sent, f"{values}\n{procs.logs()}"
    probe.wait_counts(20.0, node="calibration_service", samples=sent)

    answer = probe.call("/calibrate")
    assert answer.success, answer.message + procs.logs()
    result = read_result_yaml(tmp_path / "hand_eye.yaml")
    error = truth_error(result.T_flange_sensor, cell.truth.T_flange_sensor)
    sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
    assert sigma_t is not None and sigma_r is not None
    ratios = np.abs(
        np.concatenate([error.rotation_axes_rad / sigma_r, error.translation_axes_m / sigma_t])
    )
    print(
        f"live /tf: hand-eye error {error.translation_m * 1e3:.4f} mm, "
        f"{np.degrees(error.rotation_rad):.4f} deg, largest error/sigma {ratios.max():.2f}"
    )
    assert ratios.max() < 3.0

    # A subscriber that starts now receives the hand-eye with the result file's frames.
    received: list[TFMessage] = []
    probe.node.create_subscription(
        TFMessage, "/tf_static", received.append, reliable_qos(100, latched=True)
    )

    def hand_eye() -> Any:
        found = [
            t for m in received for t in m.transforms if t.child_frame_id == result.child_frame
        ]
        return found[-1] if found else None

    transform = wait_for(hand_eye, 10.0, "the hand-eye on /tf_static")
    written = yaml.safe_load((tmp_path / "hand_eye.yaml").read_text())["hand_eye"]
    assert transform.header.frame_id == written["parent_frame"] == "tool0"
    assert transform.child_frame_id == written["child_frame"] == "laser"
    t, q = transform.transform.translation, transform.transform.rotation
    np.testing.assert_allclose([t.x, t.y, t.z], written["translation"], atol=1e-12)
    q_sent = np.array([q.x, q.y, q.z, q.w])
    assert abs(abs(q_sent @ np.asarray(written["rotation_xyzw"])) - 1.0) < 1e-12
    probe.node.destroy_publisher(early)
    probe.node.destroy_publisher(late)


@pytest.mark.ros
@pytest.mark.slow
def test_a_missing_link_and_a_stopped_tf_stream_are_named(
    graph: tuple[RosProbe, Processes], cell: Cell, tmp_path: Path
) -> None:
    """/tf from a best-effort publisher (heard by the default QoS). First wrist_3_link ->
    flange is missing from /tf_static, then it arrives but /tf stops: both times the
    collector's /diagnostics and the /calibrate answer name the frames."""
    probe, procs = graph
    missing = {"flange"}
    first = latched(probe, cell.static_message(missing, keep=False))
    collector_args, service_args = node_args(tmp_path)
    procs.start("collector", [*module_command(COLLECTOR), *collector_args])
    procs.start("calibration_service", [*module_command(SERVICE), *service_args])
    best_effort = QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=10000, reliability=ReliabilityPolicy.BEST_EFFORT
    )
    publishers = {
        "profile": probe.node.create_publisher(
            type(cell.clouds[0][1]), "profile", reliable_qos(10000)
        ),
        "/tf": probe.node.create_publisher(TFMessage, "/tf", best_effort),
    }
    wait_for(
        lambda: all(p.get_subscription_count() > 0 for p in publishers.values()),
        30.0,
        "the collector's subscriptions",
    )
    time.sleep(0.5)
    stamps = [s for s, _ in cell.clouds]

    def answer_after(received: int) -> str:
        def answer() -> str | None:
            message = str(probe.call("/calibrate").message)
            return message if f"received {received} profiles" in message else None

        return str(wait_for(answer, 15.0, "the collector's reason in /calibrate's answer"))

    def reasons(values: dict[str, str]) -> str:
        return " | ".join(k for k in values if k.startswith("rejected pairing:"))

    gap = "no transform gives flange a parent"
    sent = play(cell, publishers, cell.items(0, stamps[3]), RATE)
    values = probe.wait_counts(20.0, profiles_received=sent, profiles_pending=0)
    assert settled(values) == 0
    assert int(values["poses rejected"]) == int(values["poses received"]) > 0, values
    assert gap in reasons(values), values
    message = answer_after(sent)
    assert message.startswith("no samples yet:") and gap in message

    second = latched(probe, cell.static_message(missing, keep=True))
    sent += play(cell, publishers, cell.items(stamps[4], stamps[7], tf=False), RATE)
    values = probe.wait_counts(20.0, profiles_received=sent, profiles_pending=0)
    assert settled(values) == 0
    stale = "forearm_link -> wrist_3_link is stale: its newest transform on /tf is"
    assert stale in reasons(values), values
    message = answer_after(sent)
    assert stale in message and gap in message
    assert "Traceback" not in procs.logs()
    for publisher in (first, second):
        probe.node.destroy_publisher(publisher)
