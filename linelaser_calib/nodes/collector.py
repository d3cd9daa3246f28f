# mypy: disallow-untyped-calls=False
# rclpy is only partly annotated: calling its untyped functions is expected here.
"""ROS 2 node ``collector``: pair live profiles with flange poses, choose samples, store, publish.

Subscribes ``profile`` (``sensor_msgs/PointCloud2``) and, per ``pose_source``, ``flange_pose``
(``geometry_msgs/PoseStamped``), ``/tf`` and ``/tf_static``, or ``joint_states``
(``sensor_msgs/JointState``, through the ``kinematics`` model); remap them to the driver's
topics. The logic lives in
:class:`~linelaser_calib.nodes.collection.LiveCollector`; this node wires it:

- receive callbacks decode messages and pair profiles (cheap), on a SingleThreadedExecutor:
  rclpy's MultiThreadedExecutor takes only a few hundred messages per second here, far
  below a 500 Hz flange-pose stream, while the single-threaded one keeps up. They also note
  each message's publisher sequence number, so profiles lost by the transport are counted;
- a storage thread appends the samples to the session's MCAP file (with pose_source
  joint_states also each sample's joint vector on ``/joint_states``, for a joint kinematic
  calibration of the session), flushes and fsyncs it
  every ``flush_period_s``, and only then publishes them on
  ``linelaser_calib/samples/profile`` and ``linelaser_calib/samples/flange_pose`` with
  identical stamps (reliable, transient_local, ``sample_history_depth`` deep, so a late or
  restarted calibration service receives every sample of the session);
- a validation thread checks profiles as the calibration will use them
  (``validate_sample``: cleaning, then the ellipse of a cylinder or, with ``target``
  ``known_point``, the V corner of a weld seam): in ``stop_and_go`` and ``on_demand`` modes
  the candidates before they become samples; in ``continuous`` mode the newest stored
  sample every ``LIVE_CHECK_PERIOD_S`` (store first: a slow fit never holds a sample back),
  and every ``clock_offset_period_s`` the live estimate of the profile-to-pose clock offset;
- ``~/capture`` (std_srvs/Trigger) waits, as a coroutine that lets the executor run on, for
  the next sample (``on_demand`` mode takes only these); ``~/clear`` starts a new session
  directory and keeps the old one on disk;
- ``/diagnostics`` carries the counts: received, paired, accepted, rejected and skipped per
  reason, lost in transport, and the clock offset estimate. Each new reason is logged once;
  the live clock offset is also published on ``linelaser_calib/clock_offset``;
- with ``auto_calibrate_samples`` > 0 it calls ``calibrate`` once the session holds that many.
"""

from __future__ import annotations

import datetime
import threading
import time
from collections.abc import Generator
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger

from linelaser_calib.core.errors import CalibrationError, InputError
from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method, validate_sample
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.tf import base_frame_warning
from linelaser_calib.core.types import FlangePose, Profile
from linelaser_calib.io import BagError, SessionBagWriter
from linelaser_calib.nodes.clock_offset import (
    ClockOffsetTracker,
    OffsetEstimate,
    offset_message,
    offset_values,
)
from linelaser_calib.nodes.collection import (
    COLLECTION_STATUS,
    KEY_NOTHING_ACCEPTED,
    CollectorConfig,
    LiveCollector,
    Mode,
    PendingSample,
)
from linelaser_calib.nodes.collector_parameters import PARAMETERS
from linelaser_calib.nodes.common import (
    CALIBRATE_SERVICE,
    CLOCK_OFFSET_TOPIC,
    POSE_INPUT_DEPTH,
    SAMPLE_POSE_TOPIC,
    SAMPLE_PROFILE_TOPIC,
    SESSION_TOPIC,
    declare_parameters,
    input_qos,
    latched_qos,
    run_node,
)
from linelaser_calib.nodes.joint_state_input import JointStatePoseInput, live_kinematic_model
from linelaser_calib.nodes.sessions import find_latest_session, new_session_path, session_samples
from linelaser_calib.nodes.tf_input import TfPoseInput
from linelaser_calib.settings import Front, given_from_parameters, pipeline_config, render
from msg_adapters import (
    MessageError,
    flange_pose_from_pose_stamped,
    pointcloud2_from_points,
    pose_stamped_from_flange_pose,
    profile_from_pointcloud2,
    rclpy_types,
)

NODE_NAME = "collector"


#: ``continuous``: at most one live check of a stored sample per period, s (a check costs a
#: few ms of CPU; the calibration checks every sample anyway).
LIVE_CHECK_PERIOD_S = 0.2


#: Diagnostic value: samples on disk in the session file.
KEY_STORED = "samples stored"


class CollectorNode(Node):
    """The ``collector`` node; see the module docstring. ``kwargs`` go to ``rclpy.node.Node``."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        p = declare_parameters(self, PARAMETERS)
        try:
            pairing = PairingConfig(
                sync_tolerance_s=p["sync_tolerance_s"],
                clock_offset_s=p["clock_offset_s"],
                max_linear_speed_m_s=p["max_linear_speed_m_s"],
                max_angular_speed_rad_s=p["max_angular_speed_rad_s"],
                speed_window_s=p["speed_window_s"],
            )
            config = CollectorConfig(
                pairing=pairing,
                pose_window_s=p["pose_window_s"],
                mode=Mode(p["mode"]),
                max_rate_hz=p["max_rate_hz"],
                standstill_s=p["standstill_s"],
                validation_queue_size=p["validation_queue_size"],
            )
        except ValueError as err:
            raise InputError(f"invalid collector parameters: {err}") from err
        pose_source = PoseSource(p["pose_source"])
        self._poses_from_pose_stamped = pose_source is PoseSource.POSE
        robot = (
            live_kinematic_model(str(p["kinematics"]), str(p["base_frame"]), str(p["flange_frame"]))
            if pose_source is PoseSource.JOINT_STATES
            else None
        )
        # Every sample of a live clock-offset batch counts (a batch is short already).
        self._pipeline = pipeline_config(
            p["target"],
            Method.DEFAULT,
            given_from_parameters({"radius": p["radius"]}),
            Front.NODE,
            seed=p["seed"],
            pairing=pairing,
            per_neighbourhood=0,
        )
        self._types = rclpy_types()
        self._collector = LiveCollector(config, self._log_new_reason)
        self._offsets = (
            ClockOffsetTracker(self._pipeline, p["clock_offset_period_s"])
            if config.mode is Mode.CONTINUOUS
            and self._pipeline.target_impl.estimates_clock_offset
            and p["clock_offset_period_s"] > 0.0
            else None
        )
        self._history_depth = int(p["sample_history_depth"])
        self._auto_calibrate_samples = int(p["auto_calibrate_samples"])
        self._auto_calibrate_done = False
        self._capture_timeout_s = float(p["capture_timeout_s"])
        self._flush_period_s = float(p["flush_period_s"])
        self._captured = threading.Event()
        self._captured_text = ""
        self._session_lock = threading.Lock()
        self._to_check: PendingSample | None = None

        self._session_pub = self.create_publisher(String, SESSION_TOPIC, latched_qos(1))
        self._offset_pub = self.create_publisher(
            Float64MultiArray, CLOCK_OFFSET_TOPIC, latched_qos(1)
        )
        self._profile_pub = self.create_publisher(
            PointCloud2, SAMPLE_PROFILE_TOPIC, latched_qos(self._history_depth)
        )
        self._pose_pub = self.create_publisher(
            PoseStamped, SAMPLE_POSE_TOPIC, latched_qos(self._history_depth)
        )
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        qos = input_qos(bool(p["reliable_inputs"]))
        pose_qos = input_qos(bool(p["reliable_inputs"]), POSE_INPUT_DEPTH)
        self._invalid_values_m = tuple(p["invalid_values_m"] or ())
        self._base_frame = str(p["base_frame"])
        self._base_frame_warned = False
        # rclpy hands a two-argument callback the message info too (its stubs say one).
        self._profile_sub = self.create_subscription(
            PointCloud2,
            "profile",
            self._on_profile,  # type: ignore[arg-type]
            qos,
        )
        self._pose_input: TfPoseInput | JointStatePoseInput | None = None
        if pose_source is PoseSource.TF:
            self._pose_input = TfPoseInput(
                self,
                self._base_frame,
                str(p["flange_frame"]),
                pairing.sync_tolerance_s,
                config.pose_window_s,
                pose_qos,
                self._add_pose,
                self._reject_pose,
            )
            self._collector.explain_no_pose = self._pose_input.why_no_pose
        elif robot is not None:
            self._pose_input = JointStatePoseInput(
                self,
                robot,
                pose_qos,
                self._add_pose,
                self._reject_pose,
            )
        self._pose_sub = self.create_subscription(
            PoseStamped,
            "flange_pose",
            self._on_pose,  # type: ignore[arg-type]
            pose_qos,
        )
        # Its own group: while a capture waits, the default group (inputs, timers) runs on.
        self.create_service(
            Trigger, "~/capture", self._on_capture, callback_group=ReentrantCallbackGroup()
        )
        self.create_service(Trigger, "~/clear", self._on_clear)
        self._calibrate_client = self.create_client(Trigger, CALIBRATE_SERVICE)
        self.create_timer(p["diagnostics_period_s"], self._on_timer)

        self._publish_offset(None)
        self._session_root = Path(p["session_dir"]).expanduser()
        reload_from = self._reload_source(str(p["reload_session"]))
        self._session = self._open_session(reload_from)
        self._work = threading.Event()
        self._stored = threading.Event()
        self._stopping = threading.Event()
        self._threads = [
            threading.Thread(target=self._store_loop, name="storage"),
            threading.Thread(target=self._validate_loop, name="validation"),
        ]
        for thread in self._threads:
            thread.start()
        self.get_logger().info(
            f"collecting in {config.mode.value} mode (target {self._pipeline.target}) "
            f"from {self._profile_sub.topic_name} and {self._pose_sub.topic_name} into "
            f"{self._session.path}"
        )

    # -- sessions ------------------------------------------------------------------------

    def _reload_source(self, value: str) -> Path | None:
        if not value:
            return None
        if value == "latest":
            return find_latest_session(self._session_root)
        return Path(value).expanduser()

    def _open_session(self, reload_from: Path | None) -> SessionBagWriter:
        """Create a new session directory, optionally seeded with an old session's samples."""
        pairs = session_samples(reload_from) if reload_from is not None else []
        writer = SessionBagWriter(
            new_session_path(self._session_root, datetime.datetime.now()),
            profile_topic=self._profile_sub.topic_name,
            pose_topic=self._pose_sub.topic_name,
            organised=False,
        )
        self._session_pub.publish(String(data=str(writer.path)))
        for profile, pose, joints in pairs:
            writer.append(profile, pose, joints)
        writer.flush()
        for profile, pose, _ in pairs:
            self._publish_sample(profile, pose)
        with self._collector.lock:
            self._collector.clear(reloaded=len(pairs))
        if reload_from is not None:
            self.get_logger().info(
                f"reloaded {len(pairs)} samples from {reload_from} into {writer.path}"
            )
        return writer

    def _on_clear(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        with self._session_lock:
            old = self._session
            try:
                old.close()
            except BagError as err:
                self.get_logger().error(render(str(err), Front.NODE))
            for publisher in (self._profile_pub, self._pose_pub):
                self.destroy_publisher(publisher)
            self._profile_pub = self.create_publisher(
                PointCloud2, SAMPLE_PROFILE_TOPIC, latched_qos(self._history_depth)
            )
            self._pose_pub = self.create_publisher(
                PoseStamped, SAMPLE_POSE_TOPIC, latched_qos(self._history_depth)
            )
            try:
                self._session = self._open_session(None)
            except CalibrationError as err:
                response.success = False
                response.message = f"cannot start a new session: {err}"
                return response
            self._auto_calibrate_done = False
        response.success = True
        response.message = (
            f"new session {self._session.path}; the previous session {old.path} "
            f"({old.count} samples) is kept on disk"
        )
        self.get_logger().info(response.message)
        return response

    # -- reception -----------------------------------------------------------------------

    def _on_profile(self, msg: PointCloud2, info: dict[str, Any]) -> None:
        now = time.monotonic()
        sequence = info.get("publication_sequence_number")
        try:
            profile = profile_from_pointcloud2(msg, invalid_values_m=self._invalid_values_m)
        except MessageError as err:
            with self._collector.lock:
                self._collector.reject_profile(render(str(err), Front.NODE), sequence)
            return
        with self._collector.lock:
            self._collector.add_profile(profile, now, sequence)
            work = self._collector.has_work
        if work:
            self._work.set()

    def _on_pose(self, msg: PoseStamped, info: dict[str, Any]) -> None:
        if not self._poses_from_pose_stamped:  # the poses come from /tf or joint states
            return
        try:
            pose = flange_pose_from_pose_stamped(msg)
        except MessageError as err:
            self._reject_pose(render(str(err), Front.NODE))
            return
        warning = base_frame_warning(pose.frame_id, self._base_frame)
        if warning is not None and not self._base_frame_warned:
            self._base_frame_warned = True
            self.get_logger().warning(warning)
        self._add_pose(pose, info.get("publication_sequence_number"))

    def _reject_pose(self, reason: str) -> None:
        with self._collector.lock:
            self._collector.reject_pose(reason)

    def _add_pose(self, pose: FlangePose, sequence: int | None = None) -> None:
        now = time.monotonic()
        with self._collector.lock:
            self._collector.add_pose(pose, now, sequence)
            if self._offsets is not None:
                self._offsets.add_pose(pose)
            work = self._collector.has_work
        if work:
            self._work.set()

    def _log_new_reason(self, key: str, message: str) -> None:
        self.get_logger().warning(f"{message} [first of its kind; counted in /diagnostics]")

    # -- storage -------------------------------------------------------------------------

    def _store_loop(self) -> None:
        """The storage thread: store, flush and publish the accepted samples every period."""
        while True:
            stopping = self._stopping.wait(self._flush_period_s)
            # Under the session lock, so that a sample accepted before ~/clear is never
            # stored in the new session (clear counts it as skipped instead).
            with self._session_lock:
                with self._collector.lock:
                    batch = self._collector.take_to_store()
                    captured, self._collector.captured = self._collector.captured, None
                if batch:
                    self._store(batch, captured)
            if stopping:
                return

    def _store(self, batch: list[PendingSample], captured: int | None) -> None:
        """Persist samples (flushed to disk), then publish them; the session lock is held."""
        samples = []
        joints = []
        offset_ns = round(self._pipeline.pairing.clock_offset_s * 1e9)
        for pending in batch:
            sample = pending.sample
            profile = Profile(sample.stamp_ns, sample.points, pending.sensor_frame)
            pose = FlangePose(sample.stamp_ns, sample.T_base_flange, pending.base_frame)
            samples.append((profile, pose, pending))
            joints.append(
                self._pose_input.joints_at(sample.stamp_ns + offset_ns)
                if isinstance(self._pose_input, JointStatePoseInput)
                else None
            )
        try:
            numbers = [
                self._session.append(profile, pose, q)
                for (profile, pose, _), q in zip(samples, joints, strict=True)
            ]
            self._session.flush()
        except BagError as err:
            self.get_logger().error(render(str(err), Front.NODE))
            with self._collector.lock:
                for _ in samples:
                    self._collector.revoke("session", render(str(err), Front.NODE))
            return
        for profile, pose, _ in samples:
            if not self.context.ok():
                break  # shutting down: the samples are on disk, and reloadable from there
            self._publish_sample(profile, pose)
        with self._collector.lock:
            if self._offsets is not None:
                for profile, _, _ in samples:
                    self._offsets.add_sample(profile)
            if self._collector.config.mode is Mode.CONTINUOUS:
                self._to_check = samples[-1][2]
                self._work.set()
        for number, (_, _, pending) in zip(numbers, samples, strict=True):
            if pending.sample.index == captured:
                self._captured_text = (
                    f"captured sample {number} of session {self._session.path.name} "
                    f"(stamp {pending.sample.stamp_ns} ns)"
                )
                self._captured.set()
                executor = self.executor
                if executor is not None:
                    executor.wake()

    def _publish_sample(self, profile: Profile, pose: FlangePose) -> None:
        """Publish one sample on the two sample topics, both stamped with the profile stamp."""
        self._pose_pub.publish(
            pose_stamped_from_flange_pose(
                FlangePose(profile.stamp_ns, pose.T_base_flange, pose.frame_id), types=self._types
            )
        )
        self._profile_pub.publish(
            pointcloud2_from_points(
                profile.points,
                profile.stamp_ns,
                profile.frame_id,
                types=self._types,
                organised=False,
            )
        )

    # -- validation, live checks and the clock offset ------------------------------------

    def _validate_loop(self) -> None:
        """The validation thread: candidates, live checks and clock offset batches."""
        next_check = 0.0
        while not self._stopping.is_set():
            self._work.wait(0.5)
            self._work.clear()
            while not self._stopping.is_set():
                with self._collector.lock:
                    pending = self._collector.next_to_validate()
                    check, self._to_check = self._to_check, None
                    batch = None if self._offsets is None else self._offsets.take_batch()
                if pending is not None:
                    rejection = validate_sample(pending.sample, self._pipeline)
                    with self._collector.lock:
                        if rejection is None:
                            self._collector.admit(pending)
                        else:
                            self._collector.reject_validated(rejection)
                elif batch is not None:
                    self._estimate_offset(*batch)
                elif check is not None and time.monotonic() >= next_check:
                    next_check = time.monotonic() + LIVE_CHECK_PERIOD_S
                    rejection = validate_sample(check.sample, self._pipeline)
                    with self._collector.lock:
                        self._collector.note_check(rejection)
                else:
                    break

    def _estimate_offset(self, profiles: list[Profile], poses: list[FlangePose]) -> None:
        """Estimate the clock offset from one batch; publish it, warn when it drifts."""
        assert self._offsets is not None
        outcome = self._offsets.estimate_batch(profiles, poses)
        with self._collector.lock:
            warning = self._offsets.add_estimate(outcome)
            estimate = self._offsets.estimate
        if isinstance(outcome, str):
            self.get_logger().warning(
                f"no clock offset estimate from {len(profiles)} samples: {outcome}",
                throttle_duration_sec=60.0,
            )
        if warning is not None:
            self.get_logger().warning(warning)
        self._publish_offset(estimate)

    def _publish_offset(self, estimate: OffsetEstimate | None) -> None:
        """Publish the pairing's clock offset, the live estimate and the rest of the pairing
        (see CLOCK_OFFSET_TOPIC)."""
        data = offset_message(self._pipeline.pairing, estimate)
        self._offset_pub.publish(Float64MultiArray(data=data))

    # -- capture -------------------------------------------------------------------------

    async def _on_capture(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        """Wait for the next sample without blocking the executor."""
        with self._collector.lock:
            if self._collector.capture_pending:
                response.success = False
                response.message = "a capture is already pending; wait for its answer"
                return response
            self._captured.clear()
            self._collector.arm_capture()
        deadline = time.monotonic() + self._capture_timeout_s
        alarm = self.create_timer(self._capture_timeout_s, lambda: None)
        try:
            while not self._captured.is_set() and time.monotonic() < deadline:
                await _NextWake()
        finally:
            self.destroy_timer(alarm)
        if self._captured.is_set():
            response.success = True
            response.message = self._captured_text
            return response
        with self._collector.lock:
            self._collector.cancel_capture()
            last = self._collector.last_rejection or "none (are profiles and poses arriving?)"
        response.success = False
        response.message = (
            f"no valid sample within {self._capture_timeout_s:g} s; last rejection: {last}"
        )
        return response

    # -- periodic: late pairing, diagnostics, auto-calibration ---------------------------

    def _on_timer(self) -> None:
        with self._collector.lock:
            self._collector.release(time.monotonic())
            work = self._collector.has_work
            values = self._collector.diagnostic_values()
            nothing = self._collector.nothing_accepted()
            last = nothing or self._collector.last_rejection
            session_samples = self._collector.session_samples
            received = self._collector.received
            offset = None if self._offsets is None else self._offsets.estimate
            offset_failure = "" if self._offsets is None else self._offsets.last_failure
        if work:
            self._work.set()
        values[KEY_STORED] = str(self._session.durable)
        if nothing is not None:
            values[KEY_NOTHING_ACCEPTED] = nothing
        level = DiagnosticStatus.OK
        if offset is not None:
            values.update(offset_values(offset))
            if self._offsets is not None and self._offsets.drifting:
                level = DiagnosticStatus.WARN
        elif offset_failure:
            values["clock offset"] = f"no estimate yet: {offset_failure}"
        self._publish_diagnostics(values, received, session_samples, last, level)
        if (
            self._auto_calibrate_samples
            and not self._auto_calibrate_done
            and session_samples >= self._auto_calibrate_samples
            and self._calibrate_client.service_is_ready()
        ):
            self._auto_calibrate_done = True
            self.get_logger().info(
                f"the session holds {session_samples} samples: calling "
                f"{self._calibrate_client.service_name}"
            )
            future = self._calibrate_client.call_async(Trigger.Request())
            future.add_done_callback(self._on_calibrated)

    def _on_calibrated(self, future: Future) -> None:
        result = future.result()
        if result is None:
            self.get_logger().error(f"{self._calibrate_client.service_name} call failed")
        elif result.success:
            self.get_logger().info(f"calibrated: {result.message}")
        else:
            self.get_logger().warning(f"calibration failed: {result.message}")

    def _publish_diagnostics(
        self, values: dict[str, str], received: int, session_samples: int, last: str, level: int
    ) -> None:
        if received and not session_samples:
            level = DiagnosticStatus.WARN
            message = f"no sample accepted yet: {last or 'none rejected'}"
        else:
            message = f"{session_samples} samples in session {self._session.path}"
        status = DiagnosticStatus(
            level=level,
            name=f"{self.get_name()}: {COLLECTION_STATUS}",
            message=message,
            hardware_id=self._profile_sub.topic_name,
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics_pub.publish(array)

    def destroy_node(self) -> None:
        """Stop the threads, store what is accepted, close the session, destroy the node."""
        self._stopping.set()
        self._work.set()
        for thread in self._threads:
            thread.join()
        try:
            self._session.close()
        except BagError as err:
            self.get_logger().error(render(str(err), Front.NODE))
        super().destroy_node()


class _NextWake:
    """Awaitable that hands control back to the executor until its next wake-up."""

    def __await__(self) -> Generator[None, None, None]:
        yield


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run linelaser_calib collector``."""
    return run_node(CollectorNode, SingleThreadedExecutor, args)


if __name__ == "__main__":
    raise SystemExit(main())
