"""Public entry of the simulator: :func:`simulate` a scenario into profiles, poses and truth."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Generic, Protocol, TypeVar

import numpy as np

from linelaser_calib.core.geometry import invert_transform
from linelaser_calib.core.robot.kinematics import JointStates
from linelaser_calib.core.targets.cylinder.model import Cylinder
from linelaser_calib.core.types import BoolArray, FlangePose, FloatArray, Profile
from linelaser_calib.sim.arm import Arm, plan_arm
from linelaser_calib.sim.clutter import (
    camera_effects,
    clustered_poses,
    clutter_rng,
    field_errors,
    has_camera_effects,
    profile_sigma_factors,
    scene_from_scenario,
)
from linelaser_calib.sim.poses import sample_sensor_poses
from linelaser_calib.sim.profiler import Measurement, Trace, measure, trace
from linelaser_calib.sim.robot import (
    Motion,
    StepMotion,
    draw_errors,
    jitter_transforms,
    plan_motion,
    reported_flange,
    true_flange,
)
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.scene import Int8Array, Int64Array


@dataclass(frozen=True, eq=False)
class SimulationTruth:
    """Ground truth of a simulated run.

    Per-shot arrays have one row per profile (K profiles); per-ray arrays are organised
    (K, N = resolution) whatever the output format: for dense output, profile k's points
    are the rows of ray ``valid[k]``.

    Attributes
    ----------
    scenario : Scenario
    seed : int
    T_flange_sensor : ndarray, shape (4, 4)
        The true hand-eye.
    cylinder : Cylinder
        The true cylinder axis (point closest to the base origin) and radius; its finite
        extent is ``scenario.cylinder_base_m`` + [0, ``scenario.cylinder_length_m``] along
        the axis.
    T_base_flange_true : ndarray, shape (K, 4, 4)
        True flange pose at each profile's acquisition time.
    T_base_flange_recorded : ndarray, shape (K, 4, 4)
        What the robot reports at the acquisition time, without per-message jitter
        (true · E_sys · E; with an arm, nominal forward kinematics).
    stamps_ns : ndarray of int64, shape (K,)
        Profile stamps as published (acquisition + latency).
    acquisition_stamps_ns : ndarray of int64, shape (K,)
        True acquisition times.
    T_base_sensor_waypoints : ndarray, shape (M, 4, 4)
        The sampled sensor poses (the shots in step-and-shoot).
    waypoint_kinds : tuple of str
        ``long``, ``short`` or ``general`` per waypoint.
    waypoint_cut_angles_rad : ndarray, shape (M,)
        Angle between each waypoint's laser plane and the cylinder cross-section, rad.
    surface : ndarray of int8, shape (K, N)
        :class:`~linelaser_calib.sim.scene.Surface` hit by each ray (before gates).
    points_true_sensor : ndarray, shape (K, N, 3)
        Noise-free hit points in the sensor frame, m (NaN: no hit).
    valid, spike, dropout : ndarray of bool, shape (K, N)
        Ray returned a point; that point is a reflection spike; the ray was dropped at
        random.
    arm : Arm or None
        With ``scenario.robot_model``: the nominal and true kinematics and the waypoint
        joint vectors.
    joint_positions : ndarray, shape (K, n), or None
        With an arm: the joint vector at each profile's acquisition time (rad).
    sigma_factor : ndarray, shape (K,), or None
        Each profile's noise as a multiple of the scenario's sigmas (None: all 1).
    field_offset_sensor_m : ndarray, shape (M, 3), or None
        The robot error field's offset at each waypoint (each shot in step-and-shoot), in
        the sensor frame, m (None: no field). See :mod:`~linelaser_calib.sim.clutter`.
    """

    scenario: Scenario
    seed: int
    T_flange_sensor: FloatArray
    cylinder: Cylinder
    T_base_flange_true: FloatArray
    T_base_flange_recorded: FloatArray
    stamps_ns: Int64Array
    acquisition_stamps_ns: Int64Array
    T_base_sensor_waypoints: FloatArray
    waypoint_kinds: tuple[str, ...]
    waypoint_cut_angles_rad: FloatArray
    surface: Int8Array
    points_true_sensor: FloatArray
    valid: BoolArray
    spike: BoolArray
    dropout: BoolArray
    arm: Arm | None = None
    joint_positions: FloatArray | None = None
    sigma_factor: FloatArray | None = None
    field_offset_sensor_m: FloatArray | None = None


@dataclass(frozen=True, eq=False)
class SimulatedData:
    """Everything a simulated run produces.

    Attributes
    ----------
    profiles : list of Profile
        One per shot, in stamp order; organised (NaN rows kept) or dense per the scenario.
    intensities : list of (ndarray or None)
        Per profile, intensities (rows aligned with the profile's points), or None.
    poses : list of FlangePose
        The full reported flange-pose stream, sorted by stamp.
    truth : SimulationTruth
    joint_states : JointStates or None
        With an arm: the joint-state stream, at the stamps of the flange poses.
    """

    profiles: list[Profile]
    intensities: list[FloatArray | None]
    poses: list[FlangePose]
    truth: SimulationTruth
    joint_states: JointStates | None = None

    @property
    def scenario(self) -> Scenario:
        """The scenario simulated (topics and frame names included)."""
        return self.truth.scenario


def stream_times_ns(scenario: Scenario, motion: Motion) -> Int64Array:
    """Times (ns from the first) of the robot's messages at ``robot_rate_hz``, shape (K,)."""
    period_ns = max(1, round(1e9 / scenario.robot_rate_hz))
    n_stream = int(np.floor(motion.duration_s * 1e9 / period_ns)) + 1
    return np.arange(n_stream, dtype=np.int64) * period_ns


def recorded_pose_stream(
    rng: np.random.Generator,
    scenario: Scenario,
    motion: Motion,
    errors: FloatArray,
    arm: Arm | None = None,
    stamp_jitter_s: float = 0.0,
) -> list[FlangePose]:
    """The robot's flange-pose stream at ``robot_rate_hz`` over the whole motion.

    Each message is the reported pose (without an arm: the true pose with the shot's error
    ``errors``; with one: the nominal forward kinematics) times a per-message jitter,
    stamped on the pose clock from ``epoch_ns``. With ``stamp_jitter_s`` (s, 1σ) each stamp
    misses the instant the pose was taken by a Gaussian error, as when a driver stamps
    messages on arrival (the stamps are kept in order).
    """
    stream_ns = stream_times_ns(scenario, motion)
    if arm is None:
        stream = reported_flange(motion, scenario, errors, stream_ns / 1e9)
    else:
        stream = arm.reported_flange(motion, stream_ns / 1e9)
    stream = stream @ jitter_transforms(rng, scenario, len(stream_ns))
    if stamp_jitter_s > 0.0:
        late = np.round(rng.normal(size=len(stream_ns)) * stamp_jitter_s * 1e9).astype(np.int64)
        stream_ns = np.sort(stream_ns + late)
    return [
        FlangePose(int(scenario.epoch_ns + s), T, frame_id=scenario.base_frame)
        for s, T in zip(stream_ns, stream, strict=True)
    ]


def joint_state_stream(scenario: Scenario, motion: Motion, arm: Arm) -> JointStates:
    """The arm's joint states at the stamps of the flange-pose stream."""
    stream_ns = stream_times_ns(scenario, motion)
    return JointStates(
        arm.nominal.joint_names,
        scenario.epoch_ns + stream_ns,
        arm.joint_positions(motion, stream_ns / 1e9),
    )


def published_profiles(
    scenario: Scenario, acq_ns: Int64Array, measured: Measurement
) -> tuple[Int64Array, list[Profile], list[FloatArray | None]]:
    """Profile stamps (acquisition + latency), profiles and intensities as published.

    Organised profiles keep every ray (NaN when invalid); dense ones keep the valid rays.
    """
    stamps = scenario.epoch_ns + acq_ns + round(scenario.latency_s * 1e9)
    profiles, intensities = [], []
    for k in range(len(acq_ns)):
        keep = slice(None) if scenario.organised else measured.valid[k]
        profiles.append(
            Profile(int(stamps[k]), measured.points[k][keep], frame_id=scenario.sensor_frame)
        )
        intensities.append(None if measured.intensity is None else measured.intensity[k][keep])
    return stamps, profiles, intensities


class _RigScene(Protocol):
    @property
    def rig(self) -> Scenario: ...


class _RigTruth(Protocol):
    @property
    def scenario(self) -> _RigScene: ...


TruthT = TypeVar("TruthT", bound=_RigTruth)


@dataclass(frozen=True, eq=False)
class RigSimulatedData(Generic[TruthT]):
    """Everything a run of a scene with a rig produces (weld seam, sphere); the same layout
    as :class:`SimulatedData`.

    Attributes
    ----------
    profiles : list of Profile
    intensities : list of (ndarray or None)
    poses : list of FlangePose
        The full reported flange-pose stream, sorted by stamp.
    truth : the scene's truth record
        Its ``scenario.rig`` is the :class:`Scenario` of profiler, robot, topics and frames.
    """

    profiles: list[Profile]
    intensities: list[FloatArray | None]
    poses: list[FlangePose]
    truth: TruthT

    @property
    def scenario(self) -> Scenario:
        """The rig (topics, frame names, output format), as ``SimulatedData.scenario``."""
        return self.truth.scenario.rig


@dataclass(frozen=True, eq=False)
class ShotRun:
    """A step-and-shoot run through given sensor poses (K shots of N rays).

    Attributes
    ----------
    acquisition_ns : ndarray of int64, shape (K,)
        Acquisition times from the start of the stream, ns.
    T_base_sensor : ndarray, shape (K, 4, 4)
        True sensor poses at the shots.
    T_base_flange_true, T_base_flange_recorded : ndarray, shape (K, 4, 4)
        True and reported (without jitter) flange poses at the shots.
    traced : Trace
    measured : Measurement
    poses : list of FlangePose
        The reported flange-pose stream.
    stamps_ns : ndarray of int64, shape (K,)
        Profile stamps as published.
    profiles : list of Profile
    intensities : list of (ndarray or None)
    """

    acquisition_ns: Int64Array
    T_base_sensor: FloatArray
    T_base_flange_true: FloatArray
    T_base_flange_recorded: FloatArray
    traced: Trace
    measured: Measurement
    poses: list[FlangePose]
    stamps_ns: Int64Array
    profiles: list[Profile]
    intensities: list[FloatArray | None]


def step_and_shoot(
    rng: np.random.Generator,
    rig: Scenario,
    views: FloatArray,
    trace_views: Callable[[FloatArray], Trace],
) -> ShotRun:
    """Move step-and-shoot through sensor poses (M, 4, 4), scan with ``trace_views`` (sensor
    poses (K, 4, 4) to noise-free returns), add the rig's noise and robot errors, publish.

    Draws from ``rng`` in a fixed order: robot errors, measurement noise, pose stream.
    """
    motion = StepMotion.plan(views, rig)
    errors = draw_errors(rng, rig, len(views))
    acq_ns = np.round(motion.shot_times_s() * 1e9).astype(np.int64)
    t_shot = acq_ns / 1e9
    T_sensor_shot = motion.T_base_sensor(t_shot)
    traced = trace_views(T_sensor_shot)
    measured = measure(rng, rig, traced)
    poses = recorded_pose_stream(rng, rig, motion, errors)
    stamps, profiles, intensities = published_profiles(rig, acq_ns, measured)
    return ShotRun(
        acquisition_ns=acq_ns,
        T_base_sensor=T_sensor_shot,
        T_base_flange_true=T_sensor_shot @ invert_transform(rig.T_flange_sensor),
        T_base_flange_recorded=reported_flange(motion, rig, errors, t_shot),
        traced=traced,
        measured=measured,
        poses=poses,
        stamps_ns=stamps,
        profiles=profiles,
        intensities=intensities,
    )


def simulate(scenario: Scenario, seed: int) -> SimulatedData:
    """Simulate a calibration run; deterministic for a given scenario and seed.

    Parameters
    ----------
    scenario : Scenario
    seed : int
        Seed of the single ``numpy.random.Generator`` used for every random draw.

    Raises
    ------
    InputError
        If the scenario admits too few feasible sensor poses.
    """
    rng = np.random.default_rng(seed)
    extra = clutter_rng(seed)
    scene = scene_from_scenario(scenario)
    arm = plan_arm(rng, scenario, scene) if scenario.robot_model else None
    if arm is not None:
        sampled = arm.sampled
    elif scenario.pose_clusters:
        centres = sample_sensor_poses(rng, replace(scenario, n_poses=scenario.pose_clusters), scene)
        sampled = clustered_poses(extra, scenario, centres)
    else:
        sampled = sample_sensor_poses(rng, scenario, scene)
    motion = plan_motion(sampled.T_base_sensor, scenario)
    errors = draw_errors(rng, scenario, len(sampled.T_base_sensor))
    offsets: FloatArray | None = None
    if any(scenario.robot_field_m):
        translation, offsets = field_errors(extra, scenario, sampled.T_base_sensor)
        errors[:, :3] += translation

    acq_ns = np.round(motion.shot_times_s() * 1e9).astype(np.int64)
    t_shot = acq_ns / 1e9
    if arm is None:
        T_sensor_shot = motion.T_base_sensor(t_shot)
        T_flange_true = true_flange(motion, scenario, t_shot)
        T_flange_recorded = reported_flange(motion, scenario, errors, t_shot)
    else:
        T_flange_true = arm.true_flange(motion, scenario, errors, t_shot)
        T_sensor_shot = T_flange_true @ scenario.T_flange_sensor
        T_flange_recorded = arm.reported_flange(motion, t_shot)
    traced = trace(scene, scenario, T_sensor_shot)
    measured = measure(rng, scenario, traced)
    sigma_factor: FloatArray | None = None
    if has_camera_effects(scenario):
        sigma_factor = profile_sigma_factors(extra, scenario, len(t_shot))
        measured = camera_effects(
            scenario, traced, measured, sigma_factor, T_sensor_shot[:, :3, :3]
        )
    poses = recorded_pose_stream(rng, scenario, motion, errors, arm)
    stamps, profiles, intensities = published_profiles(scenario, acq_ns, measured)
    truth = SimulationTruth(
        scenario=scenario,
        seed=seed,
        T_flange_sensor=scenario.T_flange_sensor,
        cylinder=scenario.cylinder(),
        T_base_flange_true=T_flange_true,
        T_base_flange_recorded=T_flange_recorded,
        stamps_ns=stamps,
        acquisition_stamps_ns=scenario.epoch_ns + acq_ns,
        T_base_sensor_waypoints=sampled.T_base_sensor,
        waypoint_kinds=sampled.kinds,
        waypoint_cut_angles_rad=sampled.cut_angles_rad,
        surface=traced.surface,
        points_true_sensor=traced.points_sensor,
        valid=measured.valid,
        spike=measured.spike,
        dropout=measured.dropout,
        arm=arm,
        joint_positions=None if arm is None else arm.joint_positions(motion, t_shot),
        sigma_factor=sigma_factor,
        field_offset_sensor_m=offsets,
    )
    joints = None if arm is None else joint_state_stream(scenario, motion, arm)
    return SimulatedData(profiles, intensities, poses, truth, joints)
