"""Ready-made :class:`~linelaser_calib.sim.scenario.Scenario` values: named presets, random scenes.

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
    and the faces the real scans show (gaps, a scale 0.1 % off;
    :mod:`~linelaser_calib.sim.sensor_models`), see :func:`_real_profiler_scenario`.

Bag size: a streamed pose costs ~120 bytes and a point 12-16 bytes in a rosbag2 MCAP file,
so ``resolution``, ``n_poses``, ``dwell_s``, the move speeds, ``robot_rate_hz`` and
``profile_rate_hz`` set the size; the presets make ~0.8-1.1 MB each before compression.

:func:`random_scenario` draws random scenes for robustness benchmarks.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, fields, replace
from math import radians as _deg
from typing import Any, Protocol, TypeVar

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import project_to_so3, quaternion_xyzw_from_matrix
from linelaser_calib.sim.scenario import Scenario, Vec3
from linelaser_calib.sim.sensor_models import PROFILERS, profiler_fields, sensor_model_from_mapping


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
        Scenario fields to replace (SI units, see :class:`Scenario`); a mapping ``sensor``
        changes only the :class:`~linelaser_calib.sim.sensor_models.SensorModel` fields it
        names.

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
    return replace(PRESETS[name], **_sensor_merged(PRESETS[name], overrides))


def _sensor_merged(rig: Scenario, overrides: Mapping[str, Any]) -> dict[str, Any]:
    """``overrides`` with a mapping ``sensor`` (some :class:`SensorModel` fields) merged into
    the rig's sensor model, so that it changes only the fields it names."""
    sensor = overrides.get("sensor")
    if not isinstance(sensor, Mapping):
        return dict(overrides)
    return {**overrides, "sensor": sensor_model_from_mapping({**asdict(rig.sensor), **sensor})}


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
    rig = (
        replace(preset.rig, **_sensor_merged(preset.rig, rig_overrides))
        if rig_overrides
        else preset.rig
    )
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
