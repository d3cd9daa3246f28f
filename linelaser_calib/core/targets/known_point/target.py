"""Hand-eye from one known point seen from many poses (the weld-seam paper, and better).

A weld-seam point p (taught in the base frame with the tool tip, or unknown) is scanned from
M flange poses; each profile is a V whose corner (:mod:`~...profile.corner`) is p in
the sensor frame, s_i = (x_i, 0, z_i). With the hand-eye X = (R_X, t_X) (``T_flange_sensor``)
and the reported flange poses (R_i, t_i) (``T_base_flange``)::

    p = R_i (R_X s_i + t_X) + t_i = R_i (x_i a1 + z_i a3 + t_X) + t_i,

where a1, a3 are R_X's first and third columns (y = 0 drops the second, as in the cylinder
paper). This is linear in (a1, a3, t_X) and, when p is not taught, in p.

Methods
-------
``paper`` (:func:`.paper.paper_correction`, weld-seam paper eq. 11-16)
    Start from an initial hand-eye and the taught point. Reconstruct p_i through every view.
    The scatter per axis is K_X = sign(X̄ − X_R) Σ|X_n − X̄| (eq. 14 as printed sums signed
    deviations, which is identically zero; the sum of absolute deviations is the evident
    intent), and ΔR = √(K_X² + K_Y² + K_Z²) (eq. 15). A two-step grid search over the hand-eye
    rotation vector minimises ΔR with the translation held, then the translation is shifted
    by the mean offset d = mean(p_i) − p (eq. 16).

    *Grid sizes.* The text says: step each component from r − Δ to r + Δ by Δ/20, "8000
    combinations", then ±Δ/20 by Δ/100. These disagree: ±Δ by Δ/20 is 41 values per axis
    (68 921 combinations), 8000 = 20³ would be 20 values. The experiment (§3) states the
    numbers it ran, ±0.4 rad by 0.02 (41 per axis) and then ±0.02 by 0.005 (9 per axis;
    Δ/100 would be 0.004), so those are the defaults (:attr:`.config.KnownPointConfig.grid_coarse`,
    ``grid_fine``); ``GridStep(0.4, 20)`` is the "8000" reading. Every candidate of a step
    is evaluated in one vectorised numpy expression (candidates × views).

    *Mapping to this package.* The paper corrects the rotation vector and translation of
    L_C (camera to calibration board) inside M_C = P_C⁻¹ C_C L_C with P_C, C_C fixed; moving
    L_C's rotation with its translation held keeps M_C's translation. Here the grid moves the
    hand-eye's own rotation vector, r = rotvec(R_X) + δ, with t_X held, the same search up to
    a fixed rotation of the grid axes. The translation step is the least-squares shift
    t_X ← t_X − mean_i R_iᵀ (p_i − p), which with the paper's constant orientation is exactly
    the base-frame offset d expressed in the flange frame, −Rᵀd.

``default`` (:func:`.linear.solve_linear` then :func:`.refine.refine_known_point`)
    1. Closed form: linear least squares in (a1, a3, t_X[, p]), then R_X = the SVD
       projection of [a1, a3 × a1, a3] onto SO(3) and t_X (and p) solved again with R_X
       fixed; exact on noise-free data whenever the views determine everything. With an
       initial hand-eye, prior rows (ridge) tie each unknown to it with the loose σ of the
       configuration, so the system stays solvable when the views leave directions
       undetermined (the paper's pattern); a1 and a3 then take their initial parts where the
       views are blind, and the projection leaves the start up to ~0.3 mm off, which step 2
       removes.
    2. Maximum likelihood (:mod:`.refine`, through the shared solver, as the cylinder's
       refinement): per-view flange-pose nuisance δ_i = (ω_i, τ_i) in the flange frame, true
       pose T_i·D(δ_i), with Gaussian priors σ_r, σ_t; the corner measured with the
       covariance of its line fits (floored) in x-z and ``aim_sigma_m`` along y (how far the
       laser plane may miss the point); a prior on the hand-eye from the initial one
       (``initial_sigma_*``, loose); p fixed when taught (or with ``point_sigma_m``), else
       estimated. Levenberg-Marquardt with the nuisance eliminated per view (Schur
       complement). Views whose residual is implausible (χ², 3 dof) are dropped and the
       solve repeated (the shared rejection loop). The 1σ counts the robot's error shared
       by neighbouring views as the residuals show it (:mod:`...shared_pose`, as the line
       target's): a weld program's views err alike by region, and their corners do not
       average that away.
    3. The profiler's x and z scale errors: each that the views read clearly off 1 is
       estimated with the hand-eye (the line target's ``auto``), and the 1σ of a held one
       counts what it may move the hand-eye (:func:`_with_scales`).

Observability (:func:`.diagnosis.analyse_known_point`)
------------------------------------------------------
The data-only information of the hand-eye (nuisance and point marginalised, initial-guess
prior left out) is eigen-analysed in lever-scaled units, as the cylinder refinement does:

- With one flange orientation for all views (the paper's eq. 6) the rotation is still
  determined if the weld point is seen at points of the laser plane that do not lie on one
  line. Stepping in z alone moves the point through the sensor along one line (for a sensor
  looking down, nearly its depth axis z); a rotation of the sensor about that line leaves
  every reconstructed point where it was. That one rotation, a roll of the laser plane about
  the path of the point, is unobservable; the two rotations across the line and the three
  translations are determined (p taught).
- With p unknown and one orientation, a shift of the sensor and the same shift of p look
  alike: the three translations are unobservable too.
- Tilting the flange between views, or moving the sensor sideways along the laser line,
  determines everything.

Unobservable directions keep the initial hand-eye's value and are named in the warnings:
after the solve with the loose prior, the default method solves again with those directions
pinned to the initial value (:attr:`.linear.HandEyePrior.pinned`), because even a direction the
views do not determine picks up a noise-driven pull that the loose prior would let move it
by a few tenths of a degree. The reported covariance keeps the loose prior's σ there.
Without an initial hand-eye they raise DegenerateError.

Model fit
---------
Each profile must be a V rather than a rival shape (a plane's line, a cylinder's or
sphere's arc), and its lines must not leave far more than the recording's other profiles'
(:func:`~...profile.corner.check_corner_recording`); no profile decides the target: where
too few profiles show a corner, or the fit below fails, the rival targets' full fits with
the poses (the line, the sphere, the cylinder) decide on the whole recording
(:mod:`..rivals`). The views' corners, mapped into the base frame, must meet in one point up
to the robot's pose error and the corner noise (about 0.05-0.1 mm: 1-2 times the robot's
σ_t on the weld presets). A residual over ten times σ_t is refused: a moving seam (the line
target's S-sweep gives ~100 mm) or corners of shapes that are no V.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import chdtri

from ...errors import DegenerateError, InputError, ModelMismatch, TooFewFeatures
from ...geometry import FloatArray, check_transform
from ...model_spread import with_held_sigma
from ...profile.along_line import PLAUSIBLE_SCALE_ERROR, ScalePair, scale_significant
from ...profile.corner import CornerSample, corner_doubt, corners_shown
from ...seam_grid import paper_correction, weld_points_base
from ...shared_pose import SharedPoseError, alone_among_neighbours, shared_pose_error
from ...solver import (
    N_HAND_EYE,
    Flag,
    recording_chi2_scale,
    recording_widening,
    solve_with_rejection,
)
from ...types import Rejection, Sample
from ..base import (
    ROBOT_PRIOR_EXCESS,
    Option,
    Progress,
    ResultSection,
    SolveContext,
    TargetSolution,
    mismatch_message,
    rejection_digest,
)
from .config import KnownPointConfig
from .features import extract_corner, extract_corners
from .linear import HandEyePrior, solve_linear
from .observability import KnownPointObservability, analyse_known_point
from .refine import KnownPointRefinement, paper_information, refine_known_point
from .section import KnownPoint, read_known_point_section

#: Accepted values of the ``method`` argument.
METHODS = ("paper", "default")
#: A solution whose RMS residual exceeds this multiple of the expected noise does not fit.
MISFIT_FACTOR = 10.0


@dataclass
class KnownPointResult:
    """Outcome of :func:`calibrate_known_point`.

    Attributes
    ----------
    T_flange_sensor : ndarray, shape (4, 4)
    point_base : ndarray, shape (3,)
        The weld point in the base frame, m: estimated, or the taught one.
    point_estimated : bool
    method : str
        ``paper`` or ``default``.
    samples_used : list of int
        Profile indices in the final solve.
    samples_rejected : list of Rejection
        Stages ``cleaning``, ``corner`` and ``outlier``.
    sample_residuals_m : dict of int to float
        Per used sample, the distance between the weld point reconstructed through it (its
        recorded pose, the estimated hand-eye) and ``point_base``, m.
    rms_residual_m : float
        RMS of those distances, m.
    uncertainty_translation_m, uncertainty_rotation_rad : ndarray, shape (3,), or None
        1σ of the hand-eye translation (m, flange axes) and rotation (rad, small angles about
        the sensor axes), priors included; None for ``paper``.
    uncertainty_point_m : ndarray, shape (3,), or None
        1σ of an estimated point, m.
    observability : KnownPointObservability
    warnings : list of str
        The observability statement when a direction is weak or undetermined, and others.
    history : dict of str to list of float
        ``paper_delta_r_m`` (ΔR at the start and after each grid step, m) or
        ``refine_cost`` (the maximum-likelihood cost per accepted step).
    corners : list of CornerSample
        The samples in the final solve.
    shared : SharedPoseError or None
        How the robot's error is shared by neighbouring views (``default``; None for
        ``paper`` or too few views), counted in the 1σ.
    sigma_widening, sigma_shared : ndarray, shape (6,), or None
        The hand-eye 1σ's factors (>= 1, [rotation, translation]) for the views' scatter
        beyond their noise model and, after that, for the robot's error the views share
        (:attr:`~..base.TargetSolution.sigma_widening`, ``sigma_shared``); None for
        ``paper``.
    sigma_model_spread : ndarray, shape (6,), or None
        What the profiler's x and z scales, held at 1, may move the hand-eye, counted in
        the 1σ (:func:`_with_scales`); None for ``paper`` or when both were estimated.
    scales, scale_sigmas : (float or None, float or None)
        The profiler's x and z scale errors estimated with the hand-eye, and their 1σ; None
        where held at 1.
    """

    T_flange_sensor: FloatArray
    point_base: FloatArray
    point_estimated: bool
    method: str
    samples_used: list[int]
    samples_rejected: list[Rejection]
    sample_residuals_m: dict[int, float]
    rms_residual_m: float
    uncertainty_translation_m: FloatArray | None
    uncertainty_rotation_rad: FloatArray | None
    uncertainty_point_m: FloatArray | None
    observability: KnownPointObservability
    warnings: list[str]
    history: dict[str, list[float]]
    corners: list[CornerSample]
    shared: SharedPoseError | None = None
    sigma_widening: FloatArray | None = None
    sigma_shared: FloatArray | None = None
    sigma_model_spread: FloatArray | None = None
    scales: ScalePair = (None, None)
    scale_sigmas: ScalePair = (None, None)


def _observability_warnings(observability: KnownPointObservability, method: str) -> list[str]:
    if not observability.directions:
        return []
    text = observability.statement()
    weak = [d for d in observability.directions if d.status == "weak"]
    if weak:
        text += " Weakly determined: " + " ".join(
            f"({k + 1}) {d.description}." for k, d in enumerate(weak)
        )
    if method == "paper" and observability.unobservable:
        text += (
            " The paper's grid search sees no change of the scatter along the undetermined "
            "directions, so its choice there is arbitrary within the grid."
        )
    return [text]


def _inputs(
    T_flange_sensor_initial: ArrayLike | None, point_base: ArrayLike | None, method: str
) -> tuple[FloatArray | None, FloatArray | None]:
    """The checked initial hand-eye and taught point; ``paper`` needs both."""
    if method not in METHODS:
        raise InputError(f"method must be one of {METHODS}, got {method!r}")
    X0: FloatArray | None = None
    if T_flange_sensor_initial is not None:
        try:
            X0 = check_transform(T_flange_sensor_initial, tolerance=1e-4)
        except ValueError as exc:
            raise InputError(f"the initial hand-eye is not a rigid transform: {exc}") from exc
    taught: FloatArray | None = None
    if point_base is not None:
        taught = np.asarray(point_base, dtype=np.float64)
        if taught.shape != (3,) or not np.all(np.isfinite(taught)):
            raise InputError(f"the weld point must be 3 finite numbers in m, got {point_base}")
    if method == "paper" and (X0 is None or taught is None):
        raise InputError(
            "the paper's method corrects an existing hand-eye against a taught point: give "
            "both the initial hand-eye and the weld point (x, y, z in m, base frame)"
        )
    return X0, taught


def _check_count(
    corners: list[CornerSample], n_samples: int, rejections: list[Rejection], min_samples: int
) -> None:
    if len(corners) < min_samples:
        found, doubted = corners_shown(corners)
        raise TooFewFeatures(
            f"only {found} of {n_samples} recorded profiles show a weld-seam corner{doubted}, "
            f"and at least {min_samples} are needed. "
            + rejection_digest(rejections)
            + "Aim the laser line across the seam through the taught point, both flanks in view.",
            found,
        )


def calibrate_known_point(
    samples: list[Sample],
    T_flange_sensor_initial: ArrayLike | None,
    point_base: ArrayLike | None,
    config: KnownPointConfig,
    method: str,
    seed: int = 0,
) -> KnownPointResult:
    """Correct (or find) the hand-eye from views of one weld-seam point.

    The pipeline reaches the same solves through :class:`KnownPointTarget`; this function
    is the whole known-point calibration on its own (benches, tests).

    Parameters
    ----------
    samples : list of Sample
        Profiles of the V joint paired with their flange poses (sensor frame, m).
    T_flange_sensor_initial : array-like, shape (4, 4), or None
        The old hand-eye. Required for ``paper``; for ``default`` it is the start and a loose
        prior (``initial_sigma_*``) that decides only what the views cannot.
    point_base : array-like, shape (3,), or None
        The taught weld point in the base frame, m. Required for ``paper``; None estimates it
        (``default``).
    config : KnownPointConfig
    method : str
        ``default`` (closed form + maximum likelihood) or ``paper`` (grid search + shift).
    seed : int
        Of the RANSAC corner fits (each sample's own generator,
        :func:`~linelaser_calib.core.targets.runs.sample_rng`).

    Returns
    -------
    KnownPointResult

    Raises
    ------
    InputError
        Malformed input, or ``paper`` without an initial hand-eye or a taught point.
    DegenerateError
        Too few corners, or (without an initial hand-eye) views that leave a direction
        undetermined; the message names the views to add.
    SolverError
    """
    X0, taught = _inputs(T_flange_sensor_initial, point_base, method)
    corner_samples, rejections = extract_corners(samples, config, seed)
    _check_count(corner_samples, len(samples), rejections, config.min_samples)
    if method == "paper":
        assert X0 is not None and taught is not None  # checked by _inputs
        return _paper_result(corner_samples, rejections, X0, taught, config)
    return _with_scales(
        _default_result(corner_samples, rejections, X0, taught, config), X0, taught, config
    )


def _stack(corners: list[CornerSample]) -> tuple[FloatArray, FloatArray, FloatArray]:
    return (
        np.array([c.corner_xz for c in corners]),
        np.array([c.covariance_xz for c in corners]),
        np.array([c.T_base_flange for c in corners]),
    )


def _residuals_m(
    corners: list[CornerSample], X: FloatArray, point: FloatArray
) -> tuple[dict[int, float], float]:
    c, _, T = _stack(corners)
    d = np.linalg.norm(weld_points_base(c, T, X) - point, axis=1)
    return {s.index: float(v) for s, v in zip(corners, d, strict=True)}, float(
        np.sqrt(np.mean(d**2))
    )


def _paper_result(
    corners: list[CornerSample],
    rejections: list[Rejection],
    X0: FloatArray,
    point: FloatArray,
    config: KnownPointConfig,
) -> KnownPointResult:
    c, _, T = _stack(corners)
    corrected = paper_correction(c, T, X0, point, config.grid_coarse, config.grid_fine)
    X = corrected.T_flange_sensor
    observability = analyse_known_point(
        paper_information(c, T, X, point, config), c, T, X, False, config
    )
    warnings = _observability_warnings(observability, "paper")
    if corrected.on_grid_edge:
        warnings.append(
            "the coarse grid's best rotation lies on its edge "
            f"(±{config.grid_coarse.half_width_rad:.2f} rad): the initial hand-eye may be "
            "further off than the search range; widen grid_coarse"
        )
    residuals, rms = _residuals_m(corners, X, point)
    return KnownPointResult(
        T_flange_sensor=X,
        point_base=point.copy(),
        point_estimated=False,
        method="paper",
        samples_used=[s.index for s in corners],
        samples_rejected=sorted(rejections, key=lambda r: r.index),
        sample_residuals_m=residuals,
        rms_residual_m=rms,
        uncertainty_translation_m=None,
        uncertainty_rotation_rad=None,
        uncertainty_point_m=None,
        observability=observability,
        warnings=warnings,
        history={"paper_delta_r_m": [float(v) for v in corrected.delta_r_m]},
        corners=corners,
    )


def _default_result(
    corners: list[CornerSample],
    rejections: list[Rejection],
    X0: FloatArray | None,
    taught: FloatArray | None,
    config: KnownPointConfig,
    learned: SharedPoseError | None = None,
    screen: bool = True,
    free_scales: tuple[bool, bool] = (False, False),
) -> KnownPointResult:
    """Closed form, maximum likelihood with outlier views dropped (with ``screen``), the
    undetermined directions pinned, the profiler's x and z scale errors estimated with
    ``free_scales``; the 1σ counts the robot's error shared by neighbouring views
    (:mod:`...shared_pose`: as ``learned`` on a superset of the corners, else learned
    here)."""
    prior = (
        None
        if X0 is None
        else HandEyePrior(X0, config.initial_sigma_rotation_rad, config.initial_sigma_translation_m)
    )
    estimate_point = taught is None or config.point_sigma_m > 0.0
    c, cov, T = _stack(corners)
    X, point = solve_linear(c, T, taught, prior, config.robot_sigma_t_m)
    limit = float(chdtri(3, config.outlier_probability))  # P(chi2 with 3 dof > limit)

    def solve_subset(
        keep: list[int], previous: KnownPointRefinement | None
    ) -> KnownPointRefinement:
        X_start = X if previous is None else previous.T_flange_sensor
        point_start = point if previous is None else previous.point_base
        return refine_known_point(
            c[keep],
            cov[keep],
            T[keep],
            X_start,
            point_start,
            estimate_point,
            prior,
            config,
            free_scales,
        )

    def flag(refined: KnownPointRefinement, keep: list[int]) -> list[Flag]:
        flags = []
        scale = recording_chi2_scale(refined.view_chi2, 3)
        doubted = [int(j) for j in np.flatnonzero(refined.view_chi2 / scale > limit)]
        alone = alone_among_neighbours(refined.views(), doubted, limit)
        for j in alone:
            view = keep[j]
            residual = float(
                np.linalg.norm(
                    weld_points_base(c[[view]], T[[view]], refined.T_flange_sensor)[0]
                    - refined.point_base
                )
            )
            flags.append(
                Flag(
                    float(refined.view_chi2[j]),
                    int(j),
                    f"the view's weld point lies {residual * 1e3:.3f} mm from the others' "
                    f"(normalised chi2 {refined.view_chi2[j]:.1f} at the robot's 1 sigma "
                    f"{config.robot_sigma_t_m * 1e3:.3f} mm, {refined.view_chi2[j] / scale:.1f} "
                    "on the scale of the recording's other views"
                    + ("" if math.isinf(alone[j]) else f", {alone[j]:.1f} given its neighbours")
                    + f", > {limit:.1f} for 3 dof): wrong corner, a miss of the taught point, or "
                    "motion during the scan",
                )
            )
        return flags

    outcome = solve_with_rejection(
        len(corners), solve_subset, flag, config.max_outlier_fraction, config.min_samples, screen
    )
    refined, keep = outcome.outcome, outcome.kept
    X, point = refined.T_flange_sensor, refined.point_base
    dropped = [
        Rejection(corners[i].index, corners[i].stamp_ns, "outlier", reason)
        for i, reason in outcome.dropped
    ]
    used = [corners[i] for i in keep]
    c_used, cov_used, T_used = _stack(used)
    observability = analyse_known_point(
        refined.information_data, c_used, T_used, X, estimate_point, config
    )
    missing = observability.unobservable
    if missing and prior is None:
        raise DegenerateError(
            "without an initial hand-eye the views must determine everything. "
            + observability.statement()
            + " Give the old hand-eye as the initial one, or add such views."
        )
    if missing and prior is not None:
        # Keep the undetermined directions at the initial value exactly (noise would move
        # them within the loose prior): solve again in the observable subspace.
        scale = np.array([observability.lever_m] * 3 + [1.0] * 3)
        pinned = replace(prior, pinned=np.array([d.vector * scale for d in missing]))
        refined = refine_known_point(
            c_used, cov_used, T_used, X, point, estimate_point, pinned, config, free_scales
        )
        X, point = refined.T_flange_sensor, refined.point_base
    warnings = _observability_warnings(observability, "default")
    if not refined.converged:
        warnings.append(
            f"the refinement stopped after {refined.iterations} iterations without converging; "
            "the result may be inaccurate"
        )
    residuals, rms = _residuals_m(used, X, point)
    widen, scatter = recording_widening(refined.view_chi2, 3, len(refined.covariance))
    if scatter is not None:
        warnings.append(scatter)
    own = widen * np.sqrt(np.diag(refined.covariance))
    shared = shared_pose_error(refined.views(), learned)
    sigma = own if shared is None else np.maximum(own, np.sqrt(np.diag(shared.covariance)))
    if shared is not None:
        note = shared.excess_note(ROBOT_PRIOR_EXCESS)
        if note is not None:
            warnings.append(note)
    return KnownPointResult(
        T_flange_sensor=X,
        point_base=point,
        point_estimated=estimate_point,
        method="default",
        samples_used=[s.index for s in used],
        samples_rejected=sorted(rejections + dropped, key=lambda r: r.index),
        sample_residuals_m=residuals,
        rms_residual_m=rms,
        uncertainty_translation_m=sigma[3:6],
        uncertainty_rotation_rad=sigma[:3],
        uncertainty_point_m=sigma[6:9] if estimate_point else None,
        observability=observability,
        warnings=warnings,
        history={"refine_cost": list(refined.cost_history)},
        corners=used,
        shared=shared,
        sigma_widening=np.full(N_HAND_EYE, widen),
        sigma_shared=None if shared is None else sigma[:N_HAND_EYE] / own[:N_HAND_EYE],
        scales=(
            float(refined.scales[0]) if free_scales[0] else None,
            float(refined.scales[1]) if free_scales[1] else None,
        ),
        scale_sigmas=refined.scale_sigmas,
    )


def _with_scales(
    result: KnownPointResult,
    X0: FloatArray | None,
    taught: FloatArray | None,
    config: KnownPointConfig,
) -> KnownPointResult:
    """``result`` (the profiler's scales held at 1), or the same views solved with each of
    the x and z scale errors estimated that reads clearly off 1 and plausible
    (:func:`~...profile.along_line.scale_significant`, within
    :data:`~...profile.along_line.PLAUSIBLE_SCALE_ERROR`; the line target's ``auto``). A
    scale held is still known only to its reading, so the held solve's 1σ counts what it
    may move the hand-eye, the larger of the move to the solve that estimates both and what
    their own 1σ adds, per axis (:func:`~...model_spread.with_held_sigma`, the line's and
    the cylinder's rule).

    The views' corners span a few tens of mm along x and z, so a scale error of a few
    tenths of a percent moves each corner by tens of µm, alike in neighbouring views: on
    the stress matrix's ``scales`` face (x 0.6 % long, z 0.2 % short) the solve with them
    held was 3.64 times its 1σ off on its worst axis (seeds 0-2; 2.30 clean). The views
    determine the scales: they read x +0.55 to +0.64 % (1σ 0.11-0.13 %) and z -0.11 to
    -0.24 % (1σ 0.06-0.07 %) there, and within 1.4 of their 1σ of 0 on clean views."""
    if result.uncertainty_rotation_rad is None:
        return result

    def solve(free_scales: tuple[bool, bool]) -> KnownPointResult:
        outcome = _default_result(
            result.corners, [], X0, taught, config, result.shared, False, free_scales
        )
        return replace(outcome, samples_rejected=result.samples_rejected)

    free = solve((True, True))
    x, z = (
        s is not None and abs(s) <= PLAUSIBLE_SCALE_ERROR and scale_significant(s, sigma)
        for s, sigma in zip(free.scales, free.scale_sigmas, strict=True)
    )
    if x and z:
        return free
    held = solve((x, z)) if x or z else result
    widened = with_held_sigma(_solution(held, [], config), _solution(free, [], config))
    return replace(
        held,
        uncertainty_rotation_rad=widened.sigma_rotation_rad,
        uncertainty_translation_m=widened.sigma_translation_m,
        sigma_model_spread=widened.sigma_model_spread,
    )


def _solution(
    result: KnownPointResult, rejections: list[Rejection], config: KnownPointConfig
) -> TargetSolution:
    """The pipeline's view of a known-point result; ``rejections`` are the earlier ones.

    The noise a view's residual carries on clean data is about the robot's position error.
    """
    earlier = {(r.index, r.stage) for r in rejections}
    section = KnownPoint(
        result.point_base,
        result.point_estimated,
        result.uncertainty_point_m,
        result.scales,
        result.scale_sigmas,
    )
    return TargetSolution(
        T_flange_sensor=result.T_flange_sensor,
        section=section,
        method=result.method,
        samples_used=list(result.samples_used),
        rejections=[r for r in result.samples_rejected if (r.index, r.stage) not in earlier],
        rms_residual_m=result.rms_residual_m,
        sample_residuals_m=dict(result.sample_residuals_m),
        sigma_translation_m=result.uncertainty_translation_m,
        sigma_rotation_rad=result.uncertainty_rotation_rad,
        warnings=list(result.warnings),
        history=dict(result.history),
        sample_fits=[c.record() for c in result.corners],
        noise_m=config.robot_sigma_t_m,
        subset_start=result.shared,
        sigma_widening=result.sigma_widening,
        sigma_shared=result.sigma_shared,
        sigma_model_spread=result.sigma_model_spread,
    )


class KnownPointTarget:
    """The known-point target (see the module docstring)."""

    name = "known_point"
    title = "known point"
    summary = "one fixed point such as a weld-seam corner, seen from many poses"
    methods = METHODS
    estimates_clock_offset = False
    config_type = KnownPointConfig
    options: Mapping[str, Option] = {
        "point_m": Option(
            "point_m",
            required_by=("paper",),
            why_required="the taught point (x, y, z in m, base frame), against which the "
            "paper's method corrects the old hand-eye",
        ),
        "min_samples": Option("min_samples"),
        "robot_sigma_t_m": Option("robot_sigma_t_m", methods=("default",)),
        "robot_sigma_r_rad": Option("robot_sigma_r_rad", methods=("default",)),
        "initial": Option(
            "",
            required_by=("paper",),
            why_required="the old hand-eye (a result YAML with its hand_eye section)",
        ),
    }
    #: Targets whose full model may explain a recording instead (:mod:`..rivals`).
    rivals = ("line", "sphere", "cylinder")

    def validate(
        self, sample: Sample, config: KnownPointConfig, rng: np.random.Generator
    ) -> Rejection | None:
        """The cleaning and V-corner fit of one sample."""
        outcome = extract_corner(sample, config, rng)
        return outcome if isinstance(outcome, Rejection) else None

    def extract(
        self,
        samples: list[Sample],
        config: KnownPointConfig,
        seed: int,
        progress: Progress,
        workers: int = 1,
    ) -> tuple[list[Any], list[Rejection]]:
        """Every sample's V corner."""
        corners, rejections = extract_corners(samples, config, seed, progress, workers)
        return list(corners), rejections

    def _solve(
        self, method: str, features: list[Any], config: KnownPointConfig, context: SolveContext
    ) -> TargetSolution:
        X0, taught = _inputs(context.initial_T_flange_sensor, config.point_m, method)
        rejections = list(context.rejections)
        _check_count(features, context.n_samples, rejections, config.min_samples)
        if method == "paper":
            assert X0 is not None and taught is not None  # checked by _inputs
            result = _paper_result(features, rejections, X0, taught, config)
        else:
            warm = context.warm_start
            learned = None if warm is None else warm.subset_start
            section = None if warm is None else warm.section
            result = _default_result(
                features,
                rejections,
                X0,
                taught,
                config,
                learned if isinstance(learned, SharedPoseError) else None,
                context.screen_outliers,
                section.free_scales if isinstance(section, KnownPoint) else (False, False),
            )
            if warm is None:
                result = _with_scales(result, X0, taught, config)
        return _solution(result, rejections, config)

    def solve_paper(
        self, features: list[Any], config: KnownPointConfig, context: SolveContext
    ) -> TargetSolution:
        """The weld-seam paper's grid search and translation shift."""
        return self._solve("paper", features, config, context)

    def solve_default(
        self, features: list[Any], config: KnownPointConfig, context: SolveContext
    ) -> TargetSolution:
        """Closed form, then maximum likelihood with the robot's pose error."""
        return self._solve("default", features, config, context)

    def check_features(self, features: list[Any], config: KnownPointConfig) -> None:
        """Nothing beyond extraction: each profile's corner meets the rival shapes there."""

    def model_doubt(self, features: list[Any], config: KnownPointConfig) -> str | None:
        """Why the profiles' own shapes put the known point in doubt
        (:func:`~...profile.corner.corner_doubt`); the whole recording decides then."""
        return corner_doubt(features)

    def check_fit(self, solution: TargetSolution, config: KnownPointConfig) -> None:
        """Refuse views whose corners do not meet in one point."""
        if solution.rms_residual_m > MISFIT_FACTOR * solution.noise_m:
            detail = (
                "the views' corners do not meet in one point (a seam scanned along its length "
                "is the line target)"
            )
            raise ModelMismatch(
                mismatch_message("known point", solution.rms_residual_m, solution.noise_m, detail)
            )

    def offset_cost(
        self, features: list[Any], config: KnownPointConfig, context: SolveContext
    ) -> Callable[[FloatArray], float] | None:
        """Not supported: step-and-shoot views of one point carry no clock information."""
        return None

    def read_section(self, mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> ResultSection:
        """The ``known_point`` section of a result file."""
        return read_known_point_section(mapping, quality)


TARGET = KnownPointTarget()
