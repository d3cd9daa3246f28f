"""The calibration service's calibrations without ROS: its parameters -> the pipeline's
configuration, the collector's samples -> the one pipeline
(:func:`~linelaser_calib.core.pipeline.calibrate_paired`, as offline), a joint kinematic
calibration of the collector's session, and the live clock offset in the result. The node
(:mod:`.calibration_service`) wires them."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from linelaser_calib.core.errors import CalibrationError, InputError
from linelaser_calib.core.pairing import NS_PER_S, PairingConfig
from linelaser_calib.core.pipeline import Method, PipelineConfig, calibrate_paired
from linelaser_calib.core.pose_source import PoseSource
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.joint_calibration import JointCalibrationConfig
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import placement_adviser
from linelaser_calib.core.types import FlangePose, Sample
from linelaser_calib.io.bags import JOINT_STATE_TYPE, bag_info, read_joint_states
from linelaser_calib.io.initial import read_initial_hand_eye
from linelaser_calib.nodes.clock_offset import DRIFT_FLOOR_S, pairing_of_message
from linelaser_calib.nodes.joint_state_input import live_kinematic_model
from linelaser_calib.offline import Recording, bag_samples, calibrate_bag
from linelaser_calib.settings import Front, given_from_parameters
from linelaser_calib.settings import pipeline_config as settings_pipeline_config


def pipeline_config(
    values: dict[str, Any], warn: Callable[[str], None] = lambda line: None
) -> PipelineConfig:
    """The pipeline configuration from the parameter values in effect (by name).

    ``radius`` 0, ``known_point`` [], ``min_samples`` 0, ``scale`` '' and
    ``initial_hand_eye_path`` '' mean "not given"; a given one that does not act on the
    target and method is refused. ``warn`` receives one line per value of the initial
    hand-eye that was normalised.

    Raises
    ------
    CalibrationError
        ``initial_hand_eye_path`` cannot be read as a result file, a setting does not apply,
        or the method needs a setting that is not given (e.g. paper with known_point).
    """
    settings: dict[str, Any] = {}
    if values["initial_hand_eye_path"]:
        try:
            initial, warnings = read_initial_hand_eye(values["initial_hand_eye_path"])
        except CalibrationError as err:
            raise type(err)(
                f"cannot use initial_hand_eye_path: {err} (or set it to '' for none)"
            ) from err
        for line in warnings:
            warn(f"initial_hand_eye_path: {line}")
        settings["initial"] = initial
    settings.update(given_from_parameters(values))
    return settings_pipeline_config(
        values["target"],
        Method(values["method"]),
        settings,
        Front.NODE,
        seed=values["seed"],
        arm_accuracy_m=float(values["arm_accuracy"]),
        per_neighbourhood=int(values["per_neighbourhood"]),
    )


def calibrate_live(
    samples: list[Sample],
    clock_offset: list[float],
    values: dict[str, Any],
    warn: Callable[[str], None] = lambda line: None,
) -> CalibrationResult:
    """The calibration of the collector's samples: the one pipeline's
    :func:`~linelaser_calib.core.pipeline.calibrate_paired`, as offline, with the collector's
    pairing (from its ``linelaser_calib/clock_offset`` message, ``clock_offset``) and the
    flange poses of the samples as the pose stream (the collector keeps no other): the result
    carries the pairing, and the test of a clock offset left out runs where the samples lie
    within the sync tolerance of each other (a continuous scan). Without the collector's
    pairing neither is known.

    Raises
    ------
    CalibrationError
        As :func:`pipeline_config` and the pipeline.
    """
    config = pipeline_config(values, warn)
    pairing = pairing_of_message(clock_offset)
    if pairing is None:
        return calibrate_paired(samples, None, config)
    shift_ns = round(pairing.clock_offset_s * NS_PER_S)
    poses = [
        FlangePose(s.stamp_ns + shift_ns, s.T_base_flange, values["base_frame"]) for s in samples
    ]
    return calibrate_paired(samples, poses, replace(config, pairing=pairing))


def calibrate_session(
    session: str | None, values: dict[str, Any], warn: Callable[[str], None] = lambda line: None
) -> CalibrationResult:
    """The joint kinematic + hand-eye calibration of the collector's session (the
    ``kinematics`` parameter set): the offline path on the session bag
    (:func:`~linelaser_calib.offline.calibrate_bag`), the flange poses the model's forward
    kinematics of the joint states the collector stored with each sample.

    Raises
    ------
    CalibrationError
        No session known, a session without joint states, an unusable model, or what the
        calibration itself refuses.
    """
    model_spec = str(values["kinematics"])
    if session is None:
        raise InputError(
            f"kinematics is {model_spec!r}, so the calibration reads the collector's session, "
            "but no collector has announced one: start the collector (pose_source "
            "joint_states) and scan the target"
        )
    if not any(t.msgtype == JOINT_STATE_TYPE for t in bag_info(session).topics):
        raise InputError(
            f"kinematics is {model_spec!r} but the session {session} holds no joint states: "
            "run the collector with pose_source joint_states (it stores each sample's joint "
            "vector), or set kinematics to '' for the hand-eye alone"
        )
    model = live_kinematic_model(model_spec, values["base_frame"], values["flange_frame"])
    recording = Recording(
        session,
        pose_source=PoseSource.JOINT_STATES,
        base_frame=values["base_frame"],
        flange_frame=values["flange_frame"],
        model=model,
    )
    run = calibrate_bag(
        recording, pipeline_config(values, warn), kinematic_calibration=JointCalibrationConfig()
    )
    return run.result


def session_placement_advice(
    session: str | None, values: dict[str, Any], result: CalibrationResult | None
) -> str:
    """``~/plan`` with ``kinematics`` set: whether another placement of the cylinder would
    determine more of the robot's kinematics, from the session's samples and joint states
    and the last calibration (its cylinder and corrections); a clause saying what is
    missing otherwise."""
    adviser = None if result is None else placement_adviser(get_target(result.target.key))
    placement = None if result is None or adviser is None else adviser.placement_of(result.target)
    if result is None or adviser is None or placement is None:
        return "placements: calibrate the cylinder first to learn how many are needed"
    if session is None or not any(t.msgtype == JOINT_STATE_TYPE for t in bag_info(session).topics):
        return "placements: the session holds no joint states (collector pose_source joint_states)"
    model = live_kinematic_model(
        str(values["kinematics"]), values["base_frame"], values["flange_frame"]
    )
    if result.kinematics is not None:
        model = result.kinematics.apply(model)
    samples = bag_samples(session, PairingConfig())
    states = read_joint_states(session)
    return "placements: " + adviser.advise(
        [(samples, states, placement)], model, result.T_flange_sensor
    )


def add_live_clock_offset(
    result: CalibrationResult, used_s: float, estimate_s: float, sigma_s: float
) -> None:
    """Put the collector's clock offsets in the result (NaN: no estimate, or no 1σ yet).

    ``used_s`` is what the collector added to the profile stamps when pairing. A warning
    says so when the live estimate disagrees with it by more than three sigma and
    ``DRIFT_FLOOR_S``: the samples were then paired with poses from the wrong moment.
    """
    result.clock_offset_s = used_s
    if math.isnan(estimate_s):
        return
    result.clock_offset_live_s = estimate_s
    result.clock_offset_live_sigma_s = None if math.isnan(sigma_s) else sigma_s
    if math.isnan(sigma_s) or abs(estimate_s - used_s) <= max(3.0 * sigma_s, DRIFT_FLOOR_S):
        return
    result.warnings.append(
        f"the collector estimates the profile-to-pose clock offset live at "
        f"{estimate_s * 1e3:+.2f} +- {sigma_s * 1e3:.2f} ms (1 sigma) but paired the samples "
        f"with {used_s * 1e3:+.2f} ms: set the collector's clock_offset_s to "
        f"{estimate_s:.4f} and collect again"
    )
