"""User settings -> the pipeline's configuration: the one place that builds a
:class:`~linelaser_calib.core.pipeline.PipelineConfig` (or a target's config) from what a user
gave, for the command line, both nodes, the planner and the demo.

One table (:data:`SETTINGS`) names every user setting as a command-line flag and as a node
parameter. The core names a setting in its messages by a neutral placeholder,
``{setting:radius_m}`` (:func:`~linelaser_calib.core.settings_text.setting`); each front end
renders its own spelling with :func:`render` (``--radius`` on the command line, ``radius``
for a node), so a node's user is never told to pass a flag.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from enum import Enum
from typing import Any

import numpy as np

from linelaser_calib.core.pairing import PairingConfig
from linelaser_calib.core.pipeline import Method, PipelineConfig
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.selfcheck import DEFAULT_ARM_ACCURACY_M
from linelaser_calib.core.settings_text import PLACEHOLDER
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import SETTINGS as TARGET_SETTINGS
from linelaser_calib.core.targets.base import configure
from linelaser_calib.core.thinning import DEFAULT_PER_NEIGHBOURHOOD
from linelaser_calib.core.types import FloatArray
from linelaser_calib.core.verdict import judge


class Front(Enum):
    """Who the user is talking to: the command line or a ROS node (its parameters)."""

    CLI = "cli"
    NODE = "node"


@dataclass(frozen=True)
class Setting:
    """A user setting and how each front end spells it.

    Attributes
    ----------
    name : str
        The setting's neutral name: a target's shared setting
        (:data:`~linelaser_calib.core.targets.base.SETTINGS`) or another setting of the run.
    flag : str
        The command-line spelling (with a metavar where a refusal should show one).
    parameter : str or None
        The node parameter (with the node's name where only one node has it); None where no
        node takes the setting (a node's user is then told the neutral name).
    """

    name: str
    flag: str
    parameter: str | None


#: Every user setting a message may name: its command-line flag and its node parameter.
SETTINGS: tuple[Setting, ...] = (
    Setting("target", "--target", "target"),
    Setting("method", "--method", "method"),
    Setting("radius_m", "--radius", "radius"),
    Setting("point_m", "--point x,y,z", "known_point"),
    Setting("centre_side", "--centre-side", None),
    Setting("sensor_sigma_m", "--sensor-sigma", None),
    Setting("robot_sigma_t_m", "--robot-sigma-t", None),
    Setting("robot_sigma_r_rad", "--robot-sigma-r", None),
    Setting("min_samples", "--min-samples", "min_samples"),
    Setting("scale", "--scale", "scale"),
    Setting("initial", "--initial FILE.yaml", "initial_hand_eye_path"),
    Setting("clock_offset_s", "--clock-offset", "the collector's clock_offset_s"),
    Setting("sync_tolerance_s", "--sync-tolerance", "the collector's sync_tolerance_s"),
    Setting("max_linear_speed_m_s", "--max-speed", "the collector's max_linear_speed_m_s"),
    Setting(
        "max_angular_speed_rad_s", "--max-angular-speed", "the collector's max_angular_speed_rad_s"
    ),
    Setting("kinematics", "--kinematics", "kinematics"),
    Setting("nominal_kinematics", "--nominal-kinematics", None),
    Setting("arm_accuracy_m", "--arm-accuracy", "arm_accuracy"),
    Setting("per_neighbourhood", "--per-neighbourhood", "per_neighbourhood"),
    Setting("pose_source", "--pose-source", "the collector's pose_source"),
    Setting("base_frame", "--base-frame", "base_frame"),
    Setting("flange_frame", "--flange-frame", "flange_frame"),
    Setting("axial_range_m", "--axial-range", "plan_axial_range"),
    Setting("from_result", "--from RESULT.yaml", None),
    Setting("cylinder_placement", "--cylinder", None),
    Setting("sphere_placement", "--sphere", None),
)

_BY_NAME = {s.name: s for s in SETTINGS}


def spelling(name: str, front: Front) -> str:
    """How ``front`` names the setting ``name`` (the neutral name where it has no spelling)."""
    setting = _BY_NAME.get(name)
    if setting is None:
        return name
    if front is Front.CLI:
        return setting.flag
    return setting.parameter or name


def labels(front: Front) -> dict[str, str]:
    """Every setting's spelling for ``front``, by name (for
    :func:`~linelaser_calib.core.targets.base.configure`'s refusals)."""
    return {s.name: spelling(s.name, front) for s in SETTINGS}


def render(text: str, front: Front) -> str:
    """``text`` with each ``{setting:NAME}`` placeholder spelled for ``front``; on the
    command line a flag's metavar is left out in running text (``--initial``)."""

    def one(match: re.Match[str]) -> str:
        word = spelling(match.group(1), front)
        return word.split(" ")[0] if front is Front.CLI else word

    return re.sub(PLACEHOLDER, one, text)


def render_warnings(result: CalibrationResult, front: Front) -> None:
    """Spell the settings named in the result's warnings for ``front`` (in place), and judge
    its verdict (``result.verdict``, spelled for ``front`` too) with every warning in, before
    the result is shown or written."""
    result.warnings[:] = [render(warning, front) for warning in result.warnings]
    verdict = judge(result)
    result.verdict = replace(
        verdict, reason=render(verdict.reason, front), next_step=render(verdict.next_step, front)
    )


def target_config(target_name: str, method: str, given: Mapping[str, Any], front: Front) -> Any:
    """The target's config with the shared settings the user gave (refusing one that does
    not act, spelled for ``front``).

    Raises
    ------
    InputError
        An unknown target, a setting that does not act on it with ``method``, or a missing
        one the method needs.
    """
    return configure(get_target(target_name), method, given, labels(front))


def pipeline_config(
    target_name: str,
    method: Method,
    given: Mapping[str, Any],
    front: Front,
    *,
    seed: int = 0,
    pairing: PairingConfig | None = None,
    workers: int = 1,
    arm_accuracy_m: float = DEFAULT_ARM_ACCURACY_M,
    per_neighbourhood: int = DEFAULT_PER_NEIGHBOURHOOD,
) -> PipelineConfig:
    """The pipeline configuration from the user's settings.

    Parameters
    ----------
    target_name : str
        A registered target.
    method : Method
    given : mapping of str to value
        Only the shared target settings the user gave (SI units; ``initial`` the initial
        hand-eye (4, 4), which the pipeline configuration holds too).
    front : Front
        Whose spelling the refusals use.
    seed : int
    pairing : PairingConfig, optional
        Default: the pairing defaults.
    workers : int
        Processes for the per-sample work.
    arm_accuracy_m : float
        Prior 1σ per axis of the robot's error common to the whole scanned workspace, m.
    per_neighbourhood : int
        Most samples kept per neighbourhood of flange poses
        (:mod:`~linelaser_calib.core.thinning`); 0 keeps every sample.

    Raises
    ------
    InputError
        As :func:`target_config`.
    """
    target = get_target(target_name)
    initial = given.get("initial")
    return PipelineConfig(
        method=method,
        target=target.name,
        target_config=configure(target, method.value, given, labels(front)),
        seed=seed,
        pairing=PairingConfig() if pairing is None else pairing,
        initial_T_flange_sensor=None if initial is None else np.asarray(initial),
        workers=workers,
        arm_accuracy_m=arm_accuracy_m,
        per_neighbourhood=per_neighbourhood,
    )


def given_from_parameters(values: Mapping[str, Any]) -> dict[str, Any]:
    """The shared target settings a node's parameter values give (SI units), of those
    among ``values``: ``radius`` 0, ``known_point`` [], ``min_samples`` 0 and ``scale`` ''
    mean "not given". The initial hand-eye is read by the node (its file's messages)."""
    given: dict[str, Any] = {}
    if values.get("radius"):
        given["radius_m"] = float(values["radius"])
    if values.get("known_point"):
        given["point_m"] = np.array(values["known_point"], dtype=np.float64)
    if values.get("min_samples"):
        given["min_samples"] = int(values["min_samples"])
    if values.get("scale"):
        given["scale"] = values["scale"]
    return given


def given_from_arguments(
    args: argparse.Namespace, initial: FloatArray | None = None
) -> dict[str, Any]:
    """The shared target settings the command line's options give (SI units), in the
    table's order, each read from its flag's option (absent or None: not given);
    ``initial`` is the initial hand-eye the command read (its file's messages are the
    command's)."""
    given: dict[str, Any] = {}
    for setting in SETTINGS:
        if setting.name not in TARGET_SETTINGS:
            continue
        if setting.name == "initial":
            value: Any = initial
        else:
            value = getattr(args, setting.flag.split(" ")[0][2:].replace("-", "_"), None)
        if value is not None:
            given[setting.name] = np.array(value) if setting.name == "point_m" else value
    return given
