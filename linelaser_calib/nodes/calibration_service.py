# mypy: disallow-untyped-calls=False
# rclpy is only partly annotated: calling its untyped functions is expected here.
"""ROS 2 node ``calibration_service``: accumulate the collector's samples, calibrate on request.

- Subscribes ``linelaser_calib/samples/profile`` and ``linelaser_calib/samples/flange_pose``
  (reliable, transient_local, ``max_samples`` deep: a late or restarted service receives the
  whole session again) and joins them by exact stamp in a bounded
  :class:`~linelaser_calib.nodes.sample_store.SampleStore`. A new collector session
  (``linelaser_calib/session``) drops the samples of the previous one.
- ``calibrate`` (std_srvs/Trigger) runs the one pipeline as offline
  (:func:`~linelaser_calib.nodes.live_calibration.calibrate_live`: the collector's pairing,
  the near-duplicate rule ``per_neighbourhood``, the test of a clock offset left out) in
  its own callback group on a MultiThreadedExecutor, so samples keep arriving during a
  solve. The pipeline configuration is built from the parameters at each call
  (:func:`~linelaser_calib.nodes.live_calibration.pipeline_config`): ``target`` (a
  registered target: cylinder, known_point, ...), ``method``, the target's settings
  (``radius``, ``known_point``, ``min_samples``; one that does not act on the target and
  method is refused), and an optional initial hand-eye read from
  ``initial_hand_eye_path``. A second call during a solve, no samples, too few or
  degenerate samples, data the target's model does not fit, or an unusable initial hand-eye
  file answer ``success: false`` with the reason; the node keeps running.
- On success it answers a one-line summary, publishes ``linelaser_calib/hand_eye``
  (TransformStamped ``flange_frame`` -> ``sensor_frame``, transient_local) and
  ``linelaser_calib/markers`` (in ``base_frame``: the profiles mapped through the result and
  the target's shapes, e.g. the fitted cylinder or the known point), puts the collector's
  clock offset and live estimate (``linelaser_calib/clock_offset``) in the result, publishes
  the hand-eye on ``/tf_static`` as tf2_ros's static broadcaster does (its own ``TFMessage``
  publisher, :mod:`~linelaser_calib.nodes.tf_output`; no tf2_ros needed), warning when
  another ``/tf_static`` publisher already gives the sensor frame a parent, and writes the
  result YAML to
  ``output_path`` atomically. A failed calibration leaves the last good file.
- With ``kinematics`` set (a robot model: ur5e, ur10e, a URDF), ``calibrate`` runs the joint
  kinematic + hand-eye calibration instead
  (:func:`~linelaser_calib.nodes.live_calibration.calibrate_session`): the offline path on
  the collector's session bag, whose samples carry the joint vectors the collector stored
  (pose_source joint_states). The answer says how many kinematic corrections were estimated;
  the result YAML has its ``kinematics`` section. A session without joint states is refused.
  ``~/plan`` then also says whether another placement of the cylinder would determine more
  of the kinematics, and how to move it
  (:func:`~linelaser_calib.nodes.live_calibration.session_placement_advice`).
- ``~/plan`` (std_srvs/Trigger) plans the next ``plan_poses`` flange poses that most reduce
  the hand-eye's predicted uncertainty (:func:`~linelaser_calib.core.planning.plan_for_target`),
  from the last calibration (or, before one, from ``initial_hand_eye_path`` with the samples
  held as exploratory scans), and publishes them on ``linelaser_calib/planned_poses``
  (PoseArray in ``base_frame``, transient_local), the laser fan at each of them on
  ``linelaser_calib/planned_fans`` (MarkerArray) and the predicted 1σ after them in
  /diagnostics. The user's motion stack drives the robot through them.
"""

from __future__ import annotations

import threading
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseArray, PoseStamped, TransformStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Float64MultiArray, String
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.core.pipeline import Method, PipelineConfig
from linelaser_calib.core.planning import Plan, PlanConstraints, fan_shape, plan_for_target
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.selfcheck import DEFAULT_ARM_ACCURACY_M
from linelaser_calib.core.targets import DEFAULT_TARGET
from linelaser_calib.core.thinning import DEFAULT_PER_NEIGHBOURHOOD
from linelaser_calib.io import write_result_yaml
from linelaser_calib.nodes.collection import COLLECTION_STATUS, KEY_NOTHING_ACCEPTED
from linelaser_calib.nodes.common import (
    CALIBRATE_SERVICE,
    CLOCK_OFFSET_TOPIC,
    HAND_EYE_TOPIC,
    MARKERS_TOPIC,
    SAMPLE_POSE_TOPIC,
    SAMPLE_PROFILE_TOPIC,
    SESSION_TOPIC,
    ParamSpec,
    declare_parameters,
    latched_qos,
    parameter_values,
    run_node,
)
from linelaser_calib.nodes.live_calibration import (
    add_live_clock_offset,
    calibrate_live,
    calibrate_session,
    pipeline_config,
    session_placement_advice,
)
from linelaser_calib.nodes.sample_store import SampleStore, points_in_base
from linelaser_calib.nodes.tf_output import static_tf_publisher
from linelaser_calib.settings import Front, render, render_warnings
from linelaser_calib.summary import one_line_summary, self_check_rows
from msg_adapters import (
    MessageError,
    flange_pose_from_pose_stamped,
    marker_array,
    points_marker,
    pose_array_from_transforms,
    profile_from_pointcloud2,
    rclpy_types,
    shape_markers,
    transform_stamped_from_matrix,
)

NODE_NAME = "calibration_service"
#: Diagnostic value: complete samples held.
KEY_SAMPLES = "samples"
#: The planning service (relative to the node: ``/calibration_service/plan``) and its topics.
PLAN_SERVICE = "~/plan"
PLANNED_POSES_TOPIC = "linelaser_calib/planned_poses"
PLANNED_FANS_TOPIC = "linelaser_calib/planned_fans"
#: Most profile points drawn in the markers (evenly subsampled over the used samples).
MAX_MARKER_POINTS = 5000
#: Every parameter; all but the read-only ones are read at each calibration, so
#: ``ros2 param set`` applies to the next one. config/calibration_service.yaml repeats the defaults.
PARAMETERS = (
    ParamSpec(
        "target",
        DEFAULT_TARGET,
        "What was scanned: a registered target's name (cylinder, known_point, ...; "
        "`linelaser-calib calibrate --help` lists them). An unknown name fails the calibration "
        "with the list.",
    ),
    ParamSpec(
        "radius",
        0.0,
        "Cylinder radius, m (half the diameter); 0 estimates it from the profiles (cylinder "
        "target; refused by the others).",
        bounds=(0.0, 1.0),
    ),
    ParamSpec(
        "scale",
        "",
        "The profiler's along-line (x) scale, and for the line target and a cylinder of given "
        "radius its depth (z) scale too (cylinder, sphere and line targets, default method): "
        "free estimates them with the hand-eye, fixed holds them at 1, auto (or '') is free "
        "for the cylinder and the line where clearly off 1 and fixed for the sphere (whose "
        "1 sigma then counts the hand-eye's move with the scale estimated, where beyond it); "
        "the result's along_line_scale, depth_scale and their 1 sigma. Refused by the known "
        "point (which always treats its x and z scales as auto) and the paper method.",
        choices=("", "auto", "fixed", "free"),
    ),
    ParamSpec(
        "known_point",
        (),
        "The fixed point [x, y, z], m, in base_frame, e.g. taught with the tool tip "
        "(known_point target); [] estimates it. method paper needs it.",
        sizes=(0, 3),
    ),
    ParamSpec(
        "initial_hand_eye_path",
        "",
        "Initial (old) hand-eye: a result YAML (e.g. an earlier result) or a YAML with a "
        "hand_eye section, or the numbers 'x y z qx qy qz qw' or 'x y z roll pitch yaw' (m, "
        "rad); '' for none. The default method starts from it; the paper method with target "
        "known_point corrects it and needs it.",
    ),
    ParamSpec(
        "output_path",
        "~/.ros/linelaser_calib/hand_eye.yaml",
        "Result YAML, replaced atomically after each successful calibration.",
    ),
    ParamSpec(
        "method",
        PipelineConfig.method.value,
        "default: the paper's solve refined by maximum likelihood with covariance; paper: "
        "the method of the target's paper as published.",
        choices=tuple(m.value for m in Method),
    ),
    ParamSpec(
        "min_samples",
        0,
        "Fewest samples with a usable feature (ellipse, corner, ...) that a calibration "
        "accepts; 0 takes the target's default.",
        bounds=(0, 100000),
    ),
    ParamSpec(
        "max_samples",
        1000,
        "Most samples kept (later ones are ignored, with one warning); also the depth of "
        "the sample subscriptions.",
        bounds=(1, 100000),
        read_only=True,
    ),
    ParamSpec(
        "seed",
        PipelineConfig.seed,
        "Seed of the random stages (RANSAC, PSO): equal inputs give equal results.",
        bounds=(0, 2**31 - 1),
    ),
    ParamSpec(
        "arm_accuracy",
        DEFAULT_ARM_ACCURACY_M,
        "Prior 1 sigma per axis, m, of the robot's error common to the whole scanned "
        "workspace (its absolute accuracy there), which no subset of the poses can see: part "
        "of the hand-eye's 1 sigma when the robot's error looks systematic (default method; "
        "not used with kinematics, whose joint calibration estimates that error).",
        bounds=(0.0, 1.0),
    ),
    ParamSpec(
        "per_neighbourhood",
        DEFAULT_PER_NEIGHBOURHOOD,
        "Most samples kept from one neighbourhood of flange poses (50 mm x 8 deg), evenly "
        "spaced in time, where a long session holds more from nearly the same pose (the "
        "result's quality.thinning); 0 keeps every sample.",
        bounds=(0, 100000),
    ),
    ParamSpec(
        "diagnostics_period_s",
        1.0,
        "Period of the /diagnostics status (samples held), s.",
        bounds=(0.01, 60.0),
        read_only=True,
    ),
    ParamSpec(
        "plan_poses",
        10,
        "Flange poses ~/plan proposes.",
        bounds=(1, 1000),
    ),
    ParamSpec(
        "plan_axial_range",
        (),
        "Span of the cylinder ~/plan may scan, [lo, hi] in m along the axis (upwards) from "
        "its point nearest the base origin; [] takes the span the samples cover.",
        sizes=(0, 2),
    ),
    ParamSpec(
        "plan_measuring_range",
        (PlanConstraints.z_min_m, PlanConstraints.z_max_m),
        "The profiler's measuring range [near, far] along its z axis, m (for ~/plan).",
        sizes=(2,),
    ),
    ParamSpec(
        "plan_fan_half_angle",
        PlanConstraints.fan_half_angle_rad,
        "Half opening of the laser fan, rad (for ~/plan).",
        bounds=(0.01, 1.5),
    ),
    ParamSpec(
        "plan_reach_half_extent",
        PlanConstraints.reach_half_extent_m,
        "Half side of the box around the first sample's flange position that planned flange "
        "poses stay in, m.",
        bounds=(0.01, 5.0),
    ),
    ParamSpec(
        "plan_table_height",
        0.0,
        "Height (base z) of the table under the target, m: planned sensor and flange poses "
        "stay above it and the laser never points up.",
        bounds=(-5.0, 5.0),
    ),
    ParamSpec(
        "kinematics",
        "",
        "The robot's kinematic model for a joint kinematic + hand-eye calibration: a preset "
        "(ur5e, ur10e), a URDF file or the URDF text; '' for none. When set, calibrate "
        "reads the collector's session (which holds the joint states with pose_source "
        "joint_states) and estimates the identifiable kinematic corrections with the hand-eye "
        "(the result's kinematics section).",
    ),
    ParamSpec("base_frame", "base_link", "Robot base frame: frame of the cylinder and markers."),
    ParamSpec("flange_frame", "tool0", "Flange frame: parent frame of the hand-eye."),
    ParamSpec("sensor_frame", "laser", "Sensor frame: child frame of the hand-eye."),
)


def kinematics_summary(result: CalibrationResult) -> str:
    """What a joint calibration estimated, in one clause ('' without one)."""
    corrections = result.kinematics
    if corrections is None:
        return ""
    return (
        f"; kinematic corrections of the {corrections.model} model: "
        f"{len(corrections.corrections)} estimated, {len(corrections.kept_nominal)} kept "
        "nominal (not determined by these scans)"
    )


def second_parent_warning(parents: dict[str, str], child: str, parent: str) -> str | None:
    """A warning when ``child`` already has a parent other than ``parent`` in /tf_static.

    Parameters
    ----------
    parents : dict
        Parent of each frame as the other /tf_static publishers give it.
    child, parent : str
        The hand-eye about to be broadcast: sensor frame and flange frame.
    """
    known = parents.get(child)
    if known is None or known == parent:
        return None
    return (
        f"the sensor frame {child} already has parent {known} on /tf_static (e.g. a joint of the "
        f"URDF); broadcasting {parent} -> {child} gives it two parents, which breaks the TF "
        f"tree. Remove the other transform (replace the URDF joint with `linelaser-calib "
        f"export RESULT.yaml --format urdf`), or give the sensor another frame name "
        f"(sensor_frame)"
    )


class CalibrationServiceNode(Node):
    """The ``calibration_service`` node; see the module docstring. ``kwargs`` go to ``Node``."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        p = declare_parameters(self, PARAMETERS)
        self._types = rclpy_types()
        self._store = SampleStore(int(p["max_samples"]))
        self._busy = threading.Lock()

        receive = MutuallyExclusiveCallbackGroup()
        depth = int(p["max_samples"])
        self._profile_sub = self.create_subscription(
            PointCloud2,
            SAMPLE_PROFILE_TOPIC,
            self._on_profile,
            latched_qos(depth),
            callback_group=receive,
        )
        self._pose_sub = self.create_subscription(
            PoseStamped,
            SAMPLE_POSE_TOPIC,
            self._on_pose,
            latched_qos(depth),
            callback_group=receive,
        )
        self.create_subscription(
            String, SESSION_TOPIC, self._on_session, latched_qos(1), callback_group=receive
        )
        self._clock_offset: list[float] = []
        self._self_check: list[tuple[str, str]] = []
        self.create_subscription(
            Float64MultiArray,
            CLOCK_OFFSET_TOPIC,
            self._on_clock_offset,
            latched_qos(1),
            callback_group=receive,
        )
        self._hand_eye_pub = self.create_publisher(TransformStamped, HAND_EYE_TOPIC, latched_qos(1))
        self._markers_pub = self.create_publisher(MarkerArray, MARKERS_TOPIC, latched_qos(1))
        self._tf_static = static_tf_publisher(self)
        if self._tf_static is None:
            self.get_logger().warning(
                "tf2_msgs is missing (no ROS install sourced, and not built by make venv): the "
                "hand-eye is published on linelaser_calib/hand_eye but not on /tf_static"
            )
        #: The collector's latest word on a session without samples (its /diagnostics).
        self._collector_status = ""
        self.create_subscription(
            DiagnosticArray, "/diagnostics", self._on_diagnostics, 10, callback_group=receive
        )
        self._diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(
            p["diagnostics_period_s"], self._publish_diagnostics, callback_group=receive
        )
        self._service = self.create_service(
            Trigger, CALIBRATE_SERVICE, self._on_calibrate, callback_group=ReentrantCallbackGroup()
        )
        self._last_result: CalibrationResult | None = None
        self._plan: Plan | None = None
        self._planned_pub = self.create_publisher(PoseArray, PLANNED_POSES_TOPIC, latched_qos(1))
        self._fans_pub = self.create_publisher(MarkerArray, PLANNED_FANS_TOPIC, latched_qos(1))
        self._plan_service = self.create_service(
            Trigger, PLAN_SERVICE, self._on_plan, callback_group=ReentrantCallbackGroup()
        )
        self.get_logger().info(
            f"collecting samples from {self._profile_sub.topic_name} and "
            f"{self._pose_sub.topic_name}; call {self._service.service_name} to calibrate"
        )

    @property
    def sample_count(self) -> int:
        """Complete samples held (profile and flange pose of equal stamp)."""
        return len(self._store)

    # -- samples -------------------------------------------------------------------------

    def _on_profile(self, msg: PointCloud2) -> None:
        try:
            profile = profile_from_pointcloud2(msg)
        except MessageError as err:
            self._bad_sample(err)
            return
        points = np.asarray(profile.points, dtype=np.float64)
        self._warn(self._store.add_profile(profile.stamp_ns, points, profile.frame_id))

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            pose = flange_pose_from_pose_stamped(msg)
        except MessageError as err:
            self._bad_sample(err)
            return
        self._warn(self._store.add_pose(pose.stamp_ns, pose.T_base_flange, pose.frame_id))

    def _bad_sample(self, err: MessageError) -> None:
        self.get_logger().warning(f"sample message ignored: {err}", throttle_duration_sec=10.0)

    def _warn(self, warning: str | None) -> None:
        if warning is not None:
            self.get_logger().warning(warning)

    def _on_session(self, msg: String) -> None:
        dropped = self._store.set_session(msg.data)
        if dropped:
            self.get_logger().info(
                f"the collector started session {msg.data}: dropped the {dropped} samples of "
                "the previous session"
            )

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        """Keep the collector's word on why it accepted no profile (cleared once it has)."""
        for status in msg.status:
            node, _, what = status.name.partition(": ")
            if what == COLLECTION_STATUS:
                why = {kv.key: kv.value for kv in status.values}.get(KEY_NOTHING_ACCEPTED)
                self._collector_status = "" if why is None else f"the {node} {why}"

    def _on_clock_offset(self, msg: Float64MultiArray) -> None:
        self._clock_offset = list(msg.data)

    def _publish_diagnostics(self) -> None:
        store = self._store
        values = {
            KEY_SAMPLES: len(store),
            "samples repeated (ignored)": store.repeated,
            "samples beyond max_samples (ignored)": store.ignored_full,
            "unmatched halves dropped": store.dropped_unmatched,
        }
        full = store.ignored_full > 0
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if full else DiagnosticStatus.OK,
            name=f"{self.get_name()}: samples",
            message=(
                f"{len(store)} samples held"
                + (f"; max_samples ({store.max_samples}) reached" if full else "")
            ),
            hardware_id="",
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]
            + [KeyValue(key="session", value=store.session or "")]
            + [KeyValue(key=k, value=v) for k, v in self._self_check]
            + self._plan_diagnostics(),
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics_pub.publish(array)

    def _plan_diagnostics(self) -> list[KeyValue]:
        """The last plan's size and predicted 1σ after it (mm, deg)."""
        plan = self._plan
        if plan is None or not plan.poses:
            return []
        last = plan.poses[-1]
        return [
            KeyValue(key="planned poses", value=str(len(plan.poses))),
            KeyValue(
                key="predicted 1 sigma translation after the plan (mm)",
                value=" ".join(f"{v * 1e3:.4f}" for v in last.sigma_translation_m),
            ),
            KeyValue(
                key="predicted 1 sigma rotation after the plan (deg)",
                value=" ".join(f"{np.rad2deg(v):.4f}" for v in last.sigma_rotation_rad),
            ),
        ]

    # -- calibration ---------------------------------------------------------------------

    def _on_calibrate(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        return self._run("calibration", "calibrated", self._calibrate, response)

    def _on_plan(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        return self._run("planning", "planned", self._plan_poses, response)

    def _run(self, what: str, done: str, work: Any, response: Trigger.Response) -> Trigger.Response:
        """Answer a Trigger call with ``work()`` (one at a time; a bug is logged, not fatal)."""
        if not self._busy.acquire(blocking=False):
            response.success = False
            response.message = (
                "a calibration or planning is already running; call again when it has finished"
            )
            return response
        try:
            response.success, message = work()
            response.message = render(message, Front.NODE)
        # The service must outlive a bug in the pipeline: log it in full and say so.
        except Exception as err:
            self.get_logger().error(f"{what} crashed (a bug):\n{traceback.format_exc()}")
            response.success = False
            response.message = (
                f"internal error, please report it (traceback in the node log): "
                f"{type(err).__name__}: {err}"
            )
        finally:
            self._busy.release()
        if response.success:  # (rclpy wants one severity per logging call site)
            self.get_logger().info(f"{done}: {response.message}")
        else:
            self.get_logger().warning(f"{what} failed: {response.message}")
        return response

    def _calibrate(self) -> tuple[bool, str]:
        """Calibrate from the stored samples; (success, one-line message)."""
        p = parameter_values(self, PARAMETERS)
        samples = self._store.samples()
        if not samples:
            if self._collector_status:
                return False, f"no samples yet: {self._collector_status}"
            return False, (
                f"no samples yet: none received on {self._profile_sub.topic_name} and "
                f"{self._pose_sub.topic_name}; run the collector and scan the "
                + p["target"].replace("_", " ")
            )
        self.get_logger().info(
            f"calibrating from {len(samples)} samples (target {p['target']}, method {p['method']})"
        )
        start = time.monotonic()
        live = list(self._clock_offset)
        try:
            if p["kinematics"]:
                result = calibrate_session(self._store.session, p, self._warn)
            else:
                result = calibrate_live(samples, live, p, self._warn)
        except CalibrationError as err:
            return False, str(err)
        result.parent_frame = p["flange_frame"]
        result.child_frame = p["sensor_frame"]
        result.base_frame = p["base_frame"]
        if len(live) >= 4:
            add_live_clock_offset(result, *live[:3])
        render_warnings(result, Front.NODE)
        summary = one_line_summary(result, len(samples)) + kinematics_summary(result)
        self._self_check = self_check_rows(result, Front.NODE)
        self._last_result = result
        self.get_logger().info(f"solved in {time.monotonic() - start:.1f} s")
        self._publish(result)
        output = Path(p["output_path"]).expanduser()
        try:
            write_result_yaml(result, output)
        except CalibrationError as err:
            return False, (
                f"calibrated, but the result file was not written ({err}); the result is on "
                f"{self._hand_eye_pub.topic_name}: {summary}"
            )
        return True, f"{summary}; written to {output}"

    def _plan_poses(self) -> tuple[bool, str]:
        """Plan from the last result (or the initial hand-eye and the samples as exploratory
        scans); (success, one-line message)."""
        p = parameter_values(self, PARAMETERS)
        samples = self._store.samples()
        try:
            config = pipeline_config(p)
        except CalibrationError as err:
            return False, str(err)
        result = self._last_result
        if result is not None and result.target.key == config.target:
            T_flange_sensor, section = result.T_flange_sensor, result.target
        elif config.initial_T_flange_sensor is not None:
            T_flange_sensor, section = config.initial_T_flange_sensor, None
        else:
            return False, (
                "planning needs a hand-eye: call calibrate first, or set "
                "initial_hand_eye_path (e.g. from CAD) and scan the target from 3 or more poses"
            )
        near, far = p["plan_measuring_range"]
        constraints = PlanConstraints(
            z_min_m=float(near),
            z_max_m=float(far),
            fan_half_angle_rad=float(p["plan_fan_half_angle"]),
            reach_half_extent_m=float(p["plan_reach_half_extent"]),
            table_height_m=float(p["plan_table_height"]),
        )
        axial = p["plan_axial_range"]
        try:
            plan = plan_for_target(
                config.target_impl,
                config.target_config,
                T_flange_sensor,
                int(p["plan_poses"]),
                samples=samples,
                section=section,
                extent=(float(axial[0]), float(axial[1])) if len(axial) else None,
                constraints=constraints,
                seed=int(p["seed"]),
            )
        except CalibrationError as err:
            return False, str(err)
        self._plan = plan
        stamp_ns = self.get_clock().now().nanoseconds
        T = np.stack([pose.T_base_flange for pose in plan.poses])
        self._planned_pub.publish(
            pose_array_from_transforms(T, p["base_frame"], stamp_ns, types=self._types)
        )
        fans = shape_markers(
            [fan_shape(plan, constraints)], p["base_frame"], types=self._types, stamp_ns=stamp_ns
        )
        self._fans_pub.publish(
            marker_array([Marker(action=Marker.DELETEALL), *fans], types=self._types)
        )
        last = plan.poses[-1]
        advice = ""
        if p["kinematics"]:
            try:
                advice = "; " + session_placement_advice(self._store.session, p, result)
            except CalibrationError as err:
                advice = f"; placements: not judged ({err})"
        return True, (
            f"planned {len(plan.poses)} flange poses on {self._planned_pub.topic_name}; "
            f"predicted 1 sigma after them: translation "
            f"{np.array2string(last.sigma_translation_m * 1e3, precision=4)} mm, rotation "
            f"{np.array2string(np.rad2deg(last.sigma_rotation_rad), precision=4)} deg" + advice
        )

    def _publish(self, result: CalibrationResult) -> None:
        """Publish the hand-eye (topic and /tf_static) and the RViz markers."""
        stamp_ns = self.get_clock().now().nanoseconds
        transform = transform_stamped_from_matrix(
            result.T_flange_sensor,
            stamp_ns,
            result.parent_frame,
            result.child_frame,
            types=self._types,
        )
        self._hand_eye_pub.publish(transform)
        if self._tf_static is not None:
            warning = second_parent_warning(
                self._tf_static.parents, result.child_frame, result.parent_frame
            )
            if warning is not None:
                self.get_logger().warning(warning)
            self._tf_static.send(transform)
        # Clear what an earlier calibration drew (e.g. another target's shapes).
        markers = [Marker(action=Marker.DELETEALL)]
        points = points_in_base(result, MAX_MARKER_POINTS)
        if len(points):
            markers.append(
                points_marker(
                    points,
                    result.base_frame,
                    types=self._types,
                    size_m=0.0005,
                    stamp_ns=stamp_ns,
                    ns="profiles",
                )
            )
        markers += shape_markers(
            result.target.shapes(points), result.base_frame, types=self._types, stamp_ns=stamp_ns
        )
        self._markers_pub.publish(marker_array(markers, types=self._types))


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run linelaser_calib calibration_service``."""
    return run_node(CalibrationServiceNode, MultiThreadedExecutor, args)


if __name__ == "__main__":
    raise SystemExit(main())
