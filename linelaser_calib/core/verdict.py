"""The verdict on a calibration: good, use with care or do not use, why, and what to do next.

One decision, made here once from the result's self-check and warnings, and shown the same
way by every front end: the summary's first line, the HTML report, the result file
(``quality.verdict``) and the calibration service's ``/calibrate`` answer.

- **do_not_use**: a warning that the solve itself failed (it stopped before converging, a
  search ended on its edge).
- **use_with_care**: no self-check ran or it measured no accuracy in use (the reason is
  ``not_measured_because``), or a warning that the result may be off (a weak direction, a
  systematic robot error, a doubtful model).
- **good**: the self-check held every region of the workspace out in turn and raised no
  warning; only notes (e.g. trimmed grazing-angle ends) remain.

Each warning has a stable id (:data:`WARNING_KINDS`, matched by its opening words as
``docs/quality_and_warnings.md`` quotes them), which is also its anchor there. Texts name
user settings by placeholder (:func:`~.settings_text.setting`); each front end spells them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .result import CalibrationResult
from .selfcheck import DEFAULT_FOLDS
from .settings_text import setting
from .types import Level, Verdict

#: Where each warning is explained: the anchor of its paragraph is ``#<warning id>``.
WARNINGS_GUIDE = "docs/quality_and_warnings.md"


#: What a warning does to the verdict: nothing (a note), or the level it lowers it to.
NOTE = None


@dataclass(frozen=True)
class WarningKind:
    """One kind of warning: its stable id, how its text opens, its weight and the next step.

    Attributes
    ----------
    id : str
        Stable id, also the anchor of its paragraph in :data:`WARNINGS_GUIDE`.
    pattern : str
        Regular expression found at the warning's start (``^`` implied) or, for those that
        start with ``.*``, anywhere in it.
    level : Level or None
        The level the warning lowers the verdict to; None for a note that does not.
    reason : str
        The deciding reason in a few words, when it decides the verdict.
    next_step : str
        What to do about it.
    names_motion : bool
        The warning ends in the motion that fixes it (after its last colon: "...: translate
        the sensor across ..."); the next step is then that motion.
    """

    id: str
    pattern: str
    level: Level | None
    reason: str
    next_step: str
    names_motion: bool = False

    def matches(self, warning: str) -> bool:
        return re.match(self.pattern, warning, flags=re.DOTALL) is not None

    def step(self, warning: str) -> str:
        """The next step for ``warning``: the motion it names, or :attr:`next_step`."""
        if not self.names_motion or ": " not in warning:
            return self.next_step
        motion = warning.rsplit(": ", 1)[1].split("; ")[0].rsplit(". ", 1)[-1]
        return f"add poses that {motion[:1].lower()}{motion[1:]}, and calibrate again"


_CARE, _STOP = Level.USE_WITH_CARE, Level.DO_NOT_USE
_ADD_POSES = "add poses with the motion the warning names, and calibrate again"

#: Every warning the package gives, most decisive first (the first matching kind of the
#: most severe warning decides the verdict's reason and next step).
WARNING_KINDS: tuple[WarningKind, ...] = (
    WarningKind(
        "not-converged",
        r"the refinement stopped after",
        _STOP,
        "the refinement stopped before it converged",
        f"give the robot's real accuracy ({setting('robot_sigma_t_m')}, "
        f"{setting('robot_sigma_r_rad')}) or add poses, and calibrate again",
    ),
    WarningKind(
        "acceptance-level",
        r"the global solve did not reach its acceptance level",
        _STOP,
        "the paper's global solve did not reach its acceptance level",
        f"calibrate with {setting('method')} default, or check the rejected samples and poses",
    ),
    WarningKind(
        "grid-edge",
        r"the coarse grid's best rotation lies on its edge",
        _STOP,
        "the grid search ended on its edge: the initial hand-eye is too far off",
        f"use the default method or a better {setting('initial')}",
    ),
    WarningKind(
        "clock-offset",
        r"the clocks look offset",
        _CARE,
        "the profile and pose clocks look offset",
        f"give {setting('clock_offset_s')} auto and calibrate again",
    ),
    WarningKind(
        "live-clock-offset",
        r"the collector estimates the profile-to-pose clock offset live",
        _CARE,
        "the samples were paired with another clock offset than the collector estimates",
        "set the collector's clock_offset_s to the estimate and collect again",
    ),
    WarningKind(
        "systematic-robot-error",
        r"the robot's pose error looks systematic",
        _CARE,
        "the robot's pose error looks systematic (kinematics off their model)",
        f"calibrate the kinematics with the hand-eye ({setting('kinematics')} with joint "
        "states), or use flange poses of a calibrated robot model",
    ),
    WarningKind(
        "robot-error-over-prior",
        r"the robot's pose error is about",
        _CARE,
        "the robot errs more than its stated accuracy",
        f"give the robot's accuracy ({setting('robot_sigma_t_m')}, {setting('robot_sigma_r_rad')})",
    ),
    WarningKind(
        "weak-direction",
        r"weak hand-eye direction",
        _CARE,
        "a direction of the hand-eye is weakly determined",
        _ADD_POSES,
        names_motion=True,
    ),
    WarningKind(
        "weakly-determined",
        r".*Weakly determined:",
        _CARE,
        "some directions of the hand-eye are weakly determined",
        _ADD_POSES,
    ),
    WarningKind(
        "few-clusters",
        r"the \d+ poses fall into only",
        _CARE,
        "the poses fall into few independent clusters",
        "add poses between the clusters, and calibrate again",
    ),
    WarningKind(
        "outliers",
        r"(\d+ more sample\(s\) look like outliers|profile \d+ looks like an outlier)",
        _CARE,
        "some profiles do not fit their recorded pose",
        "check the named profiles; record them again or leave them out",
    ),
    WarningKind(
        "profile-scatter",
        r"(the hand-eye moves from profile to profile|the views lie off the fit)",
        _CARE,
        "the profiles scatter the hand-eye more than the noise model predicts",
        "check the exposure and the target's surface; the 1 sigma already covers it",
    ),
    WarningKind(
        "radius-mismatch",
        r"the profiles fit a radius of",
        _CARE,
        "the profiles fit another radius than the given one",
        f"measure the cylinder (or leave out {setting('radius_m')}), or estimate the "
        f"sensor's scale with {setting('scale')} free",
    ),
    WarningKind(
        "scale-undetermined",
        r"the sensor's along-line scale is poorly determined",
        _CARE,
        "the sensor's along-line scale is poorly determined",
        f"give the measured {setting('radius_m')}, or scan the arc at several positions "
        "along the laser line",
    ),
    WarningKind(
        "scale-implausible",
        r"the estimated along-line scale is",
        _CARE,
        "the estimated along-line scale is implausible: it took up something else",
        f"measure the target (or leave out {setting('radius_m')}), or hold the scale with "
        f"{setting('scale')} fixed",
    ),
    WarningKind(
        "scale-held",
        r"the (along-line|depth) scale, estimated by default, read",
        _CARE,
        "a scale of the profiler read implausibly far from 1, so it was held at 1",
        f"give the measured {setting('radius_m')}; the hand-eye's 1 sigma does not cover "
        "whatever stretches the profiles",
    ),
    WarningKind(
        "scale-model-spread",
        r"the along-line scale, held at 1 by default, reads|with the radius estimated the profiles "
        r"fix only the ratio of the along-line and depth scales",
        _CARE,
        "another reading of the sensor's scales moves the hand-eye beyond its 1 sigma",
        "check the profiler's x scale on a known length (a cylinder: give its measured "
        f"{setting('radius_m')}); the 1 sigma already counts the move, "
        f"and {setting('scale')} free estimates the scale if it is known to be off",
    ),
    WarningKind(
        "model-misfit-kept",
        r"the .+ model does not fit these data:.*the result is kept",
        _CARE,
        "the target's model leaves more residual than expected, though no rival target fits",
        "look at the residual map for a shape error of the target or a systematic robot error",
    ),
    WarningKind(
        "centre-side",
        r"the data barely tell which side",
        _CARE,
        "the side of the laser plane the sphere centre lies on is uncertain",
        f"give {setting('centre_side')}, or add poses that cut the ball at other heights",
    ),
    WarningKind(
        "off-plane",
        r"\d+% of the points have \|y\| up to",
        _CARE,
        "the profiles may not be in the sensor frame",
        "check the profiles' frame_id and the driver's output frame",
    ),
    WarningKind(
        "grazing-trimmed",
        r"trimmed the grazing-angle ends",
        NOTE,
        "",
        "nothing",
    ),
    WarningKind(
        "unpaired",
        r"(recording \d+ \(.*\): )?\d+ (of its \d+ )?profiles did not pair",
        NOTE,
        "",
        "a few at the start or end are normal; many mean a clock offset or a gap in the poses",
    ),
    WarningKind(
        "pose-stream",
        r"\d+ flange poses (arrived out of stamp order|repeated a stamp)",
        NOTE,
        "",
        "nothing: the poses were sorted and a repeated stamp kept once",
    ),
    WarningKind(
        "tf-conflict",
        r"\S+ has parent \S+ but transforms give it parent",
        NOTE,
        "",
        "check the recording's /tf publishers",
    ),
    WarningKind(
        "placement-features-lost",
        r"recording \d+: \d+ of its \d+ paired profiles gave no feature",
        NOTE,
        "",
        "check the named recording's rejections",
    ),
    WarningKind(
        "skipped-messages",
        r"\d+ (malformed messages|TF transforms) were skipped",
        NOTE,
        "",
        "check the recording's messages",
    ),
    WarningKind(
        "ur-base-frame",
        r"the flange poses are in frame 'base'",
        NOTE,
        "",
        f"pass {setting('base_frame')} base, or record /tf",
    ),
    WarningKind(
        "hand-eye-normalised",
        r"the (quaternion .* has norm|matrix's rotation is off orthonormal)",
        NOTE,
        "",
        "check the source of the initial hand-eye",
    ),
    WarningKind(
        "no-kinematic-corrections",
        r"the \S+ method of the .* target does not estimate kinematic corrections",
        NOTE,
        "",
        "nothing: the joint states were used with the nominal model",
    ),
    WarningKind(
        "kinematic-identifiability",
        r"\d+ of \d+ kinematic parameters are identifiable",
        NOTE,
        "",
        "nothing: the parameters these scans cannot tell apart are kept nominal",
    ),
    WarningKind(
        "placement-advice",
        r"\d+ placements? of the",
        NOTE,
        "",
        "follow the placement advice, if it asks for another placement",
    ),
    WarningKind(
        "outside-joint-states",
        r".*outside the joint-state stream",
        NOTE,
        "",
        "record the joint states for the whole scan",
    ),
)

#: The kind of a warning no entry of :data:`WARNING_KINDS` describes (it lowers the verdict
#: to use with care: an unknown warning is not known to be harmless).
OTHER = WarningKind(
    "other-warnings",
    r"",
    _CARE,
    "a warning was raised",
    "read the warning",
)


_RANK = {kind.id: k for k, kind in enumerate(WARNING_KINDS)}


def warning_kind(warning: str) -> WarningKind:
    """The kind of ``warning`` (its stable id, weight and next step)."""
    return next((kind for kind in WARNING_KINDS if kind.matches(warning)), OTHER)


#: The next step of a good result.
EXPORT = (
    "export it (linelaser-calib export RESULT.yaml: a URDF joint, a static transform or a "
    "launch file) or use the published hand-eye"
)


def judge(result: CalibrationResult) -> Verdict:
    """The verdict on ``result`` from its self-check and warnings (see the module text)."""
    kinds = [warning_kind(w) for w in result.warnings]
    check = result.self_check
    accuracy = None if check is None else check.accuracy_in_use_m
    if check is None:
        missing = result.self_check_skipped_because or "no self-check ran"
    else:
        missing = check.no_accuracy_reason
    ids = tuple(kind.id for kind in kinds)
    ranked = sorted(
        zip(kinds, result.warnings, strict=True), key=lambda pair: _RANK.get(pair[0].id, len(_RANK))
    )
    decisive = {
        level: [(kind, text) for kind, text in ranked if kind.level is level]
        for level in (Level.DO_NOT_USE, Level.USE_WITH_CARE)
    }
    if decisive[Level.DO_NOT_USE]:
        kind, text = decisive[Level.DO_NOT_USE][0]
        return Verdict(Level.DO_NOT_USE, kind.reason, kind.step(text), accuracy, missing, ids)
    if missing:
        return Verdict(
            Level.USE_WITH_CARE,
            f"not checked: {missing}",
            _measure_step(result, check is None),
            accuracy,
            missing,
            ids,
        )
    if decisive[Level.USE_WITH_CARE]:
        kind, text = decisive[Level.USE_WITH_CARE][0]
        return Verdict(Level.USE_WITH_CARE, kind.reason, kind.step(text), accuracy, missing, ids)
    return Verdict(
        Level.GOOD,
        "the self-check held each region of the workspace out in turn and raised no warning",
        EXPORT,
        accuracy,
        missing,
        ids,
    )


def _measure_step(result: CalibrationResult, no_check: bool) -> str:
    """What to do so that the self-check measures the accuracy in use."""
    if no_check and result.method != "default":
        return f"calibrate with {setting('method')} default, whose self-check measures it"
    short = 2 * DEFAULT_FOLDS - len(result.samples_used)
    if no_check and short > 0:
        return (
            f"add at least {short} more pose{'s' if short > 1 else ''} in other regions of the "
            "workspace (other positions and flange directions), and calibrate again"
        )
    return (
        "add poses in other regions of the workspace (other positions and flange "
        "directions), and calibrate again"
    )


def no_self_check_reason(default_method: bool, folds: int, used: int, has_sigma: bool) -> str:
    """Why no self-check ran (a result without one), in words.

    Parameters
    ----------
    default_method : bool
        The default method ran (the paper's has no self-check).
    folds : int
        The self-check's folds (0: switched off).
    used : int
        Samples the solve used (the check needs two per fold).
    has_sigma : bool
        The solve gave a 1 sigma to check.
    """
    if not default_method:
        return "the paper method has no self-check"
    if not folds:
        return "the self-check was switched off (self_check_folds 0)"
    if used < 2 * folds:
        return (
            f"{used} samples were used and the self-check needs at least {2 * folds} "
            f"({folds} folds of 2)"
        )
    if not has_sigma:
        return "the solve gave no 1 sigma to check"
    return "a fold of the self-check could not be solved without its poses"


def verdict_of(result: CalibrationResult) -> Verdict:
    """The result's verdict: as judged once its warnings were all in (or read from a file),
    else judged now."""
    return result.verdict if result.verdict is not None else judge(result)
