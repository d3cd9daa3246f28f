"""Straight-seam scenes: a fillet or V joint scanned along its length, no point taught.

The target is the groove of :mod:`linelaser_calib.sim.weld` (two flanks meeting along a
straight seam), much longer than the weld scene's. The robot sweeps the sensor along the
seam without stopping, weaving it sideways in an S so that the seam crosses the laser plane
at changing places of the laser line, while the sensor tilts and turns. Every profile is a V
whose corner is where the laser plane meets the seam: all the corners lie on one 3-D line.

:class:`LineScenario` holds the seam geometry and the sweep and, in its ``rig`` field, an
ordinary :class:`~linelaser_calib.sim.scenario.Scenario` for everything else (profiler, true
hand-eye, robot error model, continuous-motion timing, profile latency, topics, frames). The
rig's cylinder, background and pose-sampler fields are not used; its ``n_poses`` is the
number of waypoints of the sweep and its motion must be ``continuous``.

Sweep (waypoint k of M, u = k / (M − 1) from 0 to 1): the laser plane meets the seam at
``seam_point_m + (2u − 1) · sweep_half_length_m · s``; there the seam point is seen at depth
``depth_range_m`` (mid ± half, one period over the sweep) and at x = ``weave_centre`` +
``weave_fraction`` · sin(2π · ``weaves`` · u + φ) of the half fan width (the S). The
orientation is the nominal view of the weld scene (sensor z into the groove, laser plane
across the seam) tilted about the sensor x axis (tipping the laser plane along the seam) by
up to ``tilt_along_rad``, about its y axis by up to ``tilt_across_rad`` and turned about the
viewing axis by up to ``yaw_rad``, each a sinusoid of its own frequency over the sweep; the
phases φ are drawn from the seed. The robot runs the rig's continuous motion through the
waypoints (a spline, quintic ease-in/out); sweeps in which a profile fails to show both
flanks with ``min_flank_points`` returns, or the sensor or flange comes within the rig's
``clearance_m`` of a flank plane, are drawn again; so, with ``determined_sigma_m`` set, are
sweeps that leave a hand-eye direction poorly determined: the line target's own information
of the hand-eye from the true corners, each known to :data:`PLANNED_CORNER_SIGMA_M`, with
the line and both profiler scales marginalised, must give every direction a 1σ (rotations
times the corners' lever) within ``determined_sigma_m``. The phases alone decide much: on
``line_ridge`` the first draws of seeds 0-9 give a worst 1σ of 0.69-2.03 mm there, and the
seeds beyond 1.2 mm (0, 7, 8) were refused as undetermined (the target refuses at 1 mm; its
corner fits are about 17 µm, so 0.9 mm here is about 0.75 mm there).

Timing: the flange-pose stream runs at the rig's ``robot_rate_hz``, each stamp off by a
Gaussian ``stamp_jitter_s``; profiles are stamped ``latency_s`` late (the rig's).

``feature_points``: instead of the whole profile, each message holds three points, as seam
trackers publish them: the outermost return of each flank and the seam point (the true corner
plus the rig's profiler noise), in x order.

Presets (:data:`LINE_PRESETS`): ``line`` (dense V profiles) and ``line_features`` (feature
points only), both a 90-deg fillet seam; a scanCONTROL-class profiler (70-150 mm, ±25 deg,
200 points, dense, no intensity); 60 waypoints over ±80 mm of seam swept at 0.1 m/s on
average (three S periods, tilts of ±30 deg along and ±15 deg across the seam, turns of
±35 deg); profiles at 25 Hz stamped 12 ms late; a 250 Hz (4 ms) pose stream with 0.25 ms
stamp jitter; and a UR-class robot error of 0.02 mm and 0.002 deg per axis (1σ) drawn at
each waypoint and blended between them.

``line_ridge``: a straight ridge on a block seen as real recordings from an SSZN-type
profiler showed it (issue 29): each profile an inverted V (``ridge``) with a long gentle
flank (60 mm at 15 deg, 600-1000 points at the 0.05 mm pitch of ``sszn_fanuc``) and a steep
one (20 mm at 80 deg, ``flank_turn_rad``) that the laser meets at grazing incidence, so that
it holds 30-250 points (median about 100), with a 10 mm floor beside it (a third straight
segment); the profiler carries the ``grazing``, ``gaps`` and ``scales`` faces of
:data:`~linelaser_calib.sim.sensor_models.REAL_FACES` (thinning at incidence, gaps, x/z scales
0.8 % apart) and ``sszn_fanuc``'s own 42 µm shape error over 4 mm. 8 waypoints over
±40 mm of ridge at 0.05 m/s, profiles at 5 Hz (about 50), the view turned 15 deg towards
the steep flank, tilts of ±26 deg along and ±8 deg across, turns of ±29 deg; a FANUC-like
robot error of 0.03 mm and 0.005 deg; sweeps determined to 0.9 mm (``determined_sigma_m``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import invert_transform, matrix_from_rotvec
from linelaser_calib.core.observability import scaled_eigen
from linelaser_calib.core.targets.line.config import LineConfig
from linelaser_calib.core.targets.line.model import Line
from linelaser_calib.core.targets.line.refine import refine_line
from linelaser_calib.core.types import BoolArray, FlangePose, FloatArray, Profile
from linelaser_calib.sim.presets import rig_scene_from_preset
from linelaser_calib.sim.profiler import Measurement, measure
from linelaser_calib.sim.robot import draw_errors, plan_motion, reported_flange
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Int8Array, Int64Array
from linelaser_calib.sim.sensor_models import PROFILERS, profiler_fields, with_faces
from linelaser_calib.sim.simulate import published_profiles, recorded_pose_stream
from linelaser_calib.sim.weld import (
    WELD_PRESETS,
    Groove,
    GrooveScene,
    GrooveShape,
    flank_counts,
    nominal_view,
    trace_groove,
)

Vec3 = tuple[float, float, float]

#: Sweeps drawn (new phases) before giving up.
MAX_SWEEP_DRAWS = 50
#: The 1σ of each true corner with which a sweep's determination is judged
#: (``determined_sigma_m``), m: a little above the ``line_ridge`` corner fits' (about 17 µm).
PLANNED_CORNER_SIGMA_M = 2e-5
#: Frequencies (periods over the sweep) of the tilts about x and y and of the turn.
_TILT_X_CYCLES, _TILT_Y_CYCLES, _YAW_CYCLES = 1.5, 1.0, 0.75


@dataclass(frozen=True)
class LineScenario(GrooveScene):
    """Every parameter of one simulated straight-seam run (see the module docstring).

    Attributes
    ----------
    name : str
    rig : Scenario
        Profiler, true hand-eye, robot errors, continuous-motion timing, latency, topics and
        frames.
    seam_point_m : (3,) floats
        A point of the seam, the middle of the sweep, base frame, m.
    seam_direction : (3,) floats
        Seam direction (normalised on use).
    groove_bisector : (3,) floats
        Out of the groove into the free space (made perpendicular to the seam).
    opening_angle_rad : float
        Angle between the flanks, rad, in (0, π).
    flank_width_m, seam_half_length_m : float
        Extent of each flank from the seam, and of the seam from ``seam_point_m``, m.
    sweep_half_length_m : float
        The sweep covers ± this along the seam, m.
    weaves : float
        Sideways periods of the S over the sweep.
    weave_fraction : float
        Amplitude of the seam point's x about ``weave_centre``, a share of the half fan
        width, in [0, 1).
    weave_centre : float
        Mean x of the seam point, a share of the half fan width (signed; 0: the middle of
        the line); ``|weave_centre| + weave_fraction`` < 1.
    depth_range_m : (2,) floats
        Depth of the seam point in the sensor, m.
    tilt_along_rad, tilt_across_rad, yaw_rad : float
        Largest tilt about the sensor x axis (the laser plane tips along the seam), about its
        y axis (the view turns across the seam inside the laser plane), and turn about its
        z axis, rad.
    ridge : bool
        The flanks run down from the seam: a ridge on a block seen from outside (an inverted
        V) instead of a groove.
    flank_turn_rad : float
        Both flanks turned about the seam by this angle, rad: one gentle, the other steep.
    second_flank_width_m : float
        Width of the second flank, m; 0: ``flank_width_m``.
    floor_width_m : float
        A floor this wide beyond the second flank's far edge (the table beside a block), m;
        0: none. It is a third straight segment in the profiles that reach it.
    view_tilt_rad : float
        The nominal view turned about the seam by this angle, rad (towards a steep flank).
    stamp_jitter_s : float
        1σ error of the flange-pose stamps, s.
    feature_points : bool
        Publish three feature points per profile instead of the profile.
    min_flank_points : int
        Fewest noise-free returns on each flank of every profile.
    determined_sigma_m : float
        Largest 1σ of any hand-eye direction a sweep may leave (corners known to
        :data:`PLANNED_CORNER_SIGMA_M`; rotations times the lever), m; 0: not checked.
    """

    name: str = "custom"
    rig: Scenario = field(default_factory=lambda: Scenario(motion="continuous"))
    seam_point_m: Vec3 = (0.55, 0.05, 0.02)
    seam_direction: Vec3 = (1.0, 0.35, 0.0)
    groove_bisector: Vec3 = (0.0, 0.0, 1.0)
    opening_angle_rad: float = math.radians(90.0)
    flank_width_m: float = 0.03
    seam_half_length_m: float = 0.2
    sweep_half_length_m: float = 0.08
    weaves: float = 3.0
    weave_fraction: float = 0.65
    weave_centre: float = 0.0
    depth_range_m: tuple[float, float] = (0.08, 0.135)
    tilt_along_rad: float = math.radians(30.0)
    tilt_across_rad: float = math.radians(15.0)
    yaw_rad: float = math.radians(35.0)
    ridge: bool = False
    flank_turn_rad: float = 0.0
    second_flank_width_m: float = 0.0
    floor_width_m: float = 0.0
    view_tilt_rad: float = 0.0
    stamp_jitter_s: float = 0.0
    feature_points: bool = False
    min_flank_points: int = 15
    determined_sigma_m: float = 0.0

    kind: ClassVar[str] = "line"
    vectors: ClassVar[tuple[str, ...]] = ("seam_point_m", "seam_direction", "groove_bisector")
    directions: ClassVar[tuple[str, ...]] = ("seam_direction", "groove_bisector")

    def __post_init__(self) -> None:
        super().__post_init__()
        require = self.require
        for name in ("sweep_half_length_m", "weaves"):
            require(getattr(self, name) > 0.0, f"{name} must be > 0, got {getattr(self, name)}")
        require(
            self.sweep_half_length_m < self.seam_half_length_m,
            "sweep_half_length_m must be shorter than seam_half_length_m",
        )
        require(0.0 <= self.weave_fraction < 1.0, "weave_fraction must be in [0, 1)")
        require(
            abs(self.weave_centre) + self.weave_fraction < 1.0,
            "|weave_centre| + weave_fraction must be < 1",
        )
        lo, hi = self.depth_range_m
        require(0.0 < lo <= hi, "depth_range_m must satisfy 0 < low <= high")
        for name in ("tilt_along_rad", "tilt_across_rad", "yaw_rad"):
            value = getattr(self, name)
            require(0.0 <= value < math.pi / 2, f"{name} must be in [0, pi/2) rad, got {value}")
        require(self.stamp_jitter_s >= 0.0, "stamp_jitter_s must be >= 0")
        for name in ("second_flank_width_m", "floor_width_m", "determined_sigma_m"):
            require(getattr(self, name) >= 0.0, f"{name} must be >= 0, got {getattr(self, name)}")
        for name in ("flank_turn_rad", "view_tilt_rad"):
            value = getattr(self, name)
            require(abs(value) < math.pi / 2, f"{name} must be within +-pi/2 rad, got {value}")
        require(self.rig.n_poses >= 4, "the rig's n_poses (waypoints) must be >= 4")
        require(self.rig.motion == "continuous", "the rig's motion must be 'continuous'")

    def groove(self) -> Groove:
        """The seam's groove in the base frame."""
        return Groove.build(
            self.seam_point_m,
            self.seam_direction,
            self.groove_bisector,
            self.opening_angle_rad,
            self.flank_width_m,
            self.seam_half_length_m,
            GrooveShape(
                self.ridge, self.flank_turn_rad, self.second_flank_width_m, self.floor_width_m
            ),
        )


def line_nearest_origin(point: FloatArray, direction: FloatArray) -> FloatArray:
    """The point (3,) of the line through ``point`` along unit ``direction`` nearest the origin."""
    return np.asarray(point - (point @ direction) * direction)


def sweep_waypoints(scenario: LineScenario, groove: Groove, phases: FloatArray) -> FloatArray:
    """Sensor poses (M, 4, 4) of the S-sweep for the given phases (5,), rad."""
    rig = scenario.rig
    u = np.linspace(0.0, 1.0, rig.n_poses)
    R0 = nominal_view(groove)
    lo, hi = scenario.depth_range_m
    depth = 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.sin(2.0 * math.pi * u + phases[0])
    half_width = depth * math.tan(rig.fan_half_angle_rad)
    x = (
        scenario.weave_fraction
        * depth
        * math.tan(rig.fan_half_angle_rad)
        * np.sin(2.0 * math.pi * scenario.weaves * u + phases[1])
    ) + scenario.weave_centre * half_width
    tilt_x = scenario.tilt_along_rad * np.sin(2.0 * math.pi * _TILT_X_CYCLES * u + phases[2])
    tilt_y = scenario.view_tilt_rad + scenario.tilt_across_rad * np.sin(
        2.0 * math.pi * _TILT_Y_CYCLES * u + phases[3]
    )
    yaw = scenario.yaw_rad * np.sin(2.0 * math.pi * _YAW_CYCLES * u + phases[4])
    on_seam = groove.point + np.outer((2.0 * u - 1.0) * scenario.sweep_half_length_m, groove.seam)
    T = np.tile(np.eye(4), (len(u), 1, 1))
    for k in range(len(u)):
        R = (
            R0
            @ matrix_from_rotvec([tilt_x[k], tilt_y[k], 0.0])
            @ matrix_from_rotvec([0.0, 0.0, yaw[k]])
        )
        T[k, :3, :3] = R
        T[k, :3, 3] = on_seam[k] - R @ np.array([x[k], 0.0, depth[k]])
    return T


def _sweep_ok(scenario: LineScenario, groove: Groove, T_base_sensor: FloatArray) -> bool:
    """Every pose shows both flanks and keeps sensor and flange clear of the plates."""
    rig = scenario.rig
    counts = flank_counts(groove, rig, T_base_sensor)
    T_base_flange = T_base_sensor @ invert_transform(rig.T_flange_sensor)
    clear = (groove.free_clearance(T_base_sensor[:, :3, 3]) >= rig.clearance_m) & (
        groove.free_clearance(T_base_flange[:, :3, 3]) >= rig.clearance_m
    )
    return bool(np.all((counts.min(axis=1) >= scenario.min_flank_points) & clear))


def worst_direction_sigma_m(
    scenario: LineScenario, groove: Groove, T_base_sensor: FloatArray
) -> float:
    """The largest 1σ of a hand-eye direction (rotations times the corners' median lever),
    m, that profiles at ``T_base_sensor`` (K, 4, 4) give the line target, each true corner
    known to :data:`PLANNED_CORNER_SIGMA_M`, the line and both scales marginalised."""
    X = scenario.rig.T_flange_sensor
    corners = np.einsum(
        "kji,kj->ki",
        T_base_sensor[:, :3, :3],
        groove.seam_point_in_plane(T_base_sensor) - T_base_sensor[:, :3, 3],
    )[:, [0, 2]]
    covariance = np.tile(np.eye(2) * PLANNED_CORNER_SIGMA_M**2, (len(corners), 1, 1))
    refined = refine_line(
        corners,
        covariance,
        T_base_sensor @ invert_transform(X),
        X,
        Line.through(groove.point, groove.seam),
        None,
        LineConfig(
            robot_sigma_t_m=scenario.rig.robot_sigma_translation_m,
            robot_sigma_r_rad=scenario.rig.robot_sigma_rotation_rad,
        ),
        (True, True),
    )
    lever = float(np.median(np.hypot(corners[:, 0], corners[:, 1])))
    return float(np.max(scaled_eigen(refined.information_data, lever)[2]))


@dataclass(frozen=True, eq=False)
class LineTruth:
    """Ground truth of a simulated straight-seam run (K profiles).

    Attributes
    ----------
    scenario : LineScenario
    seed : int
    T_flange_sensor : ndarray, shape (4, 4)
        The true hand-eye.
    line_point : ndarray, shape (3,)
        The seam line's point nearest the base origin, m.
    line_direction : ndarray, shape (3,)
        Unit seam direction.
    T_base_flange_true, T_base_flange_recorded : ndarray, shape (K, 4, 4)
        True and reported (without jitter) flange poses at the acquisition times.
    stamps_ns, acquisition_stamps_ns : ndarray of int64, shape (K,)
        Profile stamps as published (acquisition + latency), and the acquisition times.
    T_base_sensor_waypoints : ndarray, shape (M, 4, 4)
    corner_true_sensor : ndarray, shape (K, 3)
        Where each true laser plane meets the seam, sensor frame (y = 0), m.
    corner_true_base : ndarray, shape (K, 3)
        The same points in the base frame, m.
    """

    scenario: LineScenario
    seed: int
    T_flange_sensor: FloatArray
    line_point: FloatArray
    line_direction: FloatArray
    T_base_flange_true: FloatArray
    T_base_flange_recorded: FloatArray
    stamps_ns: Int64Array
    acquisition_stamps_ns: Int64Array
    T_base_sensor_waypoints: FloatArray
    corner_true_sensor: FloatArray
    corner_true_base: FloatArray


@dataclass(frozen=True, eq=False)
class LineSimulatedData:
    """Everything a straight-seam run produces; the same layout as ``SimulatedData``.

    Attributes
    ----------
    profiles : list of Profile
    intensities : list of (ndarray or None)
    poses : list of FlangePose
    truth : LineTruth
    """

    profiles: list[Profile]
    intensities: list[FloatArray | None]
    poses: list[FlangePose]
    truth: LineTruth

    @property
    def scenario(self) -> Scenario:
        """The rig (topics, frame names, output format), as ``SimulatedData.scenario``."""
        return self.truth.scenario.rig


def _feature_measurement(
    rng: np.random.Generator,
    rig: Scenario,
    corners: FloatArray,
    points: FloatArray,
    flank: Int8Array,
    seen: BoolArray,
) -> Measurement:
    """Three feature points per profile: each flank's outermost return and the seam point."""
    K = len(corners)
    feature = np.full((K, 3, 3), np.nan)
    feature[:, 1] = corners
    for k in range(K):
        for side, label in ((0, 1), (2, 2)):
            on = np.flatnonzero(seen[k] & (flank[k] == label))
            if on.size:
                far = on[np.argmax(np.linalg.norm(points[k, on] - corners[k], axis=1))]
                feature[k, side] = points[k, far]
    sigma = np.array([rig.sigma_lateral_m, rig.sigma_y_m, rig.sigma_depth_m])
    feature = feature + rng.normal(size=feature.shape) * sigma
    order = np.argsort(np.nan_to_num(feature[..., 0], nan=np.inf), axis=1)
    feature = np.take_along_axis(feature, order[..., None], axis=1)
    valid = np.all(np.isfinite(feature), axis=-1)
    none = np.zeros(valid.shape, dtype=np.bool_)
    return Measurement(feature, None, valid, none, none)


def simulate_line(scenario: LineScenario, seed: int) -> LineSimulatedData:
    """Simulate a straight-seam sweep; deterministic for a given scenario and seed.

    Raises
    ------
    InputError
        If no drawn sweep keeps both flanks in view of every profile.
    """
    rng = np.random.default_rng(seed)
    rig = scenario.rig
    groove = scenario.groove()
    for _ in range(MAX_SWEEP_DRAWS):
        waypoints = sweep_waypoints(scenario, groove, rng.uniform(0.0, 2.0 * math.pi, 5))
        motion = plan_motion(waypoints, rig)
        acq_ns = np.round(motion.shot_times_s() * 1e9).astype(np.int64)
        T_sensor_shot = motion.T_base_sensor(acq_ns / 1e9)
        if _sweep_ok(scenario, groove, np.concatenate([waypoints, T_sensor_shot])) and (
            scenario.determined_sigma_m == 0.0
            or worst_direction_sigma_m(scenario, groove, T_sensor_shot)
            <= scenario.determined_sigma_m
        ):
            break
    else:
        raise InputError(
            f"line scenario {scenario.name!r}: none of {MAX_SWEEP_DRAWS} sweeps keeps both "
            "flanks in view of every profile and determines the hand-eye "
            "(determined_sigma_m); reduce the tilts, yaw_rad or weave_fraction, or widen the "
            "profiler's range or fan"
        )
    errors = draw_errors(rng, rig, len(waypoints))
    t_shot = acq_ns / 1e9
    traced, flank = trace_groove(groove, rig, T_sensor_shot)
    corner_base = groove.seam_point_in_plane(T_sensor_shot)
    corner_sensor = np.einsum(
        "kji,kj->ki", T_sensor_shot[:, :3, :3], corner_base - T_sensor_shot[:, :3, 3]
    )
    measured = (
        _feature_measurement(rng, rig, corner_sensor, traced.points_sensor, flank, traced.seen)
        if scenario.feature_points
        else measure(rng, rig, traced)
    )
    poses = recorded_pose_stream(rng, rig, motion, errors, stamp_jitter_s=scenario.stamp_jitter_s)
    stamps, profiles, intensities = published_profiles(rig, acq_ns, measured)
    truth = LineTruth(
        scenario=scenario,
        seed=seed,
        T_flange_sensor=rig.T_flange_sensor,
        line_point=line_nearest_origin(groove.point, groove.seam),
        line_direction=groove.seam.copy(),
        T_base_flange_true=T_sensor_shot @ invert_transform(rig.T_flange_sensor),
        T_base_flange_recorded=reported_flange(motion, rig, errors, t_shot),
        stamps_ns=stamps,
        acquisition_stamps_ns=rig.epoch_ns + acq_ns,
        T_base_sensor_waypoints=waypoints,
        corner_true_sensor=corner_sensor,
        corner_true_base=corner_base,
    )
    return LineSimulatedData(profiles, intensities, poses, truth)


def _line_rig() -> Scenario:
    return replace(
        WELD_PRESETS["weld_seam"].rig,
        name="line",
        motion="continuous",
        n_poses=60,
        resolution=200,
        organised=False,
        intensity=False,
        robot_sigma_translation_m=2e-5,
        robot_sigma_rotation_rad=math.radians(0.002),
        robot_rate_hz=250.0,
        profile_rate_hz=25.0,
        move_speed_m_s=0.1,
        move_angular_speed_rad_s=1.0,
        latency_s=0.012,
    )


#: The faces the ridge's profiler carries beside its own shape error (the ``shape`` face's x
#: scale would replace the ``scales`` face's).
RIDGE_FACES = ("grazing", "gaps", "scales")


def _ridge() -> LineScenario:
    """A ridge on a block seen by an SSZN-class profiler with every face of reality."""
    spec = PROFILERS["sszn_fanuc"]
    rig = replace(
        _line_rig(),
        name="line_ridge",
        **profiler_fields(replace(spec, model=with_faces(spec.model, *RIDGE_FACES))),
        n_poses=8,
        max_incidence_rad=math.radians(88.0),
        camera_baseline_m=0.0,
        spike_fraction=0.0,
        dropout_fraction=0.0,
        robot_sigma_translation_m=3e-5,
        robot_sigma_rotation_rad=math.radians(0.005),
        profile_rate_hz=5.0,
        move_speed_m_s=0.05,
    )
    middle = 0.5 * (rig.z_min_m + rig.z_max_m)
    return LineScenario(
        name="line_ridge",
        rig=rig,
        opening_angle_rad=math.radians(85.0),
        ridge=True,
        flank_turn_rad=math.radians(32.5),
        flank_width_m=0.06,
        second_flank_width_m=0.02,
        floor_width_m=0.01,
        view_tilt_rad=math.radians(15.0),
        sweep_half_length_m=0.04,
        weaves=1.5,
        weave_fraction=0.35,
        depth_range_m=(rig.z_min_m + 0.004, middle - 0.004),
        tilt_along_rad=math.radians(26.0),
        tilt_across_rad=math.radians(8.0),
        yaw_rad=math.radians(29.0),
        stamp_jitter_s=2.5e-4,
        min_flank_points=15,
        determined_sigma_m=9e-4,
    )


#: Named straight-seam scenarios; see the module docstring and :func:`line_scenario_from_preset`.
LINE_PRESETS: dict[str, LineScenario] = {
    "line": LineScenario(name="line", rig=_line_rig(), stamp_jitter_s=2.5e-4),
    "line_features": LineScenario(
        name="line_features",
        rig=replace(_line_rig(), name="line_features"),
        stamp_jitter_s=2.5e-4,
        feature_points=True,
    ),
    "line_ridge": _ridge(),
}


def line_scenario_from_preset(name: str, **overrides: Any) -> LineScenario:
    """A line preset with fields replaced; rig (:class:`Scenario`) fields are accepted too.

    Raises
    ------
    InputError
        For an unknown preset or field, or an invalid value.
    """
    return rig_scene_from_preset(LINE_PRESETS, name, "line", overrides)
