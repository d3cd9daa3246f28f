"""Human-readable text for a calibration result: mm and degrees, each number labelled.

The pieces (:func:`headline_rows`, :func:`hand_eye_rows`, :func:`target_text`,
:func:`residual_rows`, :func:`self_check_rows`, :func:`rejection_lines`, :func:`truth_rows`) are
shared by the text summary of the CLI (:func:`format_summary`), the HTML report and the
calibration service's /diagnostics, so all say the same thing the same way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from linelaser_calib.core.errors import InputError
from linelaser_calib.core.geometry import (
    FloatArray,
    quaternion_xyzw_from_matrix,
    rotation_angle,
    rotvec_from_matrix,
    rpy_from_matrix,
)
from linelaser_calib.core.regions import CHOICE_CONFIDENCE, PER_POSE, PLAIN, ModelChoice
from linelaser_calib.core.result import CalibrationResult
from linelaser_calib.core.robot.kinematics import KinematicCorrections, effective_hand_eye
from linelaser_calib.core.selfcheck import SelfCheck, sigma_at_point, systematic_evidence
from linelaser_calib.core.targets.base import mm_text, rejection_kind
from linelaser_calib.core.types import Level, Rejection, Verdict
from linelaser_calib.core.verdict import WARNINGS_GUIDE, verdict_of, warning_kind
from linelaser_calib.io.results import Truth
from linelaser_calib.settings import Front, spelling

#: How roll, pitch and yaw are defined (ROS, REP 103).
RPY_CONVENTION = "fixed axes x-y-z, R = Rz(yaw) Ry(pitch) Rx(roll)"
#: The axes of the rotation uncertainty and of the per-axis rotation error.
ROTATION_AXES = "small angles about the sensor x, y, z axes"

#: (label, text) pairs of a table.
Rows = list[tuple[str, str]]


def deg_text(values: ArrayLike, digits: int = 4) -> str:
    """``[+1.0000, ...] deg`` from angles in rad."""
    return "[" + ", ".join(f"{np.degrees(v):+.{digits}f}" for v in np.ravel(values)) + "] deg"


def group_rejections(rejections: list[Rejection]) -> list[tuple[str, list[int]]]:
    """(``stage: reason`` of a kind, profile indices) pairs, most frequent first: rejections
    whose reasons differ only in their numbers are one kind
    (:func:`~linelaser_calib.core.targets.base.rejection_kind`)."""
    groups: dict[str, list[int]] = {}
    for r in rejections:
        groups.setdefault(rejection_kind(r), []).append(r.index)
    return sorted(groups.items(), key=lambda kv: (-len(kv[1]), kv[0]))


def one_line_summary(result: CalibrationResult, samples_total: int) -> str:
    """One line describing a calibration, every number with its unit: the verdict
    (:func:`verdict_line`) first.

    Parameters
    ----------
    result : CalibrationResult
    samples_total : int
        Samples handed to the calibration (used + rejected).
    """
    T = result.T_flange_sensor
    t_mm = T[:3, 3] * 1e3
    rpy_deg = np.degrees(rpy_from_matrix(T[:3, :3]))
    text = (
        f"T_flange_sensor ({result.parent_frame} -> {result.child_frame}): "
        f"translation [{t_mm[0]:.3f}, {t_mm[1]:.3f}, {t_mm[2]:.3f}] mm, "
        f"rpy [{rpy_deg[0]:.4f}, {rpy_deg[1]:.4f}, {rpy_deg[2]:.4f}] deg"
    )
    sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
    if sigma_t is not None and sigma_r is not None:
        text += (
            f", 1-sigma (largest axis) {float(np.max(sigma_t)) * 1e3:.4f} mm, "
            f"{float(np.degrees(np.max(sigma_r))):.4f} deg"
        )
    aside = 0 if result.thinning is None else result.thinning.set_aside
    text += (
        f"; {len(result.samples_used)} of {samples_total} samples used"
        + (f" ({aside} set aside as near-duplicates)" if aside else "")
        + f", rms residual {result.rms_residual_m * 1e6:.1f} um, method {result.method}"
    )
    verdict = verdict_of(result)
    if verdict.warning_ids:
        text += f"; warnings: {', '.join(verdict.warning_ids)}"
    return f"{verdict_line(result)} {text}"


def hand_eye_rows(result: CalibrationResult) -> Rows:
    """The hand-eye T_flange_sensor: translation, roll/pitch/yaw, quaternion and 1 sigma."""
    T = result.T_flange_sensor
    rows = [
        ("translation", mm_text(T[:3, 3])),
        ("roll/pitch/yaw", f"{deg_text(rpy_from_matrix(T[:3, :3]))}  ({RPY_CONVENTION})"),
        (
            "rotation_xyzw",
            "[" + ", ".join(f"{v:+.6f}" for v in quaternion_xyzw_from_matrix(T[:3, :3])) + "]",
        ),
    ]
    sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
    if sigma_t is None and sigma_r is None:
        rows.append(("1 sigma", f"not estimated by the {result.method} method"))
    if sigma_t is not None:
        rows.append(("1 sigma translation", f"{mm_text(sigma_t)} (flange x, y, z)"))
    if sigma_r is not None:
        rows.append(("1 sigma rotation", f"{deg_text(sigma_r)} ({ROTATION_AXES})"))
    if result.sigma_budget is not None:
        rows.append(("1 sigma from", result.sigma_budget.text()))
    if result.initial_T_flange_sensor is not None:
        change = truth_error(T, result.initial_T_flange_sensor)
        rows.append(
            (
                "initial corrected by",
                f"{change.translation_m * 1e3:.3f} mm, {np.degrees(change.rotation_rad):.3f} deg "
                f"(the initial hand-eye given: translation {mm_text(change.translation_axes_m)} "
                f"flange x, y, z; rotation {deg_text(change.rotation_axes_rad, 3)} about the "
                "sensor x, y, z axes)",
            )
        )
    depth = result.measuring_centre_depth_m
    if sigma_t is not None and sigma_r is not None and depth is not None:
        at_centre = sigma_at_point(T, sigma_r, sigma_t, np.array([0.0, 0.0, depth]))
        rows.append(
            (
                "1 sigma at centre",
                f"{mm_text(at_centre)} (flange x, y, z) at the measuring centre, "
                f"{depth * 1e3:.1f} mm along the sensor z (mean depth of the points used)",
            )
        )
    return rows


def target_text(result: CalibrationResult) -> str:
    """The target's part of the result (e.g. the fitted cylinder, the known point), base frame."""
    return result.target.describe(result.base_frame)


def residual_kind(result: CalibrationResult) -> str:
    """What the method's residual measures."""
    return result.target.residual_kind(result.method)


#: Percentiles of the per-sample residual shown between its minimum and maximum.
RESIDUAL_PERCENTILES = (25, 50, 75, 95)
#: Samples with the largest residual named in a summary (every one is in the result file).
WORST_SHOWN = 5
#: Widening of the 1σ for the profiles' scatter below which the summary does not mention it.
WIDENING_SHOWN = 1.05


def residual_rows(result: CalibrationResult) -> Rows:
    """RMS residual, the distribution of the per-sample residual and the worst samples by
    profile index, in µm (the full list is the result file's
    ``quality.sample_residuals_m``)."""
    rows = [
        (
            "residual",
            f"rms {result.rms_residual_m * 1e6:.1f} um over {len(result.samples_used)} "
            f"samples used ({residual_kind(result)})",
        )
    ]
    line_noise_text = getattr(result.target, "line_noise_text", None)
    line_noise = None if line_noise_text is None else line_noise_text()
    if line_noise is not None:
        rows.append(("line noise", line_noise))
    if result.sample_residuals_m:
        indices = np.array(list(result.sample_residuals_m))
        values = np.array(list(result.sample_residuals_m.values())) * 1e6
        levels = np.percentile(values, RESIDUAL_PERCENTILES)
        middle = ", ".join(
            f"{'median' if p == 50 else f'{p}%'} {v:.1f}"
            for p, v in zip(RESIDUAL_PERCENTILES, levels, strict=True)
        )
        rows.append(
            (
                "per-sample residual",
                f"min {values.min():.1f}, {middle}, max {values.max():.1f} um",
            )
        )
        worst = np.argsort(-values, kind="stable")[:WORST_SHOWN]
        rows.append(
            (
                "largest residuals",
                ", ".join(f"#{indices[k]} {values[k]:.1f}" for k in worst)
                + " um (profile index; every sample's is in the result file)",
            )
        )
    return rows


def accuracy_text(verdict: Verdict) -> str:
    """The accuracy in use beside a verdict: ``0.0346 mm RMS`` or ``not measured``."""
    if verdict.accuracy_in_use_m is None:
        return "not measured"
    return f"{verdict.accuracy_in_use_m * 1e3:.4f} mm RMS"


def verdict_line(result: CalibrationResult) -> str:
    """The summary's first line: the verdict, the accuracy in use, the deciding reason and
    the next step (:func:`~linelaser_calib.core.verdict.verdict_of`)."""
    verdict = verdict_of(result)
    return (
        f"Verdict: {verdict.level.words.upper()} (accuracy in use {accuracy_text(verdict)}): "
        f"{verdict.reason}. Next: {verdict.next_step}."
    )


def refusal_text(message: str) -> str:
    """The one paragraph of a calibration the data refused: its verdict first, then
    ``message`` (why, and what to do)."""
    return f"refused, no result was written (verdict: {Level.DO_NOT_USE.words}): {message}"


#: Longest warning text shown in a summary line (its whole text is in the result file).
WARNING_SHOWN = 110
#: A warning's words before its first colon stand for it when they are at least this long.
MIN_HEAD = 30


def warning_reference(k: int, warning: str) -> str:
    """Where the ``k``-th warning's whole text is (the result file) and what to do about it
    (its paragraph in the warnings guide, by its stable id)."""
    return f"quality.warnings[{k}]; {WARNINGS_GUIDE}#{warning_kind(warning).id}"


def warning_lines(result: CalibrationResult) -> list[str]:
    """One line per warning: its stable id, its opening words, and where its whole text
    (the result file) and what to do (the guide's paragraph) are."""
    lines = []
    for k, warning in enumerate(result.warnings):
        head = warning.split(": ")[0]
        head = head if len(head) >= MIN_HEAD else warning
        if len(head) > WARNING_SHOWN:
            head = head[:WARNING_SHOWN].rsplit(" ", 1)[0] + " ..."
        kind = warning_kind(warning)
        label = "note" if kind.level is None else "warning"
        lines.append(f"{label} {kind.id}: {head} ({warning_reference(k, warning)})")
    return lines


def headline_rows(result: CalibrationResult) -> Rows:
    """The verdict first (level, accuracy in use, reason, next step), then the hand-eye's
    largest 1 sigma."""
    verdict = verdict_of(result)
    check = result.self_check
    accuracy = accuracy_text(verdict)
    if verdict.not_measured_because:
        accuracy += f": {verdict.not_measured_because}"
    elif check is not None:
        accuracy += (
            f" (quality.accuracy_in_use_m: scan points of each of {check.regions} regions of "
            "the workspace held out in turn, mapped with the recorded poses and a hand-eye "
            "solved without that region)"
        )
    rows = [
        ("verdict", verdict.level.words.upper()),
        ("accuracy in use", accuracy),
        ("why", verdict.reason),
        ("next step", verdict.next_step),
    ]
    sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
    if sigma_t is None or sigma_r is None:
        rows.append(("1 sigma", f"not estimated by the {result.method} method"))
    else:
        rows.append(
            (
                "1 sigma (largest axis)",
                f"{float(np.max(sigma_t)) * 1e3:.4f} mm translation, "
                f"{float(np.degrees(np.max(sigma_r))):.4f} deg rotation",
            )
        )
    return rows


def model_text(model: ModelChoice) -> str:
    """Which robot-error model the accuracy in use chose, and whether the difference between
    the two models is significant (:func:`~linelaser_calib.core.regions.choose_model`)."""
    names = {PER_POSE: "per-pose robot error", PLAIN: "plain fit"}
    figures = ", ".join(
        f"{names[name]} {value * 1e3:.4f} mm" for name, value in model.accuracy_m.items()
    )
    if PLAIN not in model.accuracy_m:
        return (
            f"{names[PER_POSE]} ({figures}; plain fit not tried: the robot error looks "
            "independent per pose)"
        )
    test = f"one-sided paired t-test over the regions at {CHOICE_CONFIDENCE:.0%}"
    if model.chosen == PLAIN:
        return f"plain fit, better beyond chance ({figures}; {test})"
    if model.accuracy_m[PLAIN] < model.accuracy_m[PER_POSE]:
        return (
            f"{names[PER_POSE]} kept: the plain fit's lower figure is not significantly "
            f"better ({figures}; {test})"
        )
    return f"{names[PER_POSE]}, the better of the two ({figures})"


def robot_error_text(check: SelfCheck) -> str:
    """Systematic or independent per pose, with the statistics that show it and those within
    their limits (:func:`~linelaser_calib.core.selfcheck.systematic_evidence`)."""
    evidence = systematic_evidence(check)
    shown = [f"{item.name} {item.value}" for item in evidence if item.shown]
    within = [f"{item.name} {item.value}" for item in evidence if not item.shown]
    offsets = f"held-out offsets {check.offset_rms_m * 1e3:.4f} mm RMS"
    if not check.systematic:
        return f"independent per pose ({offsets}; each within its limit: {', '.join(within)})"
    return (
        "systematic, shown by "
        + (", ".join(shown) if shown else "the halves' disagreement")
        + f" ({offsets}"
        + (f"; within their limits: {', '.join(within)}" if within else "")
        + ")"
    )


def self_check_rows(result: CalibrationResult, front: Front = Front.CLI) -> Rows:
    """The self-check: accuracy in use held out by region, the model it chose, the
    pose-interleaved consistency check, halves, robot error, and the 1σ before widening;
    settings are named as ``front`` spells them."""
    check = result.self_check
    if check is None:
        return []
    poses = "recorded poses" if result.kinematics is None else "corrected kinematics"
    rows = [
        (
            "accuracy in use",
            f"not measured ({check.pose_clusters} pose cluster(s), fewer than 3 regions)"
            if check.accuracy_in_use_m is None
            else f"{check.accuracy_in_use_m * 1e3:.4f} mm RMS (held-out regions of the "
            f"workspace, {check.regions} regions, {poses})",
        ),
    ]
    if check.model is not None:
        rows.append(("model", model_text(check.model)))
    rows += [
        (
            "consistency check",
            f"{check.interleaved_rms_m * 1e3:.4f} mm RMS (pose-interleaved {check.folds}-fold "
            "cross-validation: held-out poses keep neighbours in the fit, so this is not the "
            "accuracy in use)",
        ),
        (
            "halves agreement",
            "not solved apart"
            if check.halves_sigmas is None
            else f"{float(np.max(check.halves_sigmas)):.1f} combined sigma (largest axis, even "
            "vs odd poses)",
        ),
        ("robot error", robot_error_text(check)),
    ]
    widening = check.sigma_widening
    if widening is not None and float(np.max(widening)) > WIDENING_SHOWN:
        rows.append(
            (
                "profile scatter",
                f"leaving one profile out moves the hand-eye up to {float(np.max(widening)):.2f}x "
                "as far as the noise model predicts; the 1 sigma of those axes is widened by "
                f"that (rotation x{'/'.join(f'{v:.2f}' for v in widening[:3])}, translation "
                f"x{'/'.join(f'{v:.2f}' for v in widening[3:])})",
            )
        )
    spread = check.sigma_model_spread
    if spread is not None:
        rows.append(
            (
                "1 sigma model spread",
                f"{mm_text(spread[3:])}, {deg_text(spread[:3])} (another reading of the "
                "profiler's scales that the profiles cannot tell apart moves the hand-eye this "
                "far; added per axis to the statistical 1 sigma, which the checks above use)",
            )
        )
    if check.systematic:
        arm_setting = spelling("arm_accuracy_m", front)
        rows.append(
            (
                "1 sigma noise model",
                f"{mm_text(check.sigma_model[3:])}, {deg_text(check.sigma_model[:3])} (widened "
                "above for the systematic error"
                + (
                    f", with {check.arm_accuracy_m * 1e3:.3f} mm (1 sigma) assumed for the "
                    f"arm's error common to the whole workspace, {arm_setting}"
                    if check.arm_accuracy_m > 0.0
                    else ""
                )
                + ")",
            )
        )
    return rows


def rejection_lines(result: CalibrationResult) -> list[str]:
    """One line per kind of rejection (:func:`group_rejections`): count, reason, stage and
    profile indices (every profile's own reason is in the result file)."""
    lines = []
    for kind, indices in group_rejections(result.samples_rejected):
        stage, reason = kind.split(": ", 1)
        shown = ", ".join(str(i) for i in indices[:12]) + (" ..." if len(indices) > 12 else "")
        count = f"{len(indices)} profile{'s' if len(indices) > 1 else ''}"
        lines.append(f"{count}: {reason} (at {stage}; #{shown})")
    return lines


def samples_line(result: CalibrationResult) -> str:
    """How many profiles were recorded, used, set aside as near-duplicates and rejected."""
    used, rejected = len(result.samples_used), len(result.samples_rejected)
    aside = 0 if result.thinning is None else result.thinning.set_aside
    text = f"Profiles: {used} used of {used + aside + rejected} recorded, {rejected} rejected"
    return text + (f", {aside} set aside as near-duplicates" if aside else "")


@dataclass(frozen=True)
class TruthError:
    """Error of an estimated hand-eye against the truth.

    Attributes
    ----------
    rotation_rad : float
        Angle of R_truthᵀ R_estimate, rad.
    translation_m : float
        Distance between the translations, m.
    rotation_axes_rad : ndarray, shape (3,)
        Rotation vector θ of R_estimate = R_truth · Exp(θ), rad: small angles about the
        sensor axes, as the 1 sigma rotation.
    translation_axes_m : ndarray, shape (3,)
        t_estimate − t_truth in the flange frame, m, as the 1 sigma translation.
    """

    rotation_rad: float
    translation_m: float
    rotation_axes_rad: FloatArray
    translation_axes_m: FloatArray


def truth_error(T_estimate: ArrayLike, T_truth: ArrayLike) -> TruthError:
    """Error of ``T_estimate`` (4, 4) against ``T_truth`` (4, 4), both T_flange_sensor."""
    A = np.asarray(T_estimate, dtype=np.float64)
    B = np.asarray(T_truth, dtype=np.float64)
    delta = B[:3, :3].T @ A[:3, :3]
    offset = A[:3, 3] - B[:3, 3]
    return TruthError(
        rotation_angle(delta), float(np.linalg.norm(offset)), rotvec_from_matrix(delta), offset
    )


def hand_eye_seen(truth: Truth, corrections: KinematicCorrections | None = None) -> FloatArray:
    """The true hand-eye (4, 4) as the calibration's flange poses can see it.

    When the truth file holds the simulated arm's kinematic errors (its ``kinematics``
    section: the true parameters as corrections to the nominal model), flange poses from the
    nominal model (with ``corrections`` applied, for a joint calibration) see the true
    hand-eye moved by the arm's error after its last joint's motion
    (:func:`~linelaser_calib.core.robot.kinematics.effective_hand_eye`), which no scan separates
    from the hand-eye. Otherwise, or when that section cannot be used, the physical one.
    """
    section = truth.raw.get("kinematics")
    if not isinstance(section, dict):
        return truth.T_flange_sensor
    from linelaser_calib.io.kinematics import load_model

    try:
        nominal = load_model(str(section["model"]))
        true = KinematicCorrections(
            nominal.name, {str(k): float(v) for k, v in section["corrections"].items()}
        ).apply(nominal)
        used = nominal if corrections is None else corrections.apply(nominal)
    except (InputError, KeyError, TypeError, ValueError, AttributeError):
        return truth.T_flange_sensor
    return effective_hand_eye(used, true, truth.T_flange_sensor)


def truth_rows(result: CalibrationResult, truth: Truth) -> Rows:
    """The error against the truth (:func:`hand_eye_seen`): totals and per axis, beside the
    1 sigma when known; only between hand-eyes of the same frames (else one row saying why
    not)."""
    ours = (result.parent_frame, result.child_frame)
    theirs = (truth.parent_frame, truth.child_frame)
    if ours != theirs:
        return [
            (
                "not compared",
                f"the result is the hand-eye {ours[0]} -> {ours[1]}, the truth {theirs[0]} -> "
                f"{theirs[1]}: different frames, so their difference is not an error",
            )
        ]
    error = truth_error(result.T_flange_sensor, hand_eye_seen(truth, result.kinematics))
    rows = [
        ("rotation", f"{np.degrees(error.rotation_rad):.4f} deg"),
        ("translation", f"{error.translation_m * 1e3:.4f} mm"),
        ("rotation per axis", f"{deg_text(error.rotation_axes_rad)} ({ROTATION_AXES})"),
        ("translation per axis", f"{mm_text(error.translation_axes_m)} (flange x, y, z)"),
    ]
    depth = result.measuring_centre_depth_m
    if depth is not None:
        # Where the points are: the measuring centre mapped by both hand-eyes.
        centre = np.array([0.0, 0.0, depth, 1.0])
        moved = (result.T_flange_sensor - hand_eye_seen(truth, result.kinematics)) @ centre
        rows.append(
            (
                "at the points",
                f"{np.linalg.norm(moved[:3]) * 1e3:.4f} mm (at the measuring centre, "
                f"{depth * 1e3:.1f} mm along the sensor z; the translation above is the "
                "sensor origin's)",
            )
        )
    sigma_t, sigma_r = result.uncertainty_translation_m, result.uncertainty_rotation_rad
    if sigma_t is not None and sigma_r is not None:
        ratios = np.abs(
            np.concatenate([error.rotation_axes_rad / sigma_r, error.translation_axes_m / sigma_t])
        )
        rows.append(("largest error/sigma", f"{ratios.max():.2f} (per axis, |error| / 1 sigma)"))
    return rows


def format_summary(
    result: CalibrationResult, truth: Truth | None = None, preamble: Sequence[str] = ()
) -> str:
    """Multi-line summary a person can act on: the verdict first, then one line per warning
    (its whole text is in the result file), then the numbers.

    Parameters
    ----------
    result : CalibrationResult
    truth : Truth, optional
        When given (simulated bags), the error against it is printed too.
    preamble : sequence of str
        Lines shown after the verdict and the warnings (what was calibrated).
    """

    def table(rows: Rows) -> list[str]:
        return [f"  {label:<22}{text}" for label, text in rows]

    lines = [
        verdict_line(result),
        *[f"  {line}" for line in warning_lines(result)],
        *preamble,
        f"Hand-eye T_flange_sensor ({result.parent_frame} -> {result.child_frame}), "
        f"method {result.method}:",
        *table(hand_eye_rows(result)),
        target_text(result),
        "Residual:",
        *table(residual_rows(result)),
    ]
    if result.self_check is not None:
        lines += ["Self-check:", *table(self_check_rows(result))]
    elif result.self_check_skipped_because:
        lines.append(f"Self-check: not run: {result.self_check_skipped_because}")
    lines.append(samples_line(result))
    if result.thinning is not None and result.thinning.set_aside:
        lines.append(f"  {result.thinning.sentence()} (the result's quality.thinning)")
    lines += [f"  {line}" for line in rejection_lines(result)]
    if result.clock_offset_s or result.clock_offset_estimated:
        how = "estimated from the data" if result.clock_offset_estimated else "given"
        lines.append(
            f"Clock offset added to profile stamps: {result.clock_offset_s * 1e3:+.2f} ms ({how})"
        )
    if result.clock_offset_live_s is not None:
        sigma = result.clock_offset_live_sigma_s
        spread = "" if sigma is None else f" +- {sigma * 1e3:.2f} ms (1 sigma)"
        lines.append(
            f"Clock offset estimated live by the collector: {result.clock_offset_live_s * 1e3:+.2f}"
            f" ms{spread}"
        )
    if result.kinematics is not None:
        lines.append(
            f"Kinematic corrections of the {result.kinematics.model} model: "
            f"{len(result.kinematics.corrections)} estimated, "
            f"{len(result.kinematics.kept_nominal)} kept nominal (the result's kinematics section)"
        )
    if truth is not None:
        lines.append("Error against truth:")
        if isinstance(truth.raw.get("kinematics"), dict):
            lines.append(
                "  (against the true hand-eye moved by the arm's kinematic error after its last "
                "joint's motion, which is one constant transform in the flange frame that no scan "
                "tells from the hand-eye)"
            )
        lines += table(truth_rows(result, truth))
    return "\n".join(lines)
