"""The cylinder target: profiles of a cylinder of known or unknown radius (the cylinder paper).

Methods
-------
``paper``
    The cylinder paper as published: RANSAC ellipse centres, centre-to-axis cost (eq. 12),
    PSO + generalized-Lagrange-multiplier hybrid (Fig. 4).
``default``
    The paper's solve as a seed, then maximum likelihood on every inlier point with the
    robot's per-sample pose error as nuisance parameters, outlier-sample rejection,
    covariance and observability diagnostics (:mod:`.refine`). The sensor's along-line scale,
    and with the radius given its depth scale, are estimated with them (``scale``,
    ``--scale``; :func:`estimates_scale`). With joint states and a
    robot model (``SolveContext.kinematics``) it then estimates the identifiable kinematic
    corrections together with the hand-eye and the cylinder
    (:func:`.joint.refine_kinematics`), from the other placements of the cylinder in
    ``SolveContext.placements`` too (each refined on its own first, from the paper's solve on
    its ellipse centres).

Model fit
---------
Each profile's ellipse meets rival shapes (a line, a V) by an information criterion
(:mod:`.shape`); a recording most of whose profiles a rival fits clearly better puts the
cylinder in doubt (:meth:`CylinderTarget.model_doubt`), and is never refused for it. A
cylinder's cut is an ellipse whose semi-minor axis is the radius in every view, but a short
arc leaves that axis uncertain, so the radius is judged by the joint fit of all profiles:
its point residual stays near what each profile's own free ellipse leaves (the recording's
scale); scans of a sphere (circles of varying radius) leave many times more. Which target
the recording shows is decided on the whole recording (:mod:`..rivals`): where the fit is
in doubt (that residual, a robot error far beyond the prior, no convergence, the profiles'
shapes), or too few profiles show an arc, the rival targets' full fits with the poses are
made (the sphere, the seam targets), and the recording is refused naming one only when it
explains the recording clearly better.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...errors import CalibrationError, DegenerateError, ModelMismatch, TooFewFeatures
from ...forked import map_forked
from ...geometry import FloatArray
from ...model_check import shape_doubt
from ...profile.along_line import (
    PLAUSIBLE_SCALE_ERROR,
    implausible_scale_held,
    scale_significant,
)
from ...robot.joint_calibration import KinematicSetup
from ...shared_pose import SharedPoseError
from ...solver import widening
from ...subsets import lean
from ...types import Rejection, Sample
from ..base import (
    Option,
    Placement,
    Progress,
    ResultSection,
    RobotError,
    SolveContext,
    TargetSolution,
    _no_progress,
    mismatch_message,
    rejection_digest,
)
from .advice import CylinderPlacementAdviser
from .arc import radius_mismatch
from .config import CylinderConfig, RefineConfig
from .features import (
    FittedSample,
    arc_notes,
    fit_sample,
    fit_samples,
    long_arcs,
    settle_radius,
)
from .joint import JointScan, refine_kinematics
from .model import Cylinder, centre_distances
from .plan import CylinderPlanner
from .pso_alm import PaperSolution, solve_pso_galm
from .refine import (
    MAX_SCALE_SIGMA,
    DroppedSample,
    RefineResult,
    SolvedProblem,
    refine,
    refine_with_outlier_rejection,
)
from .scales import estimates_scale, scale_verdict, with_depth_reading
from .section import CylinderSection, read_cylinder_section
from .shared import shared_widening, with_shared
from .warm import refine_at_poses, refine_screened, refine_subset

#: Points per profile in the refinements of the clock-offset search, and the most
#: linearisations of each refinement after the first (:meth:`CylinderTarget.offset_cost`).
OFFSET_SEARCH_POINTS, OFFSET_SEARCH_ITERATIONS = 50, 3
#: Most ellipse centres the default method's seed solve (PSO + GALM) is given, evenly spaced
#: in the profiles' order: the seed only has to land in the refinement's basin, which a few
#: hundred views across the recording pin as well as thousands, and its cost (hundreds of
#: GALM iterations over every centre where the swarm is not accepted early) then stays
#: bounded however long the recording (continuous 4,000 poses, 4,519 profiles kept: 146 ->
#: 121 s CPU, every figure the same).
SEED_MOST_CENTRES = 400
#: A default-method solution whose RMS point residual exceeds this multiple of the
#: recording's scale (:func:`recording_scale_m`: what each profile's own free ellipse
#: leaves) does not fit: 0.8-1.4 on the committed cylinder bags (the cluttered camera's
#: systematic robot error included), 27 and 23 for cylinder fits of the simulated and the
#: real sphere scans, whose circles of varying radius no one cylinder explains.
MISFIT_FACTOR = 5.0
#: The same for the paper method's centre-to-axis RMS against the robot's σ_t.
PAPER_MISFIT_FACTOR = 100.0


@dataclass(frozen=True)
class _SubsetStart:
    """A default solve's problem and solution (:attr:`TargetSolution.subset_start`), the
    row of each used feature (by profile index) in it, and how its views share the robot's
    error (:mod:`.shared`: taken as learned by the subsets' solves)."""

    solved: SolvedProblem
    rows: Mapping[int, int]
    shared: SharedPoseError | None = None


def _subset_start(
    features: list[FittedSample], context: SolveContext
) -> tuple[_SubsetStart, list[FittedSample], list[Rejection]] | None:
    """Where a solve of ``features`` starts when they are a subset of the warm start's (the
    self-check's solves): its solved problem, the features it used and the warm start's
    rejections of the others (outliers it dropped, dropped again without a solve: the full
    solve screened them under the same model); None for a solve of its own (no warm start,
    a joint kinematic calibration, a feature the warm start never saw)."""
    warm = context.warm_start
    start = None if warm is None else warm.subset_start
    if warm is None or not isinstance(start, _SubsetStart) or context.kinematics is not None:
        return None
    dropped = {r.index: r for r in warm.rejections if r.stage == "outlier"}
    if any(f.index not in start.rows and f.index not in dropped for f in features):
        return None
    kept = [f for f in features if f.index in start.rows]
    return start, kept, [dropped[f.index] for f in features if f.index not in start.rows]


def _solved_again(
    features: list[FittedSample], start: _SubsetStart, config: RefineConfig
) -> RefineResult:
    """A solved problem of ``features`` solved again with ``config``'s scales
    (:func:`.warm.refine_screened`: the same screened samples, trimmed points and learned line
    noise, from the solution, with the outlier rounds again); ``used`` and ``dropped`` index
    ``features``. ``--scale auto`` holding a scale, or reading a kept x scale as a depth
    scale (:func:`with_depth_reading`), changes the model a little: solved from the solution
    in 4 linearisations (``ur_scancontrol``, 1,600 poses), where a solve from scratch
    repeats the seed, the point trimming, the line-noise learning and the outlier rounds;
    the hand-eye and its 1σ move by under 0.001σ on the committed cylinder bags, 0.03σ on
    ``cylinder_keyence`` (its line noise as learned with the scale free), and the depth
    reading of ``cylinder_scancontrol`` by 0.05σ."""
    position = {f.index: j for j, f in enumerate(features)}
    feature_of_row = [position[i] for i in sorted(start.rows, key=start.rows.__getitem__)]
    refined = refine_screened(start.solved, range(len(feature_of_row)), config, final=True)
    refined.used = [feature_of_row[k] for k in refined.used]
    refined.dropped = [DroppedSample(feature_of_row[k], reason) for k, reason in refined.dropped]
    return refined


def _shared(solution: TargetSolution) -> TargetSolution:
    """A default solve's ``solution`` solved without the robot's shared error (the first solve
    of ``--scale auto``) with its hand-eye 1σ counting it (:func:`.shared.shared_widening`)."""
    start = solution.subset_start
    sigma_r, sigma_t = solution.sigma_rotation_rad, solution.sigma_translation_m
    if not isinstance(start, _SubsetStart) or sigma_r is None or sigma_t is None:
        return solution
    widened = shared_widening(start.solved, np.r_[sigma_r, sigma_t])
    if widened is None:
        return solution
    sigma, shared, factors = widened
    return replace(
        solution,
        sigma_rotation_rad=sigma[:3],
        sigma_translation_m=sigma[3:],
        sigma_shared=factors,
        subset_start=replace(start, shared=shared),
    )


def recording_scale_m(features: list[FittedSample], floor_m: float) -> float:
    """The recording's own scale, m: the median over its profiles of the RMS each profile's
    free ellipse leaves (its smooth shape error and noise), or ``floor_m`` without
    features.

    One cylinder through every profile (5 numbers and the radius for all of them) is weighed
    against a free ellipse per profile (5 numbers each): a cylinder that explains the data
    leaves residuals near this scale, whatever noise level was configured and whatever the
    local point-to-point noise.
    """
    fits = [f.ellipse.rms_m for f in features]
    return float(np.median(fits)) if fits else floor_m


#: Why the paper's method leaves a short arc out.
SHORT_ARC_UNUSED = (
    "a short arc: its centre is not a measurement, and the paper's method uses the centres "
    "of the long arcs only (the default method uses its points)"
)


def centred(features: list[FittedSample], config: CylinderConfig) -> list[FittedSample]:
    """The samples whose ellipse centres a solve on the centres uses: the long arcs when at
    least ``config.min_samples`` are there, else all (a short arc's centre is not a
    measurement, :attr:`~.ellipse.EllipseFit.short`)."""
    long = [f for f in features if not f.ellipse.short]
    return long if len(long) >= config.min_samples else features


class CylinderTarget:
    """The cylinder target (see the module docstring)."""

    name = "cylinder"
    title = "cylinder"
    summary = "a cylinder of known or estimated radius (the cylinder paper)"
    methods = ("paper", "default")
    estimates_clock_offset = True
    config_type = CylinderConfig
    options: Mapping[str, Option] = {
        "radius_m": Option("radius_m"),
        "min_samples": Option("min_samples"),
        "sensor_sigma_m": Option("refine.sensor_sigma_m", methods=("default",)),
        "robot_sigma_t_m": Option("refine.robot_sigma_t_m", methods=("default",)),
        "robot_sigma_r_rad": Option("refine.robot_sigma_r_rad", methods=("default",)),
        "scale": Option("scale", methods=("default",)),
        "initial": Option("", methods=("default",)),
    }
    #: Pose planning (:mod:`linelaser_calib.core.planning`).
    planner = CylinderPlanner()
    #: Whether another placement would determine more of the robot's kinematics.
    placement_adviser = CylinderPlacementAdviser()
    #: Targets whose full model may explain a recording instead (:mod:`..rivals`).
    rivals = ("sphere", "line", "known_point")
    #: Its residual check (against what each profile's own shape fit leaves) may fail on a
    #: real profiler's shape error alone: kept with a warning where no rival does better.
    soft_fit_check = True

    def validate(
        self, sample: Sample, config: CylinderConfig, rng: np.random.Generator
    ) -> Rejection | None:
        """The cleaning and ellipse fit of one sample (semi-axes bounded by the radius)."""
        outcome = fit_sample(sample, config, rng, config.radius_m)
        return outcome if isinstance(outcome, Rejection) else None

    def extract(
        self,
        samples: list[Sample],
        config: CylinderConfig,
        seed: int,
        progress: Progress,
        workers: int = 1,
    ) -> tuple[list[Any], list[Rejection]]:
        """Every sample's ellipse (:func:`.features.fit_samples`)."""
        fitted, rejections = fit_samples(samples, config, seed, progress, workers)
        return list(fitted), rejections

    @staticmethod
    def with_samples(features: list[Any], samples: list[Sample]) -> list[Any]:
        """The ellipses re-paired with other samples of their profiles (the ellipse is fitted
        in the sensor frame: it does not depend on the flange pose)."""
        by_index = {s.index: s for s in samples}
        return [replace(f, T_base_flange=by_index[f.index].T_base_flange) for f in features]

    def _checked(
        self, features: list[FittedSample], config: CylinderConfig, context: SolveContext
    ) -> float:
        """The radius (m), after checking there are enough ellipses."""
        radius = settle_radius(features, config.radius_m) if features else config.radius_m
        if len(features) < config.min_samples:
            if features:
                advice = (
                    "Scan the cylinder from more poses, with the laser line across the cylinder."
                )
            else:
                advice = (
                    "None of the profiles shows the cylinder's arc: check that the laser line "
                    "falls across the cylinder within the measuring range."
                )
            raise TooFewFeatures(
                f"only {len(features)} of {context.n_samples} recorded profiles gave a usable "
                "ellipse, "
                f"and at least {config.min_samples} are needed. "
                + rejection_digest(context.rejections)
                + advice,
                len(features),
            )
        assert radius is not None  # features is not empty here
        return radius

    def _seed(
        self,
        features: list[FittedSample],
        config: CylinderConfig,
        context: SolveContext,
        paper: bool,
    ) -> PaperSolution:
        """The paper's global solve on the ellipse centres (:func:`centred`; a short arc's
        centre is that of the circle of the radius through it); the default method's seed
        (not ``paper``) on at most :data:`SEED_MOST_CENTRES` of them, evenly spaced."""
        radius = settle_radius(features, config.radius_m)
        features = centred(features, config)
        if not paper and len(features) > SEED_MOST_CENTRES:
            spread = np.linspace(0, len(features) - 1, SEED_MOST_CENTRES)
            features = [features[int(k)] for k in np.round(spread)]
        centres = np.array([f.centre_xz(radius) for f in features])
        T_base_flange = np.stack([f.T_base_flange for f in features])
        context.progress("global solve", 0, 1)
        hybrid = config.hybrid if paper else config.seed_hybrid
        solution = solve_pso_galm(
            centres, T_base_flange, hybrid, np.random.default_rng(context.seed + 1)
        )
        context.progress("global solve", 1, 1)
        return solution

    def solve_paper(
        self, features: list[Any], config: CylinderConfig, context: SolveContext
    ) -> TargetSolution:
        """The paper's PSO + GALM hybrid on the long arcs' ellipse centres (the paper rejects
        short arcs; with fewer than ``config.min_samples`` long arcs it refuses)."""
        radius = self._checked(features, config, context)
        used = long_arcs(features)
        if len(used) < config.min_samples:
            raise DegenerateError(
                f"only {len(used)} of {context.n_samples} recorded profiles show an arc long "
                "enough "
                f"for its centre ({math.degrees(config.ellipse.min_arc_coverage_rad):.0f} deg "
                f"or more), and the paper's method needs {config.min_samples}; "
                f"{len(features) - len(used)} more show short arcs, whose points the default "
                "method uses: choose {setting:method} default."
            )
        kept = {f.index for f in used}
        short = [
            Rejection(f.index, f.stamp_ns, "ellipse", SHORT_ARC_UNUSED)
            for f in features
            if f.index not in kept
        ]
        features = used
        solution = self._seed(features, config, context, paper=True)
        T = solution.T_flange_sensor
        cylinder = replace(solution.cylinder, radius=radius)
        centres = np.array([f.centre_xz(radius) for f in features])
        T_base_flange = np.stack([f.T_base_flange for f in features])
        distances = centre_distances(centres, T_base_flange, T, cylinder)
        warnings = []
        if not solution.accepted:
            warnings.append(
                f"the global solve did not reach its acceptance level: the RMS centre-to-axis "
                f"distance is {solution.rms_m * 1e3:.3f} mm; check the rejected samples and "
                "the poses"
            )
        warnings.extend(arc_notes(features, config))
        return TargetSolution(
            T_flange_sensor=T,
            section=CylinderSection(cylinder, config.radius_m is None),
            method="paper",
            samples_used=[f.index for f in features],
            rejections=short,
            rms_residual_m=float(np.sqrt(np.mean(distances**2))),
            sample_residuals_m={
                f.index: float(d) for f, d in zip(features, distances, strict=True)
            },
            sigma_translation_m=None,
            sigma_rotation_rad=None,
            warnings=warnings,
            history=dict(solution.history),
            sample_fits=[f.record() for f in features],
            noise_m=config.refine.robot_sigma_t_m,
        )

    def _start(
        self, features: list[FittedSample], config: CylinderConfig, context: SolveContext
    ) -> tuple[FloatArray, Cylinder, dict[str, Any]]:
        """Hand-eye (4, 4) and axis the refinement starts from, and the seed's history: the
        warm start's when the context has one (no seed solve), else the seed's, the hand-eye
        replaced by the initial one when given."""
        warm = context.warm_start
        if warm is not None and isinstance(warm.section, CylinderSection):
            return warm.T_flange_sensor, warm.section.cylinder, {}
        seed = self._seed(features, config, context, paper=False)
        T_init = (
            seed.T_flange_sensor
            if context.initial_T_flange_sensor is None
            else np.asarray(context.initial_T_flange_sensor, dtype=np.float64)
        )
        return T_init, seed.cylinder, dict(seed.history)

    def solve_default(
        self, features: list[Any], config: CylinderConfig, context: SolveContext
    ) -> TargetSolution:
        """Maximum likelihood on every inlier point, seeded by the paper's solve (or started
        at the context's warm start). With ``{setting:scale} auto`` the scales of
        :func:`estimates_scale` are estimated and each is held at 1 again when its estimate
        is implausible, poorly determined or not clearly off 1 (:func:`scale_significant`;
        the x scale only with the radius free); a warm start keeps its own choice. With the
        radius free the x reading (kept, or held as not clearly off 1) is read as a depth
        scale too, and where that is the same stretch and moves the hand-eye beyond its 1σ,
        the move counts in the 1σ (:func:`with_depth_reading`). Both re-solves (the kept
        scales' and the depth reading's) start at the first solve's solution, so with
        ``context.workers`` 2 they run side by side, the depth reading in a forked child;
        each learns how its own views share the robot's error (:mod:`.shared`), which the
        first solve learns only where it is reported (``ur_scancontrol``, 1,600 poses: 1 s
        each, 0.6 s of it the solve)."""
        radius = self._checked(features, config, context)
        warm = context.warm_start
        free, depth = estimates_scale(config)
        if config.scale != "auto":
            return self._solve_default(features, config, context, radius, free, depth)
        if warm is not None and isinstance(warm.section, CylinderSection):
            free, depth = warm.section.scale is not None, warm.section.depth_scale is not None
            return self._solve_default(features, config, context, radius, free, depth)
        # Its 1σ counts the robot's shared error only where it is reported ("shared" below):
        # each re-solve learns the sharing on its own views (0.6 s on 1,600 profiles, side by
        # side with the other re-solve, not before both).
        solution = self._solve_default(features, config, context, radius, free, depth, False)
        section = solution.section
        assert isinstance(section, CylinderSection)
        estimates = (
            (section.scale, section.scale_sigma),
            (section.depth_scale, section.depth_scale_sigma),
        )
        kept = [
            value is not None
            and abs(value) <= PLAUSIBLE_SCALE_ERROR
            and (sigma is None or sigma <= MAX_SCALE_SIGMA)
            and scale_significant(value, sigma)
            for value, sigma in estimates
        ]
        kept[0] = kept[0] or config.radius_m is not None
        x, sigma_x = estimates[0]
        reading = (
            None
            if config.radius_m is not None
            or x is None
            or sigma_x is None
            or abs(x) > PLAUSIBLE_SCALE_ERROR
            else (x, sigma_x)
        )
        other_config = (
            config
            if section.line_noise is not None  # weighed as this one: no noise to learn
            else replace(config, refine=replace(config.refine, learn_line_noise=False))
        )
        first = solution

        def solve_again(job: str) -> TargetSolution:
            if job == "shared":
                return _shared(first)
            if job == "kept":
                return self._solve_default(
                    features, config, context, radius, kept[0], kept[1], True, first
                )
            quiet = replace(context, progress=_no_progress)
            return lean(
                self._solve_default(features, other_config, quiet, radius, False, True, True, first)
            )

        jobs = ["kept" if kept != [free, depth] else "shared"] + ["depth"] * (reading is not None)
        outcomes = dict(zip(jobs, map_forked(solve_again, jobs, context.workers), strict=True))
        again = outcomes[jobs[0]]
        if isinstance(again, CalibrationError):
            raise again
        if "kept" in outcomes:
            again.warnings.extend(
                implausible_scale_held(value, axis)
                for (value, _), axis in zip(estimates, ("along-line", "depth"), strict=True)
                if value is not None and abs(value) > PLAUSIBLE_SCALE_ERROR
            )
        other = outcomes.get("depth")
        if reading is None or other is None or isinstance(other, CalibrationError):
            return again
        return with_depth_reading(again, other, reading)

    def _solve_default(
        self,
        features: list[Any],
        config: CylinderConfig,
        context: SolveContext,
        radius: float,
        free: bool,
        depth: bool,
        share: bool = True,
        again: TargetSolution | None = None,
    ) -> TargetSolution:
        """:meth:`solve_default` with the along-line scale estimated (``free``) or held, and
        the depth scale estimated (``depth``) or held; ``again``, a solution of the same
        features with other scales, is solved again with these (:func:`_solved_again`), or
        from the start where that does not converge (``cluttered_camera`` with the radius
        free: holding its 0.5 % along-line scale moves the optimum too far)."""
        mismatch = radius_mismatch(
            [f.ellipse.semi_axes[1] for f in long_arcs(features)], config.radius_m
        )
        config = replace(
            config,
            refine=replace(config.refine, estimate_scale=free, estimate_depth_scale=depth),
        )
        subset = _subset_start(features, context)
        # The robot's sharing as learned on the whole recording, or by the other scales' solve.
        solved = subset[0] if subset is not None else None if again is None else again.subset_start
        learned = solved.shared if isinstance(solved, _SubsetStart) else None
        seed_history: dict[str, Any] = {}
        screened: list[Rejection] = []
        warm = None
        if subset is None and again is not None and isinstance(again.subset_start, _SubsetStart):
            context.progress("refine", 0, 1)
            warm = _solved_again(features, again.subset_start, config.refine)
            if warm.converged:
                screened = [r for r in again.rejections if r.stage == "outlier"]
                seed_history = {k: v for k, v in again.history.items() if k != "refine_cost"}
            else:  # the other model's optimum is far from this one's: solved from the start
                warm = None
        unwidened = False
        if subset is not None:
            start, features, screened = subset
            context.progress("refine", 0, 1)
            solved_prior = start.solved.problem.config
            same_prior = (solved_prior.robot_sigma_t_m, solved_prior.robot_sigma_r_rad) == (
                config.refine.robot_sigma_t_m,
                config.refine.robot_sigma_r_rad,
            )
            rows = [start.rows[f.index] for f in features]
            # The self-check's subsets: it reads their noise-model 1σ (subsets.model_sigma),
            # so neither the profiles' scatter nor the robot's shared error widens it here.
            unwidened = same_prior
            refined = (
                refine_subset(start.solved, rows, widen=False)
                if same_prior
                else refine_screened(start.solved, rows, config.refine)
                if context.screen_outliers
                else refine_subset(start.solved, rows, config.refine)
            )
        elif warm is not None:
            refined = warm
        else:
            T_init, cylinder0, seed_history = self._start(features, config, context)
            context.progress("refine", 0, 1)
            refined = self._refined(
                features,
                T_init,
                replace(cylinder0, radius=radius),
                config,
                context.screen_outliers,
            )
        context.progress("refine", 1, 1)
        outcome = None
        placed: list[RefineResult] = []
        if context.kinematics is not None:
            scans = [self._joint_scan(features, refined, context.kinematics)]
            for placement in context.placements:
                scans.append(
                    self._placement_scan(placement, refined.T_flange_sensor, config, context)
                )
            context.progress("kinematics", 0, 1)
            (joint, *placed), outcome = refine_kinematics(
                scans, refined.T_flange_sensor, config.refine, radius_m=config.radius_m
            )
            context.progress("kinematics", 1, 1)
            joint.used = refined.used
            joint.dropped = refined.dropped
            joint.warnings[:0] = [outcome.identifiability.describe()]
            refined = joint
        shared = shared_factors = None
        if outcome is None and not unwidened and share:
            refined, shared, shared_factors = with_shared(refined, learned)
        rejections = screened + [
            Rejection(features[j].index, features[j].stamp_ns, "outlier", reason)
            for j, reason in refined.dropped
        ]
        notes = arc_notes(features, config)
        if mismatch is not None:
            notes[notes.index(mismatch)] = mismatch + scale_verdict(refined)
        return TargetSolution(
            T_flange_sensor=refined.T_flange_sensor,
            section=CylinderSection(
                refined.cylinder,
                refined.radius_estimated,
                {
                    "sensor_sigma_m": refined.sensor_sigma_estimated_m,
                    "robot_sigma_t_m": config.refine.robot_sigma_t_m * refined.robot_sigma_scale,
                    "robot_sigma_r_rad": config.refine.robot_sigma_r_rad
                    * refined.robot_sigma_scale,
                },
                scale=None if refined.sigma_scale is None else refined.scale,
                scale_sigma=refined.sigma_scale,
                scale_radius_correlation=refined.scale_radius_correlation,
                line_noise=refined.line_noise,
                depth_scale=None if refined.sigma_depth_scale is None else refined.depth_scale,
                depth_scale_sigma=refined.sigma_depth_scale,
            ),
            method="default",
            samples_used=[features[j].index for j in refined.used],
            rejections=rejections,
            rms_residual_m=refined.rms_residual_m,
            sample_residuals_m={
                features[j].index: r for j, r in refined.sample_residuals_m.items()
            },
            sigma_translation_m=refined.sigma_translation_m,
            sigma_rotation_rad=refined.sigma_rotation_rad,
            warnings=[*refined.warnings, *notes],
            history={**seed_history, "refine_cost": list(refined.cost_history)},
            sample_fits=[features[j].record() for j in refined.used],
            noise_m=recording_scale_m(features, config.refine.sensor_sigma_m),
            kinematics=None if outcome is None else outcome.corrections,
            identifiability=None if outcome is None else outcome.identifiability,
            placement_sections=[CylinderSection(p.cylinder, p.radius_estimated) for p in placed],
            sigma_widening=widening(refined.sample_dispersion),
            sigma_shared=shared_factors,
            converged=refined.converged,
            robot_error=RobotError(
                config.refine.robot_sigma_t_m * refined.robot_sigma_scale,
                config.refine.robot_sigma_r_rad * refined.robot_sigma_scale,
                refined.robot_sigma_scale,
            )
            if config.refine.estimate_variance_factors
            else None,
            subset_start=(
                None
                if outcome is not None or refined.solved is None
                else _SubsetStart(
                    refined.solved,
                    {features[j].index: k for k, j in enumerate(refined.used)},
                    shared,
                )
            ),
        )

    @staticmethod
    def _joint_scan(
        features: list[FittedSample], refined: RefineResult, setup: KinematicSetup
    ) -> JointScan:
        """The samples a refinement kept, as one scan of the joint calibration."""
        used = [features[j] for j in refined.used]
        return JointScan(
            [f.inlier_points for f in used],
            np.array([f.stamp_ns for f in used], dtype=np.int64),
            refined.cylinder,
            setup,
        )

    def _placement_scan(
        self,
        placement: Placement,
        T_flange_sensor: FloatArray,
        config: CylinderConfig,
        context: SolveContext,
    ) -> JointScan:
        """Another placement's scan: its cylinder from the paper's solve on its ellipse
        centres, refined with the main recording's hand-eye and its outlier samples dropped."""
        features = placement.features
        radius = self._checked(features, config, replace(context, n_samples=len(features)))
        seed = self._seed(features, config, context, paper=False)
        start = replace(seed.cylinder, radius=radius)
        refined = self._refined(features, T_flange_sensor, start, config)
        return self._joint_scan(features, refined, placement.kinematics)

    @staticmethod
    def _refined(
        features: list[FittedSample],
        T_flange_sensor: FloatArray,
        cylinder: Cylinder,
        config: CylinderConfig,
        screen: bool = True,
    ) -> RefineResult:
        """The refinement with outlier samples dropped (with ``screen``), at the features'
        flange poses."""
        return refine_with_outlier_rejection(
            [f.stored_inliers for f in features],
            np.stack([f.T_base_flange for f in features]),
            T_flange_sensor,
            cylinder,
            config.refine,
            radius_m=config.radius_m,
            screen=screen,
        )

    def check_fit(self, solution: TargetSolution, config: CylinderConfig) -> None:
        """Refuse a solution whose residual one cylinder cannot explain: far above what the
        profiles' own free ellipses leave (the recording's scale)."""
        factor = PAPER_MISFIT_FACTOR if solution.method == "paper" else MISFIT_FACTOR
        if solution.rms_residual_m > factor * solution.noise_m:
            detail = (
                "the profiles are not cuts of one cylinder, though each is an elliptical arc"
                if solution.method == "default"
                else ""
            )
            raise ModelMismatch(
                mismatch_message("cylinder", solution.rms_residual_m, solution.noise_m, detail)
            )

    def model_doubt(self, features: list[Any], config: CylinderConfig) -> str | None:
        """Why the profiles' own shapes put the cylinder in doubt: at least half of them fit
        a rival shape clearly better than an ellipse (:attr:`.features.FittedSample.rival`);
        None otherwise. The whole recording decides then (:mod:`..rivals`)."""
        return shape_doubt([(f.index, f.rival) for f in features], "ellipse")

    def check_features(self, features: list[Any], config: CylinderConfig) -> None:
        """Nothing beyond extraction: each profile's ellipse meets the rival shapes there, and
        a free radius is judged by the joint fit of all profiles (:meth:`check_fit`), not by
        the spread of the ellipses' semi-minor axes, which a short arc leaves uncertain."""

    def offset_cost(
        self, features: list[Any], config: CylinderConfig, context: SolveContext
    ) -> Callable[[FloatArray], float] | None:
        """The refinement's final cost with the ellipses re-paired with other flange poses.

        The ellipses and the seed solve do not depend on the poses' offset and are computed
        once; a few dozen points per profile pin the offset as well as all of them. The
        first evaluation refines the seed at the features' own poses (the offset the search
        is centred on); each evaluation then starts at the solution of the lowest cost so
        far (:func:`.warm.refine_at_poses`: the same points at other poses) and runs at
        most :data:`OFFSET_SEARCH_ITERATIONS` linearisations. Near the optimum that
        converges; far from it (the search's first grid, 10 ms apart) the cost is an upper
        bound, high above the optimum's, which is all the grid needs to find the optimum's
        neighbours. Where the refinement at the features' poses fails (too few samples,
        an unobservable motion), every offset costs infinity.
        """
        radius = self._checked(features, config, context)
        seed = self._seed(features, config, context, paper=False)
        cylinder0 = replace(seed.cylinder, radius=radius)
        points = [f.inlier_points for f in features]
        light = replace(config.refine, max_points_per_profile=OFFSET_SEARCH_POINTS)
        try:
            refined = refine(
                points,
                np.stack([f.T_base_flange for f in features]),
                seed.T_flange_sensor,
                cylinder0,
                light,
                config.radius_m,
            )
        except CalibrationError:
            return lambda T_base_flange: float("inf")
        assert refined.solved is not None  # refine() always keeps it
        best = [(refined.cost_history[-1], refined.solved)]

        def cost(T_base_flange: FloatArray) -> float:
            try:
                again, value = refine_at_poses(best[0][1], T_base_flange, OFFSET_SEARCH_ITERATIONS)
            except CalibrationError:
                return float("inf")
            if value < best[0][0]:
                best[:] = [(value, again)]
            return value

        return cost

    def read_section(self, mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> ResultSection:
        """The ``cylinder`` section of a result file."""
        return read_cylinder_section(mapping, quality)


TARGET = CylinderTarget()
