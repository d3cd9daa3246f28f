"""Which target explains the whole recording: a target's fit against its rivals' full fits.

One profile cannot tell a sphere from a cylinder: a real profiler's smooth shape error (tens
of µm along the line) lets a 5-number conic beat a 3-number circle on almost any single
profile. The evidence is in the whole recording: a sphere's cuts are circles whose radius
changes with the plane's distance from one centre, a cylinder's are ellipses about one
axis, each consistent only through the poses. So a recording is judged here, by the full
models (:func:`check_model`, called by the pipeline after the solve; and
:func:`refuse_without_fit`, where too few profiles show the target's feature for a solve):

1. **Is the target's own model in doubt?** Its fit check (:meth:`Target.check_fit`) failed;
   or its solve needs a robot pose error more than :data:`~.base.ROBOT_PRIOR_EXCESS` times
   the prior, or did not converge; or the target's own per-profile shapes say so (the
   optional ``model_doubt(features, config)`` capability: e.g. most profiles fit a rival
   shape better).
2. **If so, does a rival target explain the recording clearly better?** Each target the
   target names as a rival (its optional ``rivals`` attribute: target names) is calibrated
   from the same samples through the target protocol (its own extraction and default
   solve). Both fits are judged alike: every point of the profiles either used is mapped
   into the base frame with its *recorded* flange pose and each fit's hand-eye, and its
   distance from each fit's target is taken (:meth:`~.base.ResultSection.surface_distances`;
   the likelihood of the points under one common Gaussian noise). A rival whose RMS
   distance is :data:`CLEAR_FACTOR` times smaller wins clearly: the recording is refused,
   the rival named with both figures.
3. **Otherwise** the data are still consistent with the target when a rival was fitted and
   every rival leaves :data:`CLEAR_FACTOR` times more. A fit that needs a robot error
   :data:`~.base.MISFIT_ROBOT_EXCESS` times the prior is refused as a misfit unless they are (its
   warnings say how large the error is). A failed fit check is refused too, in the target's
   own words with the figures; only a target whose check a real profiler's shape error
   alone may fail (its optional ``soft_fit_check``: the sphere's and the cylinder's residual
   against what each profile's own shape fit leaves) keeps a result whose check failed where
   every rival is clearly worse or none could be fitted at all (it then becomes a warning
   with the figures), but never one that failed on the robot's error (e.g. a sphere centre
   given on the wrong side) nor a :class:`~..errors.GrossMismatch` (the line's corners 10
   times farther from it than the noise explains, or lying around one point). A target
   that names no rival keeps its fit check's refusals.

Where the clock offset between profile and pose stamps is estimated (continuous scanning:
:func:`~linelaser_calib.core.offset_search.search_clock_offset`), each rival that estimates
one is judged at its own: the same profiles are paired again at the offset that fits the
rival best (:data:`RivalSamples`), since a sweep in motion paired at another target's offset
misfits by the latency times the speed. Each fit is then judged with its own pairing's
flange poses, and a rival's figure says the offset it was judged at. That search runs only
where rivals are fitted at all: where the target's own model is in doubt. The rival's
features are extracted once for its search and its fit (:mod:`.extraction`).

Where too few profiles show the target's feature to solve at all (a ball's arcs given to the
line target, a V given to the sphere; :class:`~linelaser_calib.core.errors.TooFewFeatures`),
the rivals are fitted likewise, in the target's order: the first whose fit passes its own
checks (fit check, convergence, a robot error within :data:`~.base.MISFIT_ROBOT_EXCESS` times the
prior) and uses :data:`CLEAR_FACTOR` times as many profiles as show the target's feature
explains the recording clearly better, and the refusal names it with both figures (the
profiles each explains; the RMS distances of the rivals fitted). Otherwise the target's
own refusal stands, naming no rival.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import CalibrationError, GrossMismatch, ModelMismatch, TooFewFeatures
from ..geometry import FloatArray
from ..types import Sample, SampleFit
from . import get_target
from .base import (
    MISFIT_ROBOT_EXCESS,
    ROBOT_PRIOR_EXCESS,
    SolveContext,
    Target,
    TargetSolution,
    _no_progress,
)
from .extraction import Extractions

#: A rival whose points' RMS distance from its fitted target is this many times smaller than
#: the target's own wins clearly (and the target is clearly better than a rival leaving this
#: many times more).
CLEAR_FACTOR = 2.0

#: Where the clock offset is estimated: given a rival target and the target's samples, the
#: same profiles paired with the flange poses at the rival's own best clock offset, and that
#: offset (s; None, with the samples unchanged, for a rival that estimates none).
RivalSamples = Callable[[Target[Any], list[Sample]], tuple[list[Sample], float | None]]


@dataclass(frozen=True)
class WholeFit:
    """One target's full fit judged on the whole recording.

    Attributes
    ----------
    title : str
        The target's title.
    name : str
        Its ``--target`` value.
    rms_m : float
        RMS distance of the profiles' points from the fitted target, recorded poses, m.
    n_points, n_profiles : int
        What the RMS was taken over.
    offset_s : float or None
        The clock offset the target's own pairing was searched to, s (a rival's, where the
        offset is estimated); None where it is the recording's.
    """

    title: str
    name: str
    rms_m: float
    n_points: int
    n_profiles: int
    offset_s: float | None = None

    def text(self) -> str:
        """'the sphere fitted with the poses leaves 98.1 um RMS' for messages (with 'at its
        own clock offset of +12.0 ms' after 'poses' where it has one)."""
        return f"the {self.title} fitted with the poses{self.at_offset()} leaves " + (
            f"{self.rms_m * 1e6:.1f} um RMS"
        )

    def at_offset(self) -> str:
        """' at its own clock offset of +12.0 ms', or '' where it has none."""
        if self.offset_s is None:
            return ""
        return f" at its own clock offset of {self.offset_s * 1e3:+.1f} ms"


@dataclass(frozen=True)
class PairedFit:
    """A target's full fit and the flange pose its pairing gave each profile.

    Attributes
    ----------
    target : Target
    solution : TargetSolution
    poses : mapping of int to ndarray, shape (4, 4)
        ``T_base_flange`` of each profile index as this target's samples paired it.
    offset_s : float or None
        The clock offset of that pairing where it was the target's own (a rival's); None
        where it is the recording's.
    """

    target: Target[Any]
    solution: TargetSolution
    poses: Mapping[int, FloatArray]
    offset_s: float | None = None


def _poses(samples: Sequence[Sample]) -> dict[int, FloatArray]:
    return {s.index: s.T_base_flange for s in samples}


def whole_rms_m(
    solution: TargetSolution, fits: Sequence[SampleFit], poses: Mapping[int, FloatArray]
) -> tuple[float, int]:
    """RMS distance (m) of the fits' points, each mapped with its profile's flange pose in
    ``poses`` (the fit's own where it holds none) and the solution's hand-eye, from the
    solution's target, and the number of points."""
    distances = [
        solution.section.surface_distances(
            fit, poses.get(fit.index, fit.T_base_flange) @ solution.T_flange_sensor
        )
        for fit in fits
    ]
    d = np.concatenate(distances) if distances else np.zeros(0)
    return (float(np.sqrt(np.mean(d**2))) if len(d) else math.inf), len(d)


def _judged(fit: PairedFit, fits: Sequence[SampleFit]) -> WholeFit:
    rms, n = whole_rms_m(fit.solution, fits, fit.poses)
    return WholeFit(fit.target.title, fit.target.name, rms, n, len(fits), fit.offset_s)


def _mapped_with(judged: Sequence[WholeFit]) -> str:
    """How the figures' points were mapped, for messages."""
    if any(w.offset_s is not None for w in judged):
        return "the flange poses at each target's own clock offset"
    return "the recorded flange poses"


def _rival_solution(
    name: str,
    samples: list[Sample],
    context: SolveContext,
    rival_samples: RivalSamples | None,
    extractions: Extractions,
) -> PairedFit | None:
    """The rival target's default fit of the samples with its default settings (paired at
    its own clock offset by ``rival_samples`` where given; its features from the run's
    ``extractions``); None when it cannot calibrate them (a refusal, or a singular system in
    its solve: the rival's model leaves a direction undetermined on these samples)."""
    rival = get_target(name)
    config = rival.config_type()
    try:
        own, offset = (samples, None) if rival_samples is None else rival_samples(rival, samples)
        features, rejections = extractions.of(rival, config, own)
        quiet = SolveContext(
            seed=context.seed,
            rejections=rejections,
            n_samples=len(samples),
            progress=_no_progress,
        )
        return PairedFit(rival, rival.solve_default(features, config, quiet), _poses(own), offset)
    except (CalibrationError, np.linalg.LinAlgError):
        return None


def _doubts(
    target: Target[Any], config: Any, features: list[Any], solution: TargetSolution
) -> list[str]:
    """Why the target's own model is in doubt, in words (empty: it is not)."""
    doubts = []
    robot = solution.robot_error
    if robot is not None and robot.excess > ROBOT_PRIOR_EXCESS:
        doubts.append(f"its fit needs a robot pose error {robot.excess:.1f} times the prior")
    if not solution.converged:
        doubts.append("its refinement did not converge")
    shape = getattr(target, "model_doubt", None)
    if callable(shape):
        said = shape(features, config)
        if said:
            doubts.append(said)
    return doubts


def _what(problem: ModelMismatch) -> str:
    """What a fit check found, without its title, causes and ending."""
    text = str(problem)
    for end in (". Likely causes", ". No result"):
        text = text.split(end)[0]
    return text.split("does not fit these data: ", 1)[-1]


def _inserted(text: str, more: str) -> str:
    """A refusal's text with ``more`` (sentences) before its likely causes or its end."""
    for mark in (" Likely causes", " No result was written"):
        if mark in text:
            head, _, tail = text.partition(mark)
            return f"{head}{more}{mark}{tail}"
    return text + more


def check_model(
    target: Target[Any],
    config: Any,
    samples: list[Sample],
    features: list[Any],
    solution: TargetSolution,
    context: SolveContext,
    rival_samples: RivalSamples | None = None,
    extractions: Extractions | None = None,
) -> None:
    """Refuse a solution whose target a rival explains clearly better, or that does not fit
    and is not consistent (see the module docstring); a failed fit check that every rival
    explains clearly worse becomes a warning on the solution. ``rival_samples``: where the
    clock offset was estimated, each rival's samples at its own offset; ``extractions``: the
    run's features (each rival's extracted once; None: a store of this check's own).

    Raises
    ------
    ModelMismatch
        Naming the rival with both figures, or the misfit.
    """
    problem: ModelMismatch | None = None
    try:
        target.check_fit(solution, config)
    except ModelMismatch as exc:
        problem = exc
    doubts = _doubts(target, config, features, solution)
    robot = solution.robot_error
    robot_misfit = robot is not None and robot.excess > MISFIT_ROBOT_EXCESS
    if problem is None and not doubts:
        return
    declared = tuple(getattr(target, "rivals", ()))
    store = Extractions(context.seed) if extractions is None else extractions
    tried = {
        name: _rival_solution(name, samples, context, rival_samples, store) for name in declared
    }
    rivals = [found for found in tried.values() if found is not None]
    unfit = [get_target(name).title for name, found in tried.items() if found is None]
    fits = {f.index: f for r in rivals for f in r.solution.sample_fits}
    fits.update({f.index: f for f in solution.sample_fits})
    every = [fits[k] for k in sorted(fits)]
    own = _judged(PairedFit(target, solution, _poses(samples)), every)
    judged = sorted((_judged(r, every) for r in rivals), key=lambda w: w.rms_m)
    misfit = [] if problem is None else [_what(problem)]
    if any("flange-pose corrections" in m for m in misfit):
        doubts = [d for d in doubts if not d.startswith("its fit needs a robot pose error")]
    why = "; ".join(doubts + misfit)
    figures = (
        f"over {own.n_points} points of {own.n_profiles} profiles mapped with "
        + _mapped_with(judged)
    )
    if judged and judged[0].rms_m * CLEAR_FACTOR < own.rms_m:
        best = judged[0]
        raise ModelMismatch(
            f"the {own.title} model does not explain these data ({why}): {best.text()} where "
            f"{own.text()} ({figures}). The scans show a {best.title}: choose "
            f"{{setting:target}} {best.name}. No result was written."
        )
    compared = (
        " On the whole recording, "
        + "; ".join(w.text() for w in judged)
        + f"; {own.text()} ({figures})."
        if judged
        else ""
    )
    # Every rival fitted leaves CLEAR_FACTOR times more (and one at least was fitted) ...
    consistent = bool(judged) and judged[0].rms_m >= CLEAR_FACTOR * own.rms_m
    # ... or, for a failed residual check, no rival could be fitted at all; kept only where
    # the target's check is a soft one.
    soft = bool(getattr(target, "soft_fit_check", False))
    unrivalled = soft and bool(declared) and (consistent or not judged)
    gross = isinstance(problem, GrossMismatch)
    if problem is not None and (robot_misfit or gross or not unrivalled):
        raise ModelMismatch(_inserted(str(problem), compared))
    if robot_misfit and not consistent:
        assert robot is not None
        raise ModelMismatch(
            f"the {own.title} model does not fit these data: its fit needs flange-pose "
            f"corrections of {robot.translation_m * 1e3:.3f} mm and "
            f"{math.degrees(robot.rotation_rad):.4f} deg (1 sigma), {robot.excess:.0f} times "
            "the robot's stated error"
            + ("" if solution.converged else ", and its refinement did not converge")
            + "."
            + compared
            + " Likely causes: the scans show another target ({setting:target}); the profile "
            "and pose clocks are not synchronised ({setting:clock_offset_s}); the robot moved "
            "during the scans; or the robot is less accurate than stated "
            "({setting:robot_sigma_t_m}). No result was written."
        )
    if problem is None:
        return
    others = [w.text() for w in judged] + [
        f"the {title} could not be fitted to these profiles" for title in unfit
    ]
    solution.warnings.append(
        f"the {own.title} model does not fit these data: {_what(problem)}; but "
        + (f"{own.text()} where " if judged else "")
        + ", ".join(others)
        + (f" ({figures})" if judged else "")
        + f": these data are still best explained by a {own.title}, and the result is kept"
    )


def _explains(rival: Target[Any], solution: TargetSolution) -> bool:
    """Whether a rival's fit passes its own checks: its fit check (default settings), its
    refinement converged, and its robot error within :data:`~.base.MISFIT_ROBOT_EXCESS` times the
    prior."""
    robot = solution.robot_error
    if not solution.converged or (robot is not None and robot.excess > MISFIT_ROBOT_EXCESS):
        return False
    try:
        rival.check_fit(solution, rival.config_type())
    except ModelMismatch:
        return False
    return True


def refuse_without_fit(
    target: Target[Any],
    samples: list[Sample],
    refusal: TooFewFeatures,
    context: SolveContext,
    rival_samples: RivalSamples | None = None,
    extractions: Extractions | None = None,
) -> None:
    """Where too few profiles show the target's feature (``refusal``), refuse naming a rival
    target that explains the recording clearly better, with both figures (see the module
    docstring); return otherwise (the caller's own refusal stands). ``rival_samples``: where
    the clock offset is estimated, each rival's samples at its own offset; ``extractions``
    as :func:`check_model`'s.

    The rivals are fitted in the target's order (its ``rivals``) up to the first that
    explains the recording.

    Raises
    ------
    ModelMismatch
        Naming the rival, the profiles it explains against those showing the target's
        feature, and the RMS distances of the rivals fitted.
    """
    fitted = []
    store = Extractions(context.seed) if extractions is None else extractions
    for name in getattr(target, "rivals", ()):
        found = _rival_solution(name, samples, context, rival_samples, store)
        if found is None:
            continue
        fitted.append(found)
        solution = found.solution
        enough = len(solution.samples_used) >= max(CLEAR_FACTOR * refusal.found, 1.0)
        if enough and _explains(found.target, solution):
            break
    else:
        return
    fits = {f.index: f for r in fitted for f in r.solution.sample_fits}
    every = [fits[k] for k in sorted(fits)]
    judged = [_judged(r, every) for r in fitted]
    *tried, best = judged
    others = "".join(f"; {w.text()}" for w in tried)
    own = str(refusal).split(". ", 1)[0]
    raise ModelMismatch(
        f"the {target.title} model does not explain these data: {own}; but the {best.title} "
        f"fitted with the poses{best.at_offset()} explains {len(solution.samples_used)} of "
        f"the {context.n_samples} recorded profiles and leaves {best.rms_m * 1e6:.1f} um RMS "
        f"(over {best.n_points} points of {best.n_profiles} profiles mapped with "
        f"{_mapped_with(judged)}{others}). The scans show a {best.title}: choose "
        f"{{setting:target}} {best.name}. No result was written."
    )
