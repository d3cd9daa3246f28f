"""The collector node's parameters: names, defaults, ranges and descriptions.

Every parameter is read at start-up; ``config/collector.yaml`` repeats the defaults and
``docs/reference.md`` shows this table (a test keeps both in step).
"""

from __future__ import annotations

from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.targets import DEFAULT_TARGET
from linelaser_calib.nodes.collection import CollectorConfig, Mode
from linelaser_calib.nodes.common import ParamSpec

_PAIRING = PairingConfig()


_COLLECTOR = CollectorConfig()


#: Every parameter of the collector.
PARAMETERS = (
    ParamSpec(
        "target",
        DEFAULT_TARGET,
        "What the profiles scan, which decides how each is validated (the target's feature "
        "fit): a registered target's name (cylinder, known_point, ...; `linelaser-calib "
        "calibrate --help` lists them).",
        read_only=True,
    ),
    ParamSpec(
        "mode",
        _COLLECTOR.mode.value,
        "stop_and_go: one valid sample per standstill of the flange (move, stop, move: no "
        "trigger needed); continuous: every profile paired with a pose joins the session "
        "(scanning in motion; see max_rate_hz); on_demand: only the next valid one after "
        "each ~/capture call (robot programs that trigger).",
        choices=tuple(m.value for m in Mode),
        read_only=True,
    ),
    ParamSpec(
        "standstill_s",
        _COLLECTOR.standstill_s,
        "stop_and_go: the flange must have been slower than max_linear_speed_m_s and "
        "max_angular_speed_rad_s for this long before a profile is taken, s.",
        bounds=(0.0, 10.0),
        read_only=True,
    ),
    ParamSpec(
        "reliable_inputs",
        False,
        "Subscribe profile and flange_pose (or joint_states, or /tf) with reliable QoS (nothing "
        "lost, needs reliable publishers) instead of best effort (sensor-data QoS, matches any "
        "publisher). /tf_static is always reliable and transient local.",
        read_only=True,
    ),
    ParamSpec(
        "pose_source",
        PoseSource.POSE.value,
        "Where flange poses come from: pose (geometry_msgs/PoseStamped on flange_pose), tf "
        "(the chain base_frame -> flange_frame from /tf and /tf_static; needs tf2_msgs, which "
        "make venv builds where no ROS install provides it) or "
        "joint_states (sensor_msgs/JointState on joint_states through the kinematics model).",
        choices=tuple(s.value for s in PoseSource),
        read_only=True,
    ),
    ParamSpec(
        "base_frame",
        "base_link",
        "Robot base frame: start of the TF chain (pose_source tf) or of a URDF's joint chain "
        "(pose_source joint_states); with PoseStamped poses in UR's 'base' instead, a "
        "warning says what that means.",
        read_only=True,
    ),
    ParamSpec(
        "flange_frame",
        "tool0",
        "Flange frame: end of the TF chain (pose_source tf) or of a URDF's joint chain "
        "(pose_source joint_states).",
        read_only=True,
    ),
    ParamSpec(
        "kinematics",
        "",
        "pose_source joint_states: the robot's kinematic model, a preset (ur5e, ur10e), a "
        "URDF file, or URDF text such as the value of robot_description (its chain "
        "base_frame -> flange_frame). Each sample's joint vector is stored in the session, "
        "for calibration_service's joint kinematic calibration (its kinematics parameter).",
        read_only=True,
    ),
    ParamSpec(
        "invalid_values_m",
        (),
        "Depths z, m, that the profiler sends for no return besides NaN and +-Inf, e.g. "
        "[-0.999999] (Keyence's -999.999 mm) or [0.0].",
        sizes=tuple(range(9)),
        read_only=True,
    ),
    ParamSpec(
        "sync_tolerance_s",
        _PAIRING.sync_tolerance_s,
        "Largest gap between a profile stamp and a flange pose stamp used for it, s.",
        bounds=(1e-4, 1.0),
        read_only=True,
    ),
    ParamSpec(
        "clock_offset_s",
        _PAIRING.clock_offset_s,
        "Added to every profile stamp to put it on the flange pose clock, s.",
        bounds=(-60.0, 60.0),
        read_only=True,
    ),
    ParamSpec(
        "max_linear_speed_m_s",
        _PAIRING.max_linear_speed_m_s,
        "Profiles taken while the flange moved faster are rejected, m/s; 0 disables.",
        bounds=(0.0, 10.0),
        read_only=True,
    ),
    ParamSpec(
        "max_angular_speed_rad_s",
        _PAIRING.max_angular_speed_rad_s,
        "Profiles taken while the flange turned faster are rejected, rad/s; 0 disables.",
        bounds=(0.0, 10.0),
        read_only=True,
    ),
    ParamSpec(
        "speed_window_s",
        _PAIRING.speed_window_s,
        "Half-width of the window over which the flange speed is measured, s.",
        bounds=(0.0, 1.0),
        read_only=True,
    ),
    ParamSpec(
        "pose_window_s",
        _COLLECTOR.pose_window_s,
        "Flange poses kept behind the newest one, s; a profile waits for the poses around its "
        "stamp until the pose stream has been silent this long (wall time).",
        bounds=(0.05, 60.0),
        read_only=True,
    ),
    ParamSpec(
        "max_rate_hz",
        _COLLECTOR.max_rate_hz,
        "continuous: keep at most this many samples per second of profile stamps, skipping "
        "(and counting) the others on purpose, Hz; 0 keeps every paired profile.",
        bounds=(0.0, 100000.0),
        read_only=True,
    ),
    ParamSpec(
        "validation_queue_size",
        _COLLECTOR.validation_queue_size,
        "stop_and_go and on_demand: profiles waiting for validation; more are skipped and counted.",
        bounds=(1, 100000),
        read_only=True,
    ),
    ParamSpec(
        "flush_period_s",
        0.1,
        "The session file is flushed and fsynced this often, s; samples are published once "
        "on disk, and a crash loses at most the samples of the last period.",
        bounds=(0.001, 10.0),
        read_only=True,
    ),
    ParamSpec(
        "clock_offset_period_s",
        10.0,
        "continuous (cylinder target): estimate the profile-to-pose clock offset from the "
        "samples of every period this long, s; 0 disables the live estimate.",
        bounds=(0.0, 3600.0),
        read_only=True,
    ),
    ParamSpec(
        "radius",
        0.0,
        "Cylinder radius, m, checked against each profile's ellipse; 0 accepts any radius "
        "(cylinder target; refused by the others).",
        bounds=(0.0, 1.0),
        read_only=True,
    ),
    ParamSpec(
        "seed",
        0,
        "Seed of the RANSAC fits (ellipse or corner) that validate the profiles.",
        bounds=(0, 2**31 - 1),
        read_only=True,
    ),
    ParamSpec(
        "session_dir",
        "~/.ros/linelaser_calib/sessions",
        "Directory under which each session gets its own directory (session_YYYYmmdd_HHMMSS, "
        "holding session.mcap); sessions are never deleted or overwritten.",
        read_only=True,
    ),
    ParamSpec(
        "reload_session",
        "",
        "Empty: start an empty session. 'latest' or a session directory: start with that "
        "session's samples (copied into the new session and republished).",
        read_only=True,
    ),
    ParamSpec(
        "sample_history_depth",
        1000,
        "Samples kept by the transient_local sample topics for late or restarted "
        "subscribers; make it at least the session size.",
        bounds=(1, 100000),
        read_only=True,
    ),
    ParamSpec(
        "auto_calibrate_samples",
        0,
        "Call the calibrate service once when the session holds this many samples; 0: never.",
        bounds=(0, 100000),
        read_only=True,
    ),
    ParamSpec(
        "capture_timeout_s",
        5.0,
        "How long ~/capture waits for a valid sample, s.",
        bounds=(0.01, 3600.0),
        read_only=True,
    ),
    ParamSpec(
        "diagnostics_period_s",
        1.0,
        "Period of the /diagnostics status (and of the auto-calibrate check), s.",
        bounds=(0.01, 60.0),
        read_only=True,
    ),
)
