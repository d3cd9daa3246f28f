"""Simulation scenarios: every knob of the simulator in one frozen dataclass, plus presets.

A :class:`Scenario` holds plain numbers, strings, tuples and the frozen
:class:`~linelaser_calib.sim.sensor_models.SensorModel` record only (no arrays), so that it
can be written to and read from YAML by the I/O layer and compared with ``==``. Lists given for
tuple fields (as YAML readers produce them) are converted to tuples, a mapping given for
``sensor`` to a ``SensorModel``.

Units are SI throughout: metres, radians, seconds, hertz and integer nanoseconds; the unit is
in each field name or its description. Degrees appear only in descriptions, labelled.

Presets (:data:`PRESETS`, :func:`scenario_from_preset`):

``paper``
    The simulation of the cylinder paper, §4.1.1: axis through
    (1, 1, 1) mm with direction (3, 1, 1)/√11 (a 200 mm long cylinder centred there), Ø40 mm;
    true hand-eye eq. 17 (its printed rotation is orthonormal to ~4 digits only and is
    projected to SO(3) by SVD; translation (150, 200, 250) mm); 50 step-and-shoot poses,
    about half long-axis (α 50°-75°), half short-axis (β 40°-60°); sensor σ 5 µm on x and z;
    robot σ 0.1 mm and 0.01° per axis; 125 Hz pose stream; no background, no spikes or
    dropouts, dense profiles without intensity. The paper gives no sensor geometry, so a
    wide profiler is assumed: range 80-200 mm, fan ±30°, 800 points; this holds the whole
    long-axis arc of Ø40 mm up to α = 75° (up to ~150 mm wide). The poses are placed
    around the cylinder from the cut angles and the range; the flange follows from the
    hand-eye (0.35 m behind the sensor).
``ur_scancontrol``
    A UR-class arm with a scanCONTROL-class profiler (representative numbers, not a
    datasheet): an upright Ø40 x 100 mm shaft on a table (the background plane, in view)
    at (0.45, 0.15, 0) m; range 70-150 mm, fan ±25°, 640 points, organised with NaN rows
    and intensity; σ 8 µm depth and 6 µm lateral; 0.5 % spikes of 2-8 mm, 2 % dropouts,
    returns lost beyond 80° incidence and in the shadow of a 30 mm camera baseline;
    30 step-and-shoot poses, long-axis α 50°-65° (at 75° the arc would fill the fan and
    leave no room for the table) and short-axis β 40°-60°, sensor azimuth within ±150° of
    the robot side; hand-eye 0.128 m out from the flange, rotated (roll -20°, pitch 12°,
    yaw 95°); robot σ 0.03 mm and 0.003° per axis; 125 Hz pose stream, 0.3 s dwell.
``continuous``
    ``ur_scancontrol`` scanned while the robot moves through 6 waypoints without stopping
    (spline path, 0.15 m/s and 1.5 rad/s on average, sensor roll not flipped), profiles at
    10 Hz with 320 points, a 500 Hz pose stream and profiles stamped 4 ms late.
``cluttered_camera``
    A real cell as a coarse camera-based profiler sees it (:mod:`~linelaser_calib.sim.clutter`):
    an upright Ø25 x 400 mm bar at (0.95, 0, -0.2) m about 1 m from the sensor, a wall
    300 mm behind it turned 45° to the view, and a fixture fin 80 mm long on one side over
    20 mm of the bar's height (a profile crossing it runs from the arc into the fin with no
    gap); range 0.7-1.4 m, 3200 columns over a fan of ±16.7° (0.18-0.22 mm pitch at the
    bar), depth quantised in 16 µm steps, depth noise 50 µm ± 40 % per profile and 10 µm
    along the line, a 0.5 % along-line scale error, a grazing-angle bias of 30 µm ·
    (1 / cos(incidence) - 1) out of the surface, a 150 mm camera baseline; 120 poses in 6
    clusters (±3°, ±30 mm within), cut angles 10°-35° so that each arc is about 25 mm wide
    (110-140 points, 5-10 % of a profile); a smooth robot error field of about ±0.7 mm
    along the line, ±0.2 mm across and ±0.35 mm in depth over 0.4 m of the workspace, on top
    of robot σ 0.05 mm and 0.005°; 25 Hz pose stream, 0.2 s dwell.
``ur5e_kinematic``
    ``ur_scancontrol`` scanned by a UR5e (base at the origin) whose kinematics differ from
    the nominal DH table: lengths off by 1σ 0.15 mm, joint offsets and twists by 1σ 0.02°;
    repeatability 0.02 mm and 0.001° per axis; 50 poses, 320 points; flange poses and
    joint states at 40 Hz, 0.2 s dwell and quick moves to keep the bag small.
``ur5e_cell``
    What a real UR5e cell publishes, short enough to replay live: ``ur5e_kinematic`` with
    16 step-and-shoot poses in about 10 s (0.3 s stops, each profile half-way through its
    stop), joint states and flange poses at 125 Hz, and profiles stamped 15 ms late, as a
    profiler driver stamping with the host's receive time does. ``simulate --tf`` adds the
    robot_state_publisher-style ``/tf`` chain and ``/tf_static``.
``cylinder_keyence``, ``cylinder_scancontrol``, ``cylinder_gocator``
    ``ur_scancontrol``'s cell with a real profiler's datasheet geometry and shape errors
    (:mod:`~linelaser_calib.sim.sensor_models`), see :func:`_real_profiler_scenario`.

Bag size: a streamed pose costs ~120 bytes and a point 12-16 bytes in a rosbag2 MCAP file,
so ``resolution``, ``n_poses``, ``dwell_s``, the move speeds, ``robot_rate_hz`` and
``profile_rate_hz`` set the size; the presets make ~0.8-1.1 MB each before compression.

:func:`random_scenario` draws random scenes for robustness benchmarks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any, Protocol, TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    check_quaternion_xyzw,
    matrix_from_quaternion_xyzw,
    project_to_so3,
    quaternion_xyzw_from_matrix,
    transform_from_rotation_translation,
)
from linelaser_calib.core.kinematics import UR_DH
from linelaser_calib.core.types import Cylinder, FloatArray
from linelaser_calib.sim.sensor_models import (
    PROFILERS,
    SensorModel,
    profiler_fields,
    sensor_model_from_mapping,
)

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


def _paper_hand_eye() -> tuple[Vec3, tuple[float, float, float, float]]:
    """Paper eq. 17 (mm), rotation projected to SO(3) by SVD (it is orthonormal to ~4 digits)."""
    M = np.array(
        [
            [0.5771, 0.4940, 0.6503],
            [-0.8153, 0.3021, 0.4940],
            [0.0475, -0.8153, 0.5771],
        ]
    )
    q = quaternion_xyzw_from_matrix(project_to_so3(M))
    return (0.150, 0.200, 0.250), (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def _paper_scenario() -> Scenario:
    direction = np.array([3.0, 1.0, 1.0]) / math.sqrt(11.0)
    length = 0.2
    base = np.array([0.001, 0.001, 0.001]) - 0.5 * length * direction
    translation, rotation = _paper_hand_eye()
    return Scenario(
        name="paper",
        cylinder_radius_m=0.020,
        cylinder_length_m=length,
        cylinder_base_m=(float(base[0]), float(base[1]), float(base[2])),
        axis_direction=(float(direction[0]), float(direction[1]), float(direction[2])),
        background="none",
        hand_eye_translation_m=translation,
        hand_eye_rotation_xyzw=rotation,
        z_min_m=0.08,
        z_max_m=0.20,
        fan_half_angle_rad=_deg(30.0),
        resolution=800,
        sigma_depth_m=5e-6,
        sigma_lateral_m=5e-6,
        n_poses=50,
        robot_sigma_translation_m=1e-4,
        robot_sigma_rotation_rad=_deg(0.01),
        robot_rate_hz=125.0,
        clearance_m=0.03,
    )


def _ur_scancontrol_scenario() -> Scenario:
    # Roll, pitch, yaw (fixed x-y-z axes) of the sensor on its bracket.
    R_flange_sensor = Rotation.from_euler("xyz", [_deg(-20.0), _deg(12.0), _deg(95.0)])
    q = quaternion_xyzw_from_matrix(R_flange_sensor.as_matrix())
    return Scenario(
        name="ur_scancontrol",
        cylinder_radius_m=0.020,
        cylinder_length_m=0.10,
        cylinder_base_m=(0.45, 0.15, 0.0),
        axis_direction=(0.0, 0.0, 1.0),
        background="table",
        hand_eye_translation_m=(0.012, -0.085, 0.095),
        hand_eye_rotation_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        z_min_m=0.07,
        z_max_m=0.15,
        fan_half_angle_rad=_deg(25.0),
        resolution=640,
        sigma_depth_m=8e-6,
        sigma_lateral_m=6e-6,
        spike_fraction=0.005,
        spike_min_m=0.002,
        spike_max_m=0.008,
        dropout_fraction=0.02,
        max_incidence_rad=_deg(80.0),
        camera_baseline_m=0.03,
        intensity=True,
        organised=True,
        n_poses=30,
        long_axis_cut_range_rad=(_deg(50.0), _deg(65.0)),
        axial_spread=1.0,
        azimuth_range_rad=(_deg(-150.0), _deg(150.0)),
        clearance_m=0.03,
        robot_sigma_translation_m=3e-5,
        robot_sigma_rotation_rad=_deg(0.003),
        robot_rate_hz=125.0,
        dwell_s=0.3,
    )


def _continuous_scenario() -> Scenario:
    return replace(
        _ur_scancontrol_scenario(),
        name="continuous",
        motion="continuous",
        n_poses=6,
        flip_roll=False,
        resolution=320,
        robot_rate_hz=500.0,
        profile_rate_hz=10.0,
        move_speed_m_s=0.15,
        move_angular_speed_rad_s=1.5,
        latency_s=0.004,
    )


def _cluttered_camera_scenario() -> Scenario:
    # The sensor looks along the base x axis (roll, pitch, yaw, fixed x-y-z axes).
    R_flange_sensor = Rotation.from_euler("xyz", [_deg(90.0), _deg(0.0), _deg(-90.0)])
    q = quaternion_xyzw_from_matrix(R_flange_sensor.as_matrix())
    return Scenario(
        name="cluttered_camera",
        cylinder_radius_m=0.0125,
        cylinder_length_m=0.4,
        cylinder_base_m=(0.95, 0.0, -0.2),
        axis_direction=(0.0, 0.0, 1.0),
        background="plane",
        background_point_m=(1.25, 0.0, 0.0),
        background_normal=(-0.7, 0.7, 0.0),
        fixture_length_m=0.08,
        fixture_direction=(0.0, 1.0, 0.0),
        fixture_band_m=(0.17, 0.19),
        hand_eye_translation_m=(0.03, -0.12, 0.16),
        hand_eye_rotation_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        z_min_m=0.7,
        z_max_m=1.4,
        fan_half_angle_rad=math.atan(0.3),
        resolution=3200,
        sigma_depth_m=5e-5,
        sigma_lateral_m=1e-5,
        sigma_spread=0.4,
        edge_bias_m=3e-5,
        lateral_scale_error=0.005,
        depth_quantum_m=1.6e-5,
        max_incidence_rad=_deg(85.0),
        camera_baseline_m=0.15,
        pose_mode="general",
        general_cut_range_rad=(_deg(10.0), _deg(35.0)),
        view_spread_rad=_deg(20.0),
        azimuth_range_rad=(_deg(-35.0), _deg(35.0)),
        standoff_spread=0.2,
        axial_spread=0.3,
        min_arc_fraction=0.02,
        n_poses=120,
        pose_clusters=6,
        cluster_spread_m=0.03,
        cluster_spread_rad=_deg(3.0),
        robot_sigma_translation_m=5e-5,
        robot_sigma_rotation_rad=_deg(0.005),
        robot_field_m=(7e-4, 2e-4, 3.5e-4),
        robot_field_length_m=0.4,
        robot_rate_hz=25.0,
        dwell_s=0.2,
        margin_s=0.1,
    )


def _ur5e_kinematic_scenario() -> Scenario:
    return replace(
        _ur_scancontrol_scenario(),
        name="ur5e_kinematic",
        n_poses=50,
        resolution=320,
        robot_model="ur5e",
        kinematic_sigma_length_m=1.5e-4,
        kinematic_sigma_angle_rad=_deg(0.02),
        robot_sigma_translation_m=2e-5,
        robot_sigma_rotation_rad=_deg(0.001),
        robot_rate_hz=40.0,
        dwell_s=0.2,
        min_move_s=0.3,
        move_speed_m_s=0.5,
        move_angular_speed_rad_s=3.0,
    )


def _ur5e_cell_scenario() -> Scenario:
    return replace(
        _ur5e_kinematic_scenario(),
        name="ur5e_cell",
        n_poses=16,
        robot_rate_hz=125.0,
        dwell_s=0.3,
        min_move_s=0.15,
        margin_s=0.1,
        latency_s=0.015,
    )


#: Named scenarios; see the module docstring and :func:`scenario_from_preset`.
PRESETS: dict[str, Scenario] = {
    "paper": _paper_scenario(),
    "ur_scancontrol": _ur_scancontrol_scenario(),
    "continuous": _continuous_scenario(),
    "cluttered_camera": _cluttered_camera_scenario(),
    "ur5e_kinematic": _ur5e_kinematic_scenario(),
    "ur5e_cell": _ur5e_cell_scenario(),
}


def _real_profiler_scenario(
    name: str, profiler: str, radius_m: float, cut_range_deg: tuple[float, float]
) -> Scenario:
    """``ur_scancontrol``'s cell and arm scanning a shaft with a real profiler's datasheet
    geometry and shape errors (:data:`~linelaser_calib.sim.sensor_models.PROFILERS`).

    The shaft's radius and the cut angles (``general`` views, any in-plane direction) are
    chosen so that the visible arc fits the profiler's narrower line.
    """
    return replace(
        _ur_scancontrol_scenario(),
        name=name,
        **profiler_fields(PROFILERS[profiler]),
        cylinder_radius_m=radius_m,
        pose_mode="general",
        general_cut_range_rad=(_deg(cut_range_deg[0]), _deg(cut_range_deg[1])),
    )


# Real profilers on a shaft (datasheet figures and their sources: sim/sensor_models.py).
# ``cylinder_keyence``: Keyence LJ-X8080 (35 mm line), Ø16 mm shaft, cut angles 10-35 deg;
# ``cylinder_scancontrol``: scanCONTROL 3010-50 (50 mm line), Ø30 mm, 10-40 deg;
# ``cylinder_gocator``: Gocator 2330 (47-85 mm line), Ø40 mm, 10-45 deg.
PRESETS.update(
    {
        "cylinder_keyence": _real_profiler_scenario(
            "cylinder_keyence", "keyence_lj_x8080", 0.008, (10.0, 35.0)
        ),
        "cylinder_scancontrol": _real_profiler_scenario(
            "cylinder_scancontrol", "scancontrol_3010_50", 0.015, (10.0, 40.0)
        ),
        "cylinder_gocator": _real_profiler_scenario(
            "cylinder_gocator", "gocator_2330", 0.020, (10.0, 45.0)
        ),
    }
)


def scenario_from_preset(name: str, **overrides: Any) -> Scenario:
    """A preset scenario with some fields replaced.

    Parameters
    ----------
    name : str
        A key of :data:`PRESETS`.
    **overrides
        Scenario fields to replace (SI units, see :class:`Scenario`).

    Raises
    ------
    InputError
        For an unknown preset or field, or an invalid value.
    """
    if name not in PRESETS:
        raise InputError(f"unknown scenario preset {name!r}; choose one of {sorted(PRESETS)}")
    known = {f.name for f in fields(Scenario)}
    unknown = sorted(set(overrides) - known)
    if unknown:
        raise InputError(
            f"unknown scenario field(s) {unknown}; see linelaser_calib.sim.Scenario for the "
            "list of fields"
        )
    return replace(PRESETS[name], **overrides)


class _HasRig(Protocol):
    @property
    def rig(self) -> Scenario: ...


RigScene = TypeVar("RigScene", bound=_HasRig)


def rig_scene_from_preset(
    presets: Mapping[str, RigScene], name: str, what: str, overrides: Mapping[str, Any]
) -> RigScene:
    """A preset of a scene dataclass with a ``rig`` (:class:`Scenario`) field, fields replaced.

    Parameters
    ----------
    presets : mapping of str to scene
    name : str
        A key of ``presets``.
    what : str
        The scene's name in messages (``weld``, ``sphere``).
    overrides : mapping
        The scene's own fields, or :class:`Scenario` fields (applied to the rig), SI.

    Raises
    ------
    InputError
        For an unknown preset or field, or an invalid value.
    """
    if name not in presets:
        raise InputError(f"unknown {what} preset {name!r}; choose one of {sorted(presets)}")
    preset = presets[name]
    own = {f.name for f in fields(preset)} - {"rig"}  # type: ignore[arg-type]
    rig_fields = {f.name for f in fields(Scenario)} - {"name"}
    unknown = sorted(set(overrides) - own - rig_fields)
    if unknown:
        raise InputError(
            f"unknown {what} scenario field(s) {unknown}; see the {type(preset).__name__} "
            "class and linelaser_calib.sim.Scenario"
        )
    rig_overrides = {k: v for k, v in overrides.items() if k in rig_fields}
    own_overrides = {k: v for k, v in overrides.items() if k in own}
    rig = replace(preset.rig, **rig_overrides) if rig_overrides else preset.rig
    return replace(preset, rig=rig, **own_overrides)  # type: ignore[type-var]


def random_scenario(
    rng: np.random.Generator,
    *,
    n_poses_range: tuple[int, int] = (12, 100),
    **overrides: Any,
) -> Scenario:
    """A random scene for robustness benchmarks.

    Drawn: a uniformly random hand-eye rotation with a 0.03-0.3 m translation in a random
    direction; the cylinder axis through a point uniform in a ±0.5 m box, in a uniformly
    random direction; radius 10-30 mm and a length that holds every cut; a table or no
    background (even odds); a profiler with range start 50-100 mm, range depth 100-200 mm
    and fan half-angle 20°-35°; ``general`` poses (any in-plane viewing direction, cut
    angles 40°-75°); sensor noise 2-20 µm, robot noise up to 0.1 mm and 0.01° (1σ per
    axis); spikes up to 1 %, dropouts up to 5 %; ``n_poses`` uniform in ``n_poses_range``
    (inclusive). Everything else keeps the :class:`Scenario` defaults.

    Parameters
    ----------
    rng : numpy.random.Generator
    n_poses_range : (int, int)
        Inclusive range of the number of poses.
    **overrides
        Fields set after drawing (they win over the draws).
    """
    q = rng.normal(size=4)
    q = q / np.linalg.norm(q)
    t_dir = rng.normal(size=3)
    translation = t_dir / np.linalg.norm(t_dir) * rng.uniform(0.03, 0.3)
    axis = rng.normal(size=3)
    axis = axis / np.linalg.norm(axis)
    radius = float(rng.uniform(0.01, 0.03))
    cut_range = (_deg(40.0), _deg(75.0))
    length = max(float(rng.uniform(0.12, 0.3)), 2.0 * radius * math.tan(cut_range[1]) + 0.02)
    z_min = float(rng.uniform(0.05, 0.1))
    drawn = Scenario(
        name="random",
        cylinder_radius_m=radius,
        cylinder_length_m=length,
        cylinder_base_m=tuple(float(v) for v in rng.uniform(-0.5, 0.5, 3)),  # type: ignore[arg-type]
        axis_direction=(float(axis[0]), float(axis[1]), float(axis[2])),
        background="table" if rng.random() < 0.5 else "none",
        hand_eye_translation_m=(
            float(translation[0]),
            float(translation[1]),
            float(translation[2]),
        ),
        hand_eye_rotation_xyzw=(float(q[0]), float(q[1]), float(q[2]), float(q[3])),
        z_min_m=z_min,
        z_max_m=z_min + float(rng.uniform(0.1, 0.2)),
        fan_half_angle_rad=float(rng.uniform(_deg(20.0), _deg(35.0))),
        sigma_depth_m=float(rng.uniform(2e-6, 2e-5)),
        sigma_lateral_m=float(rng.uniform(2e-6, 2e-5)),
        spike_fraction=float(rng.uniform(0.0, 0.01)),
        dropout_fraction=float(rng.uniform(0.0, 0.05)),
        pose_mode="general",
        general_cut_range_rad=cut_range,
        n_poses=int(rng.integers(n_poses_range[0], n_poses_range[1] + 1)),
        robot_sigma_translation_m=float(rng.uniform(0.0, 1e-4)),
        robot_sigma_rotation_rad=float(rng.uniform(0.0, _deg(0.01))),
    )
    return replace(drawn, **overrides) if overrides else drawn
