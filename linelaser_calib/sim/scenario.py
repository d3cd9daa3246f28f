"""Simulation scenarios: every knob of the simulator in one frozen dataclass, validated.

A :class:`Scenario` holds plain numbers, strings, tuples and the frozen
:class:`~linelaser_calib.sim.sensor_models.SensorModel` record only (no arrays), so that it
can be written to and read from YAML by the I/O layer and compared with ``==``. Lists given for
tuple fields (as YAML readers produce them) are converted to tuples, a mapping given for
``sensor`` to a ``SensorModel``.

Units are SI throughout: metres, radians, seconds, hertz and integer nanoseconds; the unit is
in each field name or its description. Degrees appear only in descriptions, labelled.

The named presets and random scenes are in :mod:`~linelaser_calib.sim.presets`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    check_quaternion_xyzw,
    matrix_from_quaternion_xyzw,
    transform_from_rotation_translation,
)
from linelaser_calib.core.robot.kinematics import UR_DH
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import FloatArray
from linelaser_calib.sim.sensor_models import SensorModel, sensor_model_from_mapping

Vec3 = tuple[float, float, float]


Range = tuple[float, float]


#: Accepted values of :attr:`Scenario.motion`.
MOTIONS = ("step", "continuous")


#: Accepted values of :attr:`Scenario.background`.
BACKGROUNDS = ("none", "table", "plane")


#: Accepted values of :attr:`Scenario.pose_mode`.
POSE_MODES = ("paper", "general")


def _deg(value: float) -> float:
    return math.radians(value)


@dataclass(frozen=True)
class Scenario:
    """Every parameter of one simulated calibration run.

    Scene
    -----
    name : str
        Label for reports (the preset name, or ``custom``).
    cylinder_radius_m : float
        Cylinder radius, m.
    cylinder_length_m : float
        Length of the finite cylinder along its axis, m.
    cylinder_base_m : (3,) floats
        Centre of the cylinder's bottom face in the base frame, m. The cylinder occupies axial
        positions 0 .. ``cylinder_length_m`` from here along ``axis_direction``.
    axis_direction : (3,) floats
        Axis direction in the base frame (normalised on use; any non-zero length).
    background : str
        ``none``; ``table``: an infinite plane through ``cylinder_base_m`` perpendicular to the
        axis, on which the cylinder stands (sensor and flange stay on the cylinder's side);
        ``plane``: the plane through ``background_point_m`` with normal ``background_normal``,
        whose normal points to the side where sensor and flange must stay.
    background_point_m : (3,) floats
        A point of the ``plane`` background, m.
    background_normal : (3,) floats
        Normal of the ``plane`` background (normalised on use).

    fixture_length_m : float
        Length of a fixture fin beyond the cylinder surface, m; 0 means no fin (see
        :mod:`~linelaser_calib.sim.clutter`).
    fixture_direction : (3,) floats
        Radial direction of the fin (projected perpendicular to the axis on use).
    fixture_band_m : (2,) floats
        Axial band of the fin, measured from ``cylinder_base_m`` along the axis, m.

    Hand-eye (truth)
    ----------------
    hand_eye_translation_m : (3,) floats
        Translation of the true ``T_flange_sensor``, m.
    hand_eye_rotation_xyzw : (4,) floats
        Rotation of the true ``T_flange_sensor``, unit quaternion ``xyzw``.

    Profiler
    --------
    z_min_m, z_max_m : float
        Measuring range (depth along sensor z), m. Returns outside are invalid.
    fan_half_angle_rad : float
        Half the opening angle of the laser fan, rad. Rays leave the sensor origin in the
        x-z plane with directions (τ, 0, 1)/|.|, τ evenly spaced in
        [-tan(fan_half_angle_rad), +tan(fan_half_angle_rad)] (even spacing in x at any
        depth, like the columns of a triangulation camera). The width at depth z is
        2 z tan(fan_half_angle_rad).
    resolution : int
        Number of rays (points per organised profile).
    sigma_depth_m, sigma_lateral_m, sigma_y_m : float
        Gaussian noise (1σ) on each point's z, x and y in the sensor frame, m. With
        ``sigma_y_m`` = 0 every point has y = 0 exactly.
    spike_fraction : float
        Fraction of returned points displaced along their ray by a random ±(``spike_min_m`` ..
        ``spike_max_m``) offset (reflections; they get a high, glint-like intensity).
    spike_min_m, spike_max_m : float
        Range of spike displacement magnitudes, m.
    dropout_fraction : float
        Fraction of otherwise valid rays that return nothing (NaN).
    max_incidence_rad : float
        Returns whose angle between the ray and the surface normal exceeds this are lost
        (grazing incidence), rad. π/2 disables the gate.
    camera_baseline_m : float
        Offset of the triangulation camera along sensor +y, m. A point is lost if the camera
        cannot see it (surface facing away or occluded by the scene). 0 disables shadowing.
    intensity : bool
        Produce per-point intensities (0..1): reflectance · cos(incidence) · (1 + noise).
        Invalid points get 0.
    cylinder_reflectance, background_reflectance : float
        Reflectance factors (0..1) used for the intensity.
    intensity_noise : float
        Relative 1σ noise of the intensity.
    organised : bool
        True: every profile has ``resolution`` rows, NaN rows for invalid rays (REP 117).
        False: dense, invalid rays dropped.
    sigma_spread : float
        0..1: each profile's noise is the sigmas above times a factor uniform in
        1 ± ``sigma_spread``.
    edge_bias_m : float
        Grazing-angle bias: each return moves out along the surface normal by
        ``edge_bias_m * (1 / cos(incidence) - 1)`` (capped at 10 ``edge_bias_m``), m.
    lateral_scale_error : float
        Relative error of the sensor's along-line scale: measured x = (1 + this) x.
    depth_quantum_m : float
        Depth resolution: measured z is rounded to multiples of this, m; 0 disables it.
    sensor : SensorModel
        A real profiler's shape errors beyond the white noise above (linearity bow, smooth
        per-profile error, correlated speckle, x/z output steps, weak returns on steep or
        dark surfaces); the default has none (see :mod:`~linelaser_calib.sim.sensor_models`).

    Pose sampler
    ------------
    n_poses : int
        Number of sensor poses (step-and-shoot shots, or continuous-motion waypoints).
    pose_mode : str
        ``paper``: long-axis and short-axis profiles (see below) with their own cut-angle
        ranges; ``general``: any in-plane viewing direction, cut angle in
        ``general_cut_range_rad``.
    long_axis_fraction : float
        In ``paper`` mode, the fraction of long-axis profiles.
    long_axis_cut_range_rad : (2,) floats
        Cut angle α (between the laser plane and the cylinder's cross-section) of long-axis
        profiles, rad; the sensor looks along the ellipse's minor axis and sees the flat arc
        spanning the major axis. Paper: 50°–75°.
    short_axis_cut_range_rad : (2,) floats
        Cut angle β of short-axis profiles, rad; the sensor looks along the ellipse's major axis
        (obliquely along the cylinder) and sees the curved arc around a major-axis vertex.
        Paper: 40°–60°.
    general_cut_range_rad : (2,) floats
        Cut angle in ``general`` mode, rad.
    view_spread_rad : float
        The sensor position is turned inside the laser plane about the ellipse centre by up to
        ± this from the nominal long/short-axis view, rad.
    aim_spread_rad : float
        The sensor is yawed about its y axis by up to ± this, so the arc is off-centre, rad.
    flip_roll : bool
        Turn half of the sensors 180° about their viewing axis (x and y flipped).
    standoff_spread : float
        0..1: fraction of the feasible standoff interval (whole arc within range and fan)
        the standoff is drawn from, centred on its middle.
    axial_spread : float
        0..1: fraction of the feasible axial interval (ellipse fully on the side) the ellipse
        centre is drawn from, centred on its middle.
    azimuth_range_rad : (2,) floats
        Allowed azimuth of the sensor around the axis, rad, measured from the direction from
        the axis towards the base origin (the robot side; any perpendicular if the axis passes
        within 1 cm of the origin), right-handed about the axis. (-π, π) allows all round.
    clearance_m : float
        Least distance of the sensor and flange origins from the cylinder and the background,
        m (a crude collision check).
    min_arc_fraction : float
        A pose is used only if at least this fraction of the rays return a cylinder point
        (noise-free).
    pose_clusters : int
        0: every pose is drawn on its own. C > 0: C poses are drawn and the ``n_poses``
        poses are spread over C clusters around them, each member turned by up to
        ± ``cluster_spread_rad`` (rotation vector, per axis, about the sensor origin) and
        shifted by up to ± ``cluster_spread_m`` (per base axis).
    cluster_spread_m, cluster_spread_rad : float
        Half-widths of the uniform spread within a cluster, m and rad.

    Robot
    -----
    robot_sigma_translation_m, robot_sigma_rotation_rad : float
        Per-axis 1σ of the per-shot pose error: recorded = true · E_sys · E, E with a Gaussian
        translation (m) and a Gaussian rotation vector (rad), in the flange frame.
    robot_systematic_translation_m, robot_systematic_rotvec_rad : (3,) floats
        The fixed error E_sys (translation m, rotation vector rad), in the flange frame.
    robot_field_m : (3,) floats
        Amplitude (about 2σ) of a smooth, position-dependent error of the recorded flange
        pose, expressed as the offset of the profile in the sensor frame (x along the
        line, y, z depth), m; zeros disable it (see :mod:`~linelaser_calib.sim.clutter`).
    robot_field_length_m : float
        Length scale of that field over the flange position, m.
    pose_jitter_translation_m, pose_jitter_rotation_rad : float
        Per-message 1σ jitter on every streamed pose (m, rad).
    robot_rate_hz : float
        Rate of the flange-pose stream, Hz (the stream runs before, during and after the
        scan; the period is rounded to whole ns).
    motion : str
        ``step``: step-and-shoot, a profile mid-way through each dwell; ``continuous``:
        profiles at ``profile_rate_hz`` while the robot moves through the waypoints.
    dwell_s : float
        Step-and-shoot: time the robot rests at each pose, s.
    margin_s : float
        Stream time before the first and after the last motion, s.
    move_speed_m_s, move_angular_speed_rad_s : float
        Average sensor speed (m/s) and turn rate (rad/s) of the moves. Step moves use
        quintic time scaling (at rest at both ends); continuous motion follows splines
        through the waypoints with quintic ease-in/out over the whole path.
    min_move_s : float
        Step-and-shoot: shortest move, s.
    profile_rate_hz : float
        Continuous motion: profile rate, Hz.
    latency_s : float
        Profiles are stamped this much later than acquired (negative: earlier), s.
    epoch_ns : int
        Stamp of the first streamed pose, ns.

    Arm kinematics
    --------------
    robot_model : str
        Empty: the flange simply follows the sampled poses (errors as above). ``ur5e`` or
        ``ur10e``: a serial arm (:mod:`~linelaser_calib.sim.arm`) whose controller reports
        nominal forward kinematics of its joints, also published as joint states; the
        robot errors above then act as repeatability on the true pose.
    kinematic_sigma_length_m : float
        1σ error of every length parameter of the true arm (DH d and a), m.
    kinematic_sigma_angle_rad : float
        1σ error of every angle parameter of the true arm (joint zero offsets and twists),
        rad.
    kinematic_seed : int
        -1: the true arm's errors are drawn with the run's seed. Otherwise they are drawn
        from this seed alone, so that runs with other seeds (other poses, another target
        placement) scan with the same arm.

    Topics and frames
    -----------------
    profile_topic, pose_topic : str
    joint_state_topic : str
        Topic of the joint states (written only with a ``robot_model``).
    sensor_frame, flange_frame, base_frame : str
    """

    name: str = "custom"
    cylinder_radius_m: float = 0.02
    cylinder_length_m: float = 0.2
    cylinder_base_m: Vec3 = (0.45, 0.15, 0.0)
    axis_direction: Vec3 = (0.0, 0.0, 1.0)
    background: str = "none"
    background_point_m: Vec3 = (0.0, 0.0, 0.0)
    background_normal: Vec3 = (0.0, 0.0, 1.0)
    fixture_length_m: float = 0.0
    fixture_direction: Vec3 = (1.0, 0.0, 0.0)
    fixture_band_m: Range = (0.0, 0.0)

    hand_eye_translation_m: Vec3 = (0.0, -0.06, 0.09)
    hand_eye_rotation_xyzw: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    z_min_m: float = 0.08
    z_max_m: float = 0.2
    fan_half_angle_rad: float = _deg(30.0)
    resolution: int = 800
    sigma_depth_m: float = 5e-6
    sigma_lateral_m: float = 5e-6
    sigma_y_m: float = 0.0
    spike_fraction: float = 0.0
    spike_min_m: float = 0.002
    spike_max_m: float = 0.008
    dropout_fraction: float = 0.0
    max_incidence_rad: float = math.pi / 2
    camera_baseline_m: float = 0.0
    intensity: bool = False
    cylinder_reflectance: float = 0.9
    background_reflectance: float = 0.5
    intensity_noise: float = 0.02
    organised: bool = False
    sigma_spread: float = 0.0
    edge_bias_m: float = 0.0
    lateral_scale_error: float = 0.0
    depth_quantum_m: float = 0.0
    sensor: SensorModel = field(default_factory=SensorModel)

    n_poses: int = 30
    pose_mode: str = "paper"
    long_axis_fraction: float = 0.5
    long_axis_cut_range_rad: Range = (_deg(50.0), _deg(75.0))
    short_axis_cut_range_rad: Range = (_deg(40.0), _deg(60.0))
    general_cut_range_rad: Range = (_deg(40.0), _deg(75.0))
    view_spread_rad: float = _deg(10.0)
    aim_spread_rad: float = _deg(4.0)
    flip_roll: bool = True
    standoff_spread: float = 0.6
    axial_spread: float = 0.8
    azimuth_range_rad: Range = (-math.pi, math.pi)
    clearance_m: float = 0.03
    min_arc_fraction: float = 0.15
    pose_clusters: int = 0
    cluster_spread_m: float = 0.0
    cluster_spread_rad: float = 0.0

    robot_sigma_translation_m: float = 0.0
    robot_sigma_rotation_rad: float = 0.0
    robot_systematic_translation_m: Vec3 = (0.0, 0.0, 0.0)
    robot_systematic_rotvec_rad: Vec3 = (0.0, 0.0, 0.0)
    robot_field_m: Vec3 = (0.0, 0.0, 0.0)
    robot_field_length_m: float = 0.5
    pose_jitter_translation_m: float = 0.0
    pose_jitter_rotation_rad: float = 0.0
    robot_rate_hz: float = 125.0
    motion: str = "step"
    dwell_s: float = 0.3
    margin_s: float = 0.2
    move_speed_m_s: float = 0.25
    move_angular_speed_rad_s: float = 1.0
    min_move_s: float = 0.4
    profile_rate_hz: float = 10.0
    latency_s: float = 0.0
    epoch_ns: int = 1_700_000_000_000_000_000

    robot_model: str = ""
    kinematic_sigma_length_m: float = 0.0
    kinematic_sigma_angle_rad: float = 0.0
    kinematic_seed: int = -1

    profile_topic: str = "/profile"
    pose_topic: str = "/flange_pose"
    joint_state_topic: str = "/joint_states"
    sensor_frame: str = "laser"
    flange_frame: str = "tool0"
    base_frame: str = "base_link"

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, list):
                object.__setattr__(self, f.name, tuple(float(v) for v in value))
        if isinstance(self.sensor, Mapping):
            object.__setattr__(self, "sensor", sensor_model_from_mapping(self.sensor))
        self._validate()

    @property
    def T_flange_sensor(self) -> FloatArray:
        """The true hand-eye, shape (4, 4), translation in m."""
        R = matrix_from_quaternion_xyzw(self.hand_eye_rotation_xyzw)
        return transform_from_rotation_translation(R, self.hand_eye_translation_m)

    @property
    def axis_unit(self) -> FloatArray:
        """Unit axis direction, shape (3,)."""
        a = np.asarray(self.axis_direction, dtype=np.float64)
        return a / np.linalg.norm(a)

    def cylinder(self) -> Cylinder:
        """The true cylinder as an infinite axis: the axis point closest to the base origin."""
        a = self.axis_unit
        b = np.asarray(self.cylinder_base_m, dtype=np.float64)
        return Cylinder(point=b - (b @ a) * a, direction=a, radius=self.cylinder_radius_m)

    def _validate(self) -> None:
        def require(ok: bool, what: str) -> None:
            if not ok:
                raise InputError(f"scenario {self.name!r}: {what}")

        def positive(*names: str) -> None:
            for n in names:
                require(getattr(self, n) > 0.0, f"{n} must be > 0, got {getattr(self, n)}")

        def non_negative(*names: str) -> None:
            for n in names:
                require(getattr(self, n) >= 0.0, f"{n} must be >= 0, got {getattr(self, n)}")

        def fraction(*names: str) -> None:
            for n in names:
                v = getattr(self, n)
                require(0.0 <= v <= 1.0, f"{n} must be in [0, 1], got {v}")

        def vector(name: str, size: int, nonzero: bool) -> None:
            v = np.asarray(getattr(self, name), dtype=np.float64)
            require(
                v.shape == (size,) and bool(np.all(np.isfinite(v))),
                f"{name} must be {size} finite numbers, got {getattr(self, name)}",
            )
            if nonzero:
                require(float(np.linalg.norm(v)) > 1e-12, f"{name} must not be zero")

        def cut_range(name: str) -> None:
            lo, hi = getattr(self, name)
            require(
                0.0 < lo <= hi < math.pi / 2,
                f"{name} must satisfy 0 < low <= high < pi/2 rad, got ({lo}, {hi})",
            )

        positive("cylinder_radius_m", "cylinder_length_m", "z_min_m", "fan_half_angle_rad")
        positive("robot_rate_hz", "dwell_s", "move_speed_m_s", "move_angular_speed_rad_s")
        positive("min_move_s", "profile_rate_hz", "max_incidence_rad")
        non_negative("sigma_depth_m", "sigma_lateral_m", "sigma_y_m", "spike_min_m")
        non_negative("camera_baseline_m", "intensity_noise", "view_spread_rad", "aim_spread_rad")
        non_negative("clearance_m", "robot_sigma_translation_m", "robot_sigma_rotation_rad")
        non_negative("pose_jitter_translation_m", "pose_jitter_rotation_rad", "margin_s")
        non_negative("edge_bias_m", "depth_quantum_m", "fixture_length_m")
        non_negative("cluster_spread_m", "cluster_spread_rad")
        positive("robot_field_length_m")
        fraction("sigma_spread")
        require(isinstance(self.sensor, SensorModel), "sensor must be a SensorModel")
        require(
            abs(self.lateral_scale_error) < 0.5,
            f"lateral_scale_error must be within +-0.5, got {self.lateral_scale_error}",
        )
        require(
            isinstance(self.pose_clusters, int) and 0 <= self.pose_clusters <= self.n_poses,
            f"pose_clusters must be an integer in [0, n_poses], got {self.pose_clusters}",
        )
        vector("robot_field_m", 3, nonzero=False)
        vector("fixture_direction", 3, nonzero=True)
        non_negative("kinematic_sigma_length_m", "kinematic_sigma_angle_rad")
        require(
            self.robot_model in ("", *UR_DH),
            f"robot_model must be empty or one of {sorted(UR_DH)}, got {self.robot_model!r}",
        )
        fraction("spike_fraction", "dropout_fraction", "cylinder_reflectance")
        fraction("background_reflectance", "long_axis_fraction", "standoff_spread")
        fraction("axial_spread", "min_arc_fraction")
        for name in ("cylinder_base_m", "background_point_m"):
            vector(name, 3, nonzero=False)
        for name in ("robot_systematic_translation_m", "robot_systematic_rotvec_rad"):
            vector(name, 3, nonzero=False)
        for name in ("axis_direction", "background_normal", "hand_eye_translation_m"):
            vector(name, 3, nonzero=name != "hand_eye_translation_m")
        try:
            check_quaternion_xyzw(self.hand_eye_rotation_xyzw)
        except ValueError as exc:
            raise InputError(f"scenario {self.name!r}: hand_eye_rotation_xyzw: {exc}") from None
        require(
            self.z_max_m > self.z_min_m,
            f"z_max_m ({self.z_max_m}) must exceed z_min_m ({self.z_min_m})",
        )
        require(
            self.fan_half_angle_rad < math.pi / 2,
            f"fan_half_angle_rad must be < pi/2, got {self.fan_half_angle_rad}",
        )
        require(
            self.max_incidence_rad <= math.pi / 2,
            f"max_incidence_rad must be <= pi/2, got {self.max_incidence_rad}",
        )
        require(
            isinstance(self.resolution, int) and self.resolution >= 3,
            f"resolution must be an integer >= 3, got {self.resolution}",
        )
        require(
            self.spike_max_m >= self.spike_min_m,
            f"spike_max_m ({self.spike_max_m}) must be >= spike_min_m ({self.spike_min_m})",
        )
        require(
            isinstance(self.n_poses, int) and self.n_poses >= 1,
            f"n_poses must be an integer >= 1, got {self.n_poses}",
        )
        require(self.background in BACKGROUNDS, f"background must be one of {BACKGROUNDS}")
        require(self.pose_mode in POSE_MODES, f"pose_mode must be one of {POSE_MODES}")
        require(self.motion in MOTIONS, f"motion must be one of {MOTIONS}")
        require(
            self.motion == "step" or self.n_poses >= 2,
            "continuous motion needs n_poses >= 2 waypoints",
        )
        for name in ("long_axis_cut_range_rad", "short_axis_cut_range_rad"):
            cut_range(name)
        cut_range("general_cut_range_rad")
        lo, hi = self.azimuth_range_rad
        require(
            lo < hi <= lo + 2 * math.pi,
            f"azimuth_range_rad must satisfy low < high <= low + 2 pi, got ({lo}, {hi})",
        )
        require(
            abs(self.latency_s) < self.margin_s,
            f"|latency_s| ({self.latency_s}) must be < margin_s ({self.margin_s}) so the pose "
            "stream brackets every profile stamp; raise margin_s",
        )
        require(
            isinstance(self.epoch_ns, int) and self.epoch_ns >= 0,
            f"epoch_ns must be a non-negative integer, got {self.epoch_ns}",
        )
        for name in ("profile_topic", "pose_topic", "joint_state_topic", "sensor_frame"):
            require(bool(getattr(self, name)), f"{name} must not be empty")
        for name in ("flange_frame", "base_frame"):
            require(bool(getattr(self, name)), f"{name} must not be empty")
