"""The sphere target: a tooling ball seen from many flange poses.

Per profile (:func:`extract_feature`): cleaning, then a RANSAC circle (centre, radius r) in
the laser plane; a profile without a circle that a rival shape (a line, a V) fits clearly
better is rejected naming it (:mod:`.shape`). A profile whose circle a rival fits better one
by one is kept: a real profiler's smooth shape error makes a conic beat a circle on almost
any single profile. Per recording (:meth:`SphereTarget.extract`): a profile whose circle
leaves far more than the recording's other profiles is set aside; a recording most of whose
profiles fit a rival shape better puts the sphere in doubt (:meth:`SphereTarget.model_doubt`),
and the whole recording decides: a rival target (the cylinder, the seam targets) fitted with
the poses must explain it clearly better for the recording to be refused (:mod:`..rivals`);
so too where too few profiles show a circle. The sphere centre lies
√(R² − r²) off the plane on one side.

- ``paper``: the fixed-point linear solve of the tools that calibrate profilers on a
  sphere, projected onto SO(3) and polished (:mod:`.model`); the side resolved from the
  data unless given; an unknown radius by the least centre scatter. Directions the poses
  leave undetermined are named from the fixed-point equations' information (with the
  robot's stated σ as the centres' noise).
- ``default``: that solve as the start, then maximum likelihood on every inlier point with
  each sample's robot pose error as nuisance (:mod:`.refine`, the shared solver), samples
  with outlying residuals dropped, the covariance (1σ) and the directions the poses leave
  weak or undetermined named.

:meth:`SphereTarget.check_fit` refuses a result whose residual lies far above the noise
(the circles' median RMS residual over the recording's profiles for ``default``; what the
robot's σ explains for ``paper``) or
whose pose corrections lie far above the robot's σ.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from linelaser_calib.core.errors import (
    CalibrationError,
    DegenerateError,
    ModelMismatch,
    ProfileRejected,
    TooFewFeatures,
)
from linelaser_calib.core.geometry import FloatArray
from linelaser_calib.core.model_check import effective_count, shape_doubt
from linelaser_calib.core.observability import poor_directions, scaled_eigen
from linelaser_calib.core.profile.along_line import (
    PLAUSIBLE_SCALE_ERROR,
)
from linelaser_calib.core.profile.cleaning import clean_profile
from linelaser_calib.core.shared_pose import SharedPoseError, shared_pose_error
from linelaser_calib.core.solver import Flag, dispersion_warning, solve_with_rejection, widening
from linelaser_calib.core.targets.base import (
    Option,
    Progress,
    RobotError,
    SolveContext,
    TargetSolution,
    mismatch_message,
    rejection_digest,
)
from linelaser_calib.core.targets.runs import extract_each
from linelaser_calib.core.targets.sphere.circle import (
    CircleFit,
    circle_residuals,
    fit_circle_algebraic,
    fit_circle_geometric,
    fit_circle_ransac,
)
from linelaser_calib.core.targets.sphere.config import SphereConfig, estimates_scale
from linelaser_calib.core.targets.sphere.features import SphereFeature
from linelaser_calib.core.targets.sphere.model import (
    SIDE_LABELS,
    FixedPointSolution,
    centres_in_sensor,
    estimate_radius,
    fixed_point_information,
    fixed_point_residuals,
    resolve_side,
    side_from_label,
    side_is_clear,
    solve_fixed_point,
)
from linelaser_calib.core.targets.sphere.outliers import sample_flags
from linelaser_calib.core.targets.sphere.plan import SpherePlanner
from linelaser_calib.core.targets.sphere.refine import (
    N_LOCAL,
    SphereRefinement,
    SphereState,
    refine_sphere,
)
from linelaser_calib.core.targets.sphere.scales import read_as_depth, with_scale_model_spread
from linelaser_calib.core.targets.sphere.section import SphereSection, read_sphere_section
from linelaser_calib.core.targets.sphere.shape import (
    circle_rival_rejection,
    compare_circle,
    set_aside_outliers,
)
from linelaser_calib.core.types import Rejection, Sample

#: Circle radii may exceed a given sphere radius by this share plus
#: :data:`RADIUS_MARGIN_M` (noise at the equator).
RADIUS_MARGIN = 0.02
RADIUS_MARGIN_M = 5e-4


def extract_feature(
    sample: Sample, config: SphereConfig, rng: np.random.Generator
) -> SphereFeature | Rejection:
    """Clean one profile, fit its circle and weigh it against the rival shapes; a rejection
    says why it failed (a :class:`~linelaser_calib.core.model_check.RivalRejection` when no
    circle was found and a rival fits clearly better)."""
    try:
        cleaned = clean_profile(sample.points, config.cleaning)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "cleaning", str(exc))
    largest = None
    if config.radius_m is not None:
        largest = config.radius_m * (1.0 + RADIUS_MARGIN) + RADIUS_MARGIN_M
    xz = cleaned.points_xz
    try:
        circle: CircleFit | ProfileRejected = fit_circle_ransac(xz, config.circle, rng, largest)
    except ProfileRejected as exc:
        circle = exc
    if isinstance(circle, CircleFit):
        centre, radius = circle.centre_xz, circle.radius_m
    else:
        # No usable arc: the least-squares circle of the whole profile meets the rivals.
        try:
            centre, radius = fit_circle_geometric(xz, *fit_circle_algebraic(xz))
        except ValueError:
            return Rejection(sample.index, sample.stamp_ns, "circle", str(circle))
    comparison = compare_circle(xz, centre, radius)
    if isinstance(circle, ProfileRejected):
        if comparison.rival_wins:
            return circle_rival_rejection(sample.index, sample.stamp_ns, comparison)
        return Rejection(sample.index, sample.stamp_ns, "circle", str(circle))
    points = cleaned.points[circle.inliers]
    return SphereFeature(
        sample.index,
        sample.stamp_ns,
        sample.T_base_flange,
        circle,
        points,
        effective_count(circle_residuals(xz[circle.inliers], centre, radius)),
        comparison if comparison.rival_wins else None,
    )


def _fmt(v: FloatArray) -> str:
    return "(" + ", ".join(f"{x:+.2f}" for x in v) + ")"


def describe_direction(vector: FloatArray, status: str) -> str:
    """Plain words for a poorly determined hand-eye direction seen through a sphere.

    ``vector`` (6,) is in scaled units (rotation about the sensor axes times the lever,
    then translation along the flange axes).
    """
    cannot = "cannot" if status == "unobservable" else "can hardly"
    if float(vector[:3] @ vector[:3]) >= 0.5:
        axis = vector[:3] / np.linalg.norm(vector[:3])
        return (
            f"rotation of the sensor about {_fmt(axis)} (sensor axes) {cannot} be seen: the "
            "sphere centres barely move when it changes. Move the ball through the sensor's "
            "field between poses (different depths and positions along the line) and turn the "
            "line about its viewing axis"
        )
    direction = vector[3:] / np.linalg.norm(vector[3:])
    return (
        f"translation of the sensor along {_fmt(direction)} (flange frame) {cannot} be told "
        "from a shift of the sphere: rotate the flange between poses by at least 20 deg about "
        f"axes perpendicular to {_fmt(direction)}"
    )


class SphereTarget:
    """The sphere target (see the module docstring); satisfies the target protocol."""

    name = "sphere"
    title = "sphere"
    summary = "a sphere (tooling ball) scanned from many poses: each profile a circle"
    methods: tuple[str, ...] = ("paper", "default")
    estimates_clock_offset = False
    config_type = SphereConfig
    options: Mapping[str, Option] = {
        "radius_m": Option("radius_m"),
        "centre_side": Option("centre_side"),
        "sensor_sigma_m": Option("refine.sensor_sigma_m", methods=("default",)),
        "robot_sigma_t_m": Option("refine.robot_sigma_t_m"),
        "robot_sigma_r_rad": Option("refine.robot_sigma_r_rad"),
        "min_samples": Option("min_samples"),
        "scale": Option("scale", methods=("default",)),
    }
    #: Pose planning (:mod:`linelaser_calib.core.planning`).
    planner = SpherePlanner()
    #: Targets whose full model may explain a recording instead (:mod:`..rivals`).
    rivals = ("cylinder", "known_point", "line")
    #: Its residual check (against what each profile's own shape fit leaves) may fail on a
    #: real profiler's shape error alone: kept with a warning where no rival does better.
    soft_fit_check = True

    def validate(
        self, sample: Sample, config: SphereConfig, rng: np.random.Generator
    ) -> Rejection | None:
        """The sample's rejection, or None when its profile shows a circular arc."""
        outcome = extract_feature(sample, config, rng)
        return outcome if isinstance(outcome, Rejection) else None

    def extract(
        self,
        samples: list[Sample],
        config: SphereConfig,
        seed: int,
        progress: Progress,
        workers: int = 1,
    ) -> tuple[list[Any], list[Rejection]]:
        """The circles of all samples and the rejections; profiles whose circle is an outlier
        among the recording's, by its RMS over its effective points, are set aside."""
        features, rejections = extract_each(
            samples, config, seed, extract_feature, progress, "circle", workers
        )
        aside = set_aside_outliers(
            np.array([f.circle.rms_m for f in features]),
            np.array([f.n_effective for f in features]),
            config.profile_outlier_sigmas,
        )
        rejections += [
            Rejection(features[k].index, features[k].stamp_ns, "circle", reason)
            for k, reason in aside
        ]
        dropped = {k for k, _ in aside}
        return [f for k, f in enumerate(features) if k not in dropped], rejections

    def _require(
        self, features: list[SphereFeature], config: SphereConfig, context: SolveContext
    ) -> None:
        """Refuse too few circles (the pipeline first asks whether another target explains
        the recording, :mod:`..rivals`)."""
        if len(features) >= config.min_samples:
            return
        raise TooFewFeatures(
            f"only {len(features)} profiles show a usable circle; the sphere target needs "
            f"{config.min_samples}. {rejection_digest(context.rejections)}Scan the ball from "
            "more poses with the line across it.",
            len(features),
        )

    def _fixed_point(
        self, features: list[SphereFeature], config: SphereConfig
    ) -> tuple[FixedPointSolution, list[str]]:
        """Radius, side and the fixed-point solve, with warnings."""
        T = np.stack([f.T_base_flange for f in features])
        C = np.stack([f.circle.centre_xz for f in features])
        r = np.array([f.circle.radius_m for f in features])
        side = None if config.centre_side is None else side_from_label(config.centre_side)
        radius = config.radius_m or estimate_radius(T, C, r, side)
        warnings: list[str] = []
        if side is not None:
            return solve_fixed_point(T, C, r, radius, side), warnings
        better, worse = resolve_side(T, C, r, radius)
        if not side_is_clear(better, worse):
            warnings.append(
                f"the data barely tell which side of the laser plane the sphere centre lies on "
                f"(centre scatter {better.scatter_m * 1e3:.3f} mm on the "
                f"{SIDE_LABELS[better.side]} side, {worse.scatter_m * 1e3:.3f} mm on the other); "
                "give the side if you know it, or add poses that cut the ball at different "
                "heights and turn the flange"
            )
        return better, warnings

    def _expected_scatter_m(self, config: SphereConfig, lever_m: float) -> float:
        """3-D RMS centre scatter the robot's stated σ explains, m."""
        per_axis = math.hypot(
            config.refine.robot_sigma_t_m, lever_m * config.refine.robot_sigma_r_rad
        )
        return math.sqrt(3.0) * per_axis

    def solve_paper(
        self, features: list[Any], config: SphereConfig, context: SolveContext
    ) -> TargetSolution:
        """Fixed-point linear solve, SO(3) projection and polish."""
        self._require(features, config, context)
        fixed, warnings = self._fixed_point(features, config)
        T = np.stack([f.T_base_flange for f in features])
        distances = np.linalg.norm(
            fixed_point_residuals(T, fixed.centres_sensor, fixed.T_flange_sensor)
            - fixed.centre_base,
            axis=1,
        )
        lever = float(np.median(np.linalg.norm(fixed.centres_sensor, axis=1)))
        expected = self._expected_scatter_m(config, lever)
        if fixed.scatter_m <= config.max_scatter_ratio * expected:
            # The centres' per-axis noise the robot's stated sigma explains.
            information = fixed_point_information(
                T, fixed.centres_sensor, fixed.T_flange_sensor
            ) / (expected**2 / 3.0)
            warnings += self._diagnose(np.linalg.pinv(information), lever, config)
        section = SphereSection(
            fixed.centre_base,
            fixed.radius_m,
            fixed.side,
            radius_estimated=config.radius_m is None,
            side_estimated=config.centre_side is None,
        )
        return TargetSolution(
            T_flange_sensor=fixed.T_flange_sensor,
            section=section,
            method="paper",
            samples_used=[f.index for f in features],
            rejections=[],
            rms_residual_m=fixed.scatter_m,
            sample_residuals_m={
                f.index: float(d) for f, d in zip(features, distances, strict=True)
            },
            sigma_translation_m=None,
            sigma_rotation_rad=None,
            warnings=warnings,
            history={},
            sample_fits=[f.record() for f in features],
            noise_m=expected,
        )

    def solve_default(
        self, features: list[Any], config: SphereConfig, context: SolveContext
    ) -> TargetSolution:
        """Maximum likelihood on every point, outlier samples dropped, 1σ and diagnosis.

        Started at the fixed-point solve, or at the context's warm start (the self-check's
        solves of subsets), whose noise levels then weight the points and poses from the
        first round on. The along-line scale is estimated with ``{setting:scale} free``
        (:func:`estimates_scale`); a warm start keeps the whole recording's choice. With
        ``auto`` (default) it is solved held and estimated, and the recording decides which
        is kept, the 1σ counting the move between them (:func:`with_scale_model_spread`).
        """
        self._require(features, config, context)
        warm = context.warm_start
        free = estimates_scale(
            config, None if warm is None else getattr(warm.section, "scale", None) is not None
        )
        chooses = not free and warm is None and config.scale == "auto"
        solution: TargetSolution | DegenerateError
        try:
            solution = self._solve_default(features, config, context, free)
        except DegenerateError as exc:
            if not chooses:
                raise
            solution = exc
        if not chooses:
            assert isinstance(solution, TargetSolution)
            return solution
        try:
            estimated = self._solve_default(features, config, context, True)
        except CalibrationError:
            if isinstance(solution, DegenerateError):
                raise solution from None
            return solution
        return with_scale_model_spread(
            solution,
            estimated,
            lambda scale: self._solve_default(
                read_as_depth(features, scale), config, context, False
            ),
        )

    def _solve_default(
        self, features: list[Any], config: SphereConfig, context: SolveContext, free: bool
    ) -> TargetSolution:
        """:meth:`solve_default` with the along-line scale estimated (``free``) or held."""
        refine_config = replace(
            config.refine, estimate_radius=config.radius_m is None, estimate_scale=free
        )
        scale = 0.0
        warm = context.warm_start
        learned = None if warm is None else warm.subset_start
        if warm is not None and isinstance(warm.section, SphereSection):
            section = warm.section
            T_start, centre, radius, side = (
                warm.T_flange_sensor,
                section.centre_m,
                section.radius_m,
                section.centre_side,
            )
            warnings: list[str] = []
            scale = section.scale or 0.0
            levels = section.noise_levels or {}
            stated = refine_config
            refine_config = replace(
                refine_config,
                variance_rounds=1,
                sensor_sigma_m=levels.get("sensor_sigma_m", stated.sensor_sigma_m),
                # The robot's prior is only ever tightened (see refine_sphere).
                robot_sigma_t_m=min(
                    levels.get("robot_sigma_t_m", stated.robot_sigma_t_m), stated.robot_sigma_t_m
                ),
                robot_sigma_r_rad=min(
                    levels.get("robot_sigma_r_rad", stated.robot_sigma_r_rad),
                    stated.robot_sigma_r_rad,
                ),
            )
        else:
            fixed, warnings = self._fixed_point(features, config)
            T_start, centre, radius, side = (
                fixed.T_flange_sensor,
                fixed.centre_base,
                fixed.radius_m,
                fixed.side,
            )
        circles = np.stack([f.circle.centre_xz for f in features])
        circle_radii = np.array([f.circle.radius_m for f in features])
        lever = float(
            np.median(
                np.linalg.norm(centres_in_sensor(circles, circle_radii, radius, side), axis=1)
            )
        )

        def solve(kept: list[int], previous: SphereRefinement | None) -> SphereRefinement:
            chosen = [features[k] for k in kept]
            if previous is not None:
                T_start_k, centre_k, radius_k = (
                    previous.state.T_flange_sensor,
                    previous.state.centre_m,
                    previous.state.radius_m,
                )
            else:
                T_start_k, centre_k, radius_k = T_start, centre, radius
            start = SphereState(
                T_start_k,
                centre_k,
                radius_k,
                np.zeros((len(kept), N_LOCAL)),
                scale if previous is None else previous.state.scale,
            )
            return refine_sphere(
                np.stack([f.T_base_flange for f in chosen]),
                [f.points for f in chosen],
                start,
                refine_config,
            )

        def flag(outcome: SphereRefinement, kept: list[int]) -> list[Flag]:
            return sample_flags(
                outcome,
                config.outlier_sigmas,
                config.refine.robot_sigma_t_m,
                config.refine.robot_sigma_r_rad,
            )

        run = solve_with_rejection(
            len(features),
            solve,
            flag,
            config.max_outlier_fraction,
            config.min_samples,
            context.screen_outliers,
        )
        outcome = run.outcome
        kept = [features[k] for k in run.kept]
        state = outcome.state
        sigma = np.sqrt(np.maximum(np.diag(outcome.covariance), 0.0))
        # The robot's error shared by neighbouring views, as the recording shows it: the 1σ
        # of the same estimate under it, where wider (a warm start's sharing as learned).
        # Under the stated prior (each solve tightens its own): the self-check's subsets take
        # the sharing as learned on the whole recording.
        views = outcome.views()
        stated = config.refine
        shared = (
            None
            if views is None
            else shared_pose_error(
                views._replace(
                    robot_sigma=np.repeat([stated.robot_sigma_r_rad, stated.robot_sigma_t_m], 3)
                ),
                learned if isinstance(learned, SharedPoseError) else None,
            )
        )
        own = sigma[:6].copy()
        if shared is not None:
            sigma[:6] = np.maximum(own, np.sqrt(np.diag(shared.covariance)[:6]))
        noise = float(np.median([f.circle.rms_m for f in kept]))
        if self._misfit(outcome.rms_m, noise, outcome.robot_sigma_t_m, config) is None:
            # A model that does not fit is refused by check_fit, not called degenerate. Whether
            # the poses suffice is a question of the noise model, not of the widened 1σ.
            model = (
                outcome.covariance if outcome.model_covariance is None else outcome.model_covariance
            )
            warnings += self._diagnose(model[:6, :6], lever, config)
        for index, reason in run.left_flagged:
            warnings.append(f"profile {features[index].index} looks like an outlier: {reason}")
        scatter = dispersion_warning(outcome.sample_dispersion)
        if scatter is not None:
            warnings.append(scatter)
        if outcome.scale_index is not None and abs(state.scale) > PLAUSIBLE_SCALE_ERROR:
            warnings.append(
                f"the estimated along-line scale is {1.0 + state.scale:.4f} "
                f"({100.0 * state.scale:+.2f} % from nominal): a scale error beyond "
                f"{100.0 * PLAUSIBLE_SCALE_ERROR:.0f} % is implausible, and it likely takes up "
                "something else, such as a ball that is not the given size (measure it, or "
                "omit {setting:radius_m}); {setting:scale} fixed holds it at 1"
            )
        rms = outcome.sample_rms_m()
        section = SphereSection(
            state.centre_m,
            state.radius_m,
            side,
            radius_estimated=config.radius_m is None,
            side_estimated=config.centre_side is None,
            centre_sigma_m=sigma[6:9],
            scale=None if outcome.scale_index is None else state.scale,
            scale_sigma=None if outcome.scale_index is None else float(sigma[outcome.scale_index]),
            noise_levels={
                "sensor_sigma_m": outcome.sensor_sigma_m,
                "robot_sigma_t_m": outcome.robot_sigma_t_m,
                "robot_sigma_r_rad": outcome.robot_sigma_r_rad,
            },
        )
        return TargetSolution(
            T_flange_sensor=state.T_flange_sensor,
            section=section,
            method="default",
            samples_used=[f.index for f in kept],
            rejections=[
                Rejection(features[k].index, features[k].stamp_ns, "outlier", reason)
                for k, reason in run.dropped
            ],
            rms_residual_m=outcome.rms_m,
            sample_residuals_m={f.index: float(v) for f, v in zip(kept, rms, strict=True)},
            sigma_translation_m=sigma[3:6],
            sigma_rotation_rad=sigma[:3],
            warnings=warnings,
            history={"refine_cost": list(outcome.cost_history)},
            sample_fits=[f.record() for f in kept],
            noise_m=noise,
            sigma_widening=None
            if outcome.sample_dispersion is None
            else widening(outcome.sample_dispersion[:6]),
            sigma_shared=None if shared is None else sigma[:6] / own,
            converged=outcome.converged,
            robot_error=RobotError(
                outcome.robot_sigma_t_m,
                outcome.robot_sigma_r_rad,
                outcome.robot_sigma_t_m / config.refine.robot_sigma_t_m,
            )
            if config.refine.estimate_variance_factors
            else None,
            subset_start=shared,
        )

    def _diagnose(self, covariance: FloatArray, lever_m: float, config: SphereConfig) -> list[str]:
        """Warnings for weak directions; DegenerateError for undetermined ones."""
        _, vectors, sigma = scaled_eigen(np.linalg.pinv(covariance), lever_m)
        poor = poor_directions(
            vectors,
            sigma,
            config.observability.weak_sigma_m,
            config.observability.unobservable_sigma_m,
        )
        missing = [d for d in poor if d.status == "unobservable"]
        if missing:
            items = " ".join(
                f"({k + 1}) {describe_direction(d.vector, d.status)}."
                for k, d in enumerate(missing)
            )
            raise DegenerateError(
                f"the flange poses cannot determine the hand-eye from the sphere: {len(missing)} "
                f"direction(s) have a predicted 1 sigma above "
                f"{config.observability.unobservable_sigma_m * 1e3:.0f} mm. {items} Add such "
                "poses and calibrate again."
            )
        return [
            f"weak hand-eye direction (predicted 1 sigma {d.sigma_m * 1e3:.2f} mm): "
            f"{describe_direction(d.vector, d.status)}"
            for d in poor
        ]

    def model_doubt(self, features: list[Any], config: SphereConfig) -> str | None:
        """Why the profiles' own shapes put the sphere in doubt: at least half of them fit a
        rival shape clearly better than a circle (:attr:`SphereFeature.rival`); None
        otherwise. The whole recording decides then (:mod:`..rivals`)."""
        return shape_doubt([(f.index, f.rival) for f in features], "circle")

    def check_features(self, features: list[Any], config: SphereConfig) -> None:
        """Nothing beyond extraction: each profile's shape is checked there, against rival
        shapes and against the recording's other profiles."""

    def _misfit(
        self, rms_m: float, noise_m: float, robot_sigma_t_m: float | None, config: SphereConfig
    ) -> str | None:
        """Why the default method's sphere does not explain the data, or None (``noise_m``:
        the circles' median RMS residual over the profiles, what a sphere could leave)."""
        if rms_m > config.max_residual_ratio * noise_m:
            return mismatch_message(
                "sphere",
                rms_m,
                noise_m,
                "the noise figure is the median RMS the profiles' circles leave",
            )
        stated = config.refine.robot_sigma_t_m
        if robot_sigma_t_m is not None and robot_sigma_t_m > config.max_robot_ratio * stated:
            return (
                f"the sphere model fits the profiles only with flange-pose corrections of "
                f"{robot_sigma_t_m * 1e3:.3f} mm (1 sigma), {robot_sigma_t_m / stated:.0f} times "
                f"the robot's stated {stated * 1e3:.3f} mm. Likely causes: the sphere centre is "
                "on the other side of the laser plane ({setting:centre_side}); the profile and "
                "pose "
                "clocks are not synchronised ({setting:clock_offset_s}); the robot moved during "
                "the scans; "
                "the scans show another target; or the robot is less accurate than stated "
                "({setting:robot_sigma_t_m}). No result was written."
            )
        return None

    def check_fit(self, solution: TargetSolution, config: SphereConfig) -> None:
        """Refuse a sphere that does not explain the data (see the module docstring)."""
        if solution.method == "paper":
            if solution.rms_residual_m > config.max_scatter_ratio * solution.noise_m:
                raise ModelMismatch(
                    mismatch_message(
                        "sphere",
                        solution.rms_residual_m,
                        solution.noise_m,
                        "the sphere centres of the profiles scatter that much about their "
                        "common centre (the robot's stated sigma explains the noise figure)",
                    )
                )
            return
        section = solution.section
        levels = section.noise_levels if isinstance(section, SphereSection) else None
        problem = self._misfit(
            solution.rms_residual_m,
            solution.noise_m,
            levels["robot_sigma_t_m"] if levels else None,
            config,
        )
        if problem is not None:
            raise ModelMismatch(problem)

    def offset_cost(
        self, features: list[Any], config: SphereConfig, context: SolveContext
    ) -> Callable[[FloatArray], float] | None:
        """Not supported: the sphere is scanned step-and-shoot."""
        return None

    def read_section(self, mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> SphereSection:
        """The section from a result file (ValueError naming a bad key)."""
        return read_sphere_section(mapping, quality)
