"""The simulator's preset registry: each family of presets, how a run of one of its presets
becomes a recording, and what truth that recording carries.

Each family (cylinder scenes, weld seams, spheres, straight seams) knows the result section
of its own truth, so the bag writer (:mod:`~linelaser_calib.sim.bag_writer`) and the demo
ask this registry and never a scene's kind.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.robot.kinematics import JointStates
from linelaser_calib.core.targets.base import ResultSection
from linelaser_calib.core.targets.cylinder import CylinderSection
from linelaser_calib.core.targets.known_point import KnownPoint
from linelaser_calib.core.targets.line import Line, LineSection
from linelaser_calib.core.targets.sphere import SphereSection
from linelaser_calib.core.types import FlangePose, FloatArray, Profile
from linelaser_calib.sim.arm import Arm
from linelaser_calib.sim.line import LINE_PRESETS, line_scenario_from_preset, simulate_line
from linelaser_calib.sim.presets import PRESETS, scenario_from_preset
from linelaser_calib.sim.scenario import Scenario
from linelaser_calib.sim.simulate import simulate
from linelaser_calib.sim.sphere import SPHERE_PRESETS, simulate_sphere, sphere_scenario_from_preset
from linelaser_calib.sim.weld import WELD_PRESETS, simulate_weld, weld_scenario_from_preset


@dataclass
class SimRecording:
    """One simulated run of a preset, with its truth, ready to be written as a bag.

    Attributes
    ----------
    rig : Scenario
        The sensor and robot set-up (topics, frames, profile layout).
    profiles : list of Profile
        Sensor frame, m.
    intensities : list of (ndarray or None)
        Per profile.
    poses : list of FlangePose
        The reported flange-pose stream.
    T_flange_sensor : ndarray, shape (4, 4)
        The true hand-eye.
    truth : ResultSection
        The true target, as a result file's section.
    initial : ResultSection or None
        The target section of the recording's ``initial.yaml`` (the taught point, the true
        line), for presets whose calibration starts from an old hand-eye; None otherwise.
    arm : Arm or None
        The simulated arm (true and nominal kinematics), for presets with joint states.
    joint_states : JointStates or None
    simulation : dict of str to object
        Further entries of the truth file's ``simulation`` section (SI units).
    """

    rig: Scenario
    profiles: list[Profile]
    intensities: list[FloatArray | None]
    poses: list[FlangePose]
    T_flange_sensor: FloatArray
    truth: ResultSection
    initial: ResultSection | None = None
    arm: Arm | None = None
    joint_states: JointStates | None = None
    simulation: dict[str, object] = field(default_factory=dict)


#: How a preset's run becomes a recording: (preset name, scenario overrides, seed).
Recorder = Callable[[str, dict[str, object], int], SimRecording]


def _cylinder(name: str, overrides: dict[str, object], seed: int) -> SimRecording:
    """A cylinder scene: the true cylinder; with an arm, its joint states."""
    data = simulate(scenario_from_preset(name, **overrides), seed)
    return SimRecording(
        data.scenario,
        data.profiles,
        data.intensities,
        data.poses,
        data.truth.T_flange_sensor,
        CylinderSection(data.truth.cylinder),
        arm=data.truth.arm,
        joint_states=data.joint_states,
    )


def _weld(name: str, overrides: dict[str, object], seed: int) -> SimRecording:
    """A weld seam: the true corner point; ``initial.yaml`` holds the taught point."""
    data = simulate_weld(weld_scenario_from_preset(name, **overrides), seed)
    return SimRecording(
        data.scenario,
        data.profiles,
        data.intensities,
        data.poses,
        data.truth.T_flange_sensor,
        KnownPoint(data.truth.weld_point_m, estimated=False),
        initial=KnownPoint(np.asarray(data.truth.taught_point_m), estimated=False),
        simulation={"taught_point": data.truth.taught_point_m},
    )


def _sphere(name: str, overrides: dict[str, object], seed: int) -> SimRecording:
    """A sphere: its true centre, radius and side of the laser plane."""
    # --radius is the target's radius: the sphere's here.
    own = {"radius_m" if k == "cylinder_radius_m" else k: v for k, v in overrides.items()}
    data = simulate_sphere(sphere_scenario_from_preset(name, **own), seed)
    return SimRecording(
        data.scenario,
        data.profiles,
        data.intensities,
        data.poses,
        data.truth.T_flange_sensor,
        SphereSection(
            data.truth.centre_m,
            data.truth.radius_m,
            data.truth.centre_side,
            radius_estimated=False,
            side_estimated=False,
        ),
    )


def _line(name: str, overrides: dict[str, object], seed: int) -> SimRecording:
    """A straight seam: the true line, also the target of ``initial.yaml``."""
    data = simulate_line(line_scenario_from_preset(name, **overrides), seed)
    section = LineSection(Line(data.truth.line_point, data.truth.line_direction))
    return SimRecording(
        data.scenario,
        data.profiles,
        data.intensities,
        data.poses,
        data.truth.T_flange_sensor,
        section,
        initial=section,
    )


@dataclass(frozen=True)
class PresetFamily:
    """Presets simulated alike: by name, each preset's rig (its set-up and motion), and the
    recorder of a run."""

    rigs: Mapping[str, Scenario]
    record: Recorder


def _rigs(presets: Mapping[str, Any]) -> dict[str, Scenario]:
    """The rig of each preset of a family whose scenarios hold one (``rig`` field)."""
    return {name: scenario.rig for name, scenario in presets.items()}


#: Every family of simulator presets.
FAMILIES: tuple[PresetFamily, ...] = (
    PresetFamily(_rigs(WELD_PRESETS), _weld),
    PresetFamily(_rigs(SPHERE_PRESETS), _sphere),
    PresetFamily(_rigs(LINE_PRESETS), _line),
    PresetFamily(PRESETS, _cylinder),
)


def preset_names() -> list[str]:
    """Every simulator preset, of every family, sorted."""
    return sorted(name for family in FAMILIES for name in family.rigs)


def record(name: str, overrides: dict[str, object], seed: int) -> SimRecording:
    """Simulate the preset ``name`` with scenario ``overrides`` and ``seed``.

    Raises
    ------
    InputError
        An unknown preset (the message lists them all) or a bad override.
    """
    family = next((f for f in FAMILIES if name in f.rigs), None)
    if family is None:
        raise InputError(
            f"unknown scenario preset {name!r}; choose one of {', '.join(preset_names())}"
        )
    return family.record(name, overrides, seed)


def preset_motion(name: object) -> str | None:
    """The motion (``step``, ``continuous``) of a simulator preset; None for another name."""
    if not isinstance(name, str):
        return None
    rig = next((f.rigs[name] for f in FAMILIES if name in f.rigs), None)
    return None if rig is None else rig.motion
