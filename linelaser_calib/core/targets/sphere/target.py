"""The sphere target: a tooling ball seen from many flange poses.

Per profile (:func:`extract_feature`): cleaning, then a RANSAC circle (centre, radius r) in
the laser plane; a profile whose circle leaves much more than its own noise is no circular
arc and is rejected. The sphere centre lies √(R² − r²) off the plane on one side.

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
(the profiles' own noise for ``default``; what the robot's σ explains for ``paper``) or
whose pose corrections lie far above the robot's σ.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from linelaser_calib.core.errors import (
    DegenerateError,
    InputError,
    ModelMismatch,
    ProfileRejected,
)
from linelaser_calib.core.geometry import FloatArray, apply_transform
from linelaser_calib.core.observability import poor_directions, scaled_eigen
from linelaser_calib.core.profile.cleaning import MAD_TO_SIGMA, clean_profile
from linelaser_calib.core.solver import Flag, solve_with_rejection
from linelaser_calib.core.targets.base import (
    Option,
    Progress,
    Shape,
    SolveContext,
    TargetSolution,
    extract_each,
    mismatch_message,
    plain_floats,
    read_vector,
    rejection_digest,
)
from linelaser_calib.core.targets.sphere.circle import NOT_A_CIRCLE, CircleFit, fit_circle_ransac
from linelaser_calib.core.targets.sphere.config import SphereConfig
from linelaser_calib.core.targets.sphere.model import (
    SIDE_LABELS,
    FixedPointSolution,
    estimate_radius,
    fixed_point_information,
    fixed_point_residuals,
    resolve_side,
    side_from_label,
    side_is_clear,
    solve_fixed_point,
)
from linelaser_calib.core.targets.sphere.plan import SpherePlanner
from linelaser_calib.core.targets.sphere.refine import (
    N_LOCAL,
    SphereRefinement,
    SphereState,
    refine_sphere,
)
from linelaser_calib.core.types import Rejection, Sample, SampleFit

#: Circle radii may exceed a given sphere radius by this share plus
#: :data:`RADIUS_MARGIN_M` (noise at the equator).
RADIUS_MARGIN = 0.02
RADIUS_MARGIN_M = 5e-4


@dataclass(frozen=True)
class SphereFeature:
    """One profile's circle.

    Attributes
    ----------
    index : int
    stamp_ns : int
    T_base_flange : ndarray, shape (4, 4)
    circle : CircleFit
    points : ndarray, shape (N, 3)
        The circle's inlier points, sensor frame, m, in scan order.
    """

    index: int
    stamp_ns: int
    T_base_flange: FloatArray
    circle: CircleFit
    points: FloatArray

    def record(self) -> SampleFit:
        """The plain record kept in the result."""
        return SampleFit(
            self.index, self.stamp_ns, self.T_base_flange, self.points, self.circle.centre_xz
        )


def extract_feature(
    sample: Sample, config: SphereConfig, rng: np.random.Generator
) -> SphereFeature | Rejection:
    """Clean one profile and fit its circle; a rejection says why it failed."""
    try:
        cleaned = clean_profile(sample.points, config.cleaning)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "cleaning", str(exc))
    largest = None
    if config.radius_m is not None:
        largest = config.radius_m * (1.0 + RADIUS_MARGIN) + RADIUS_MARGIN_M
    try:
        circle = fit_circle_ransac(cleaned.points_xz, config.circle, rng, largest)
    except ProfileRejected as exc:
        return Rejection(sample.index, sample.stamp_ns, "circle", str(exc))
    points = cleaned.points[circle.inliers]
    return SphereFeature(sample.index, sample.stamp_ns, sample.T_base_flange, circle, points)


@dataclass(frozen=True)
class SphereSection:
    """The sphere of a result, base frame.

    Attributes
    ----------
    centre_m : ndarray, shape (3,)
    radius_m : float
    centre_side : int
        +1 or −1: the sensor y side of the laser plane the centre lies on.
    radius_estimated, side_estimated : bool
        Estimated from the data (True) or given.
    centre_sigma_m : ndarray, shape (3,), or None
        1σ of the centre per base axis, m (default method).
    noise_levels : dict of str to float
        The noise levels re-estimated from the residuals (``sensor_sigma_m``,
        ``robot_sigma_t_m``, ``robot_sigma_r_rad``; default method), or empty.
    """

    key: ClassVar[str] = "sphere"
    title: ClassVar[str] = "sphere"

    centre_m: FloatArray
    radius_m: float
    centre_side: int
    radius_estimated: bool
    side_estimated: bool
    centre_sigma_m: FloatArray | None = None
    noise_levels: Mapping[str, float] | None = None

    def to_mapping(self, base_frame: str) -> dict[str, Any]:
        """``{frame, centre, radius, centre_side, uncertainty_m}`` in m."""
        return {
            "frame": base_frame,
            "centre": plain_floats(self.centre_m),
            "radius": float(self.radius_m),
            "centre_side": SIDE_LABELS[self.centre_side],
            "uncertainty_m": None
            if self.centre_sigma_m is None
            else plain_floats(self.centre_sigma_m),
        }

    def quality_entries(self) -> dict[str, Any]:
        """Whether the radius and side were estimated, and the re-estimated noise levels."""
        entries: dict[str, Any] = {
            "radius_estimated": self.radius_estimated,
            "centre_side_estimated": self.side_estimated,
        }
        if self.noise_levels:
            entries["noise_estimated"] = {k: float(v) for k, v in self.noise_levels.items()}
        return entries

    def describe(self, base_frame: str) -> str:
        """One line: centre and radius in mm, side."""
        x, y, z = (v * 1e3 for v in self.centre_m)
        return (
            f"sphere centre ({x:.3f}, {y:.3f}, {z:.3f}) mm in {base_frame}, radius "
            f"{self.radius_m * 1e3:.3f} mm ({'estimated' if self.radius_estimated else 'given'})"
            f", centre on the sensor's {SIDE_LABELS[self.centre_side]} side "
            f"({'from the data' if self.side_estimated else 'given'})"
        )

    def residual_kind(self, method: str) -> str:
        """Point-to-sphere distance (default) or sphere-centre distance (paper)."""
        if method == "paper":
            return "distance of the profile's sphere centre from the common centre"
        return "point-to-sphere distance"

    def shapes(self, points_base: FloatArray) -> list[Shape]:
        """The sphere."""
        return [Shape("sphere", self.centre_m[None], self.radius_m, "sphere")]

    def surface_distances(self, fit: SampleFit, T_base_sensor: FloatArray) -> FloatArray:
        """Distance of the sample's points from the centre minus the radius (N,), m."""
        points = apply_transform(T_base_sensor, fit.points)
        return np.asarray(np.linalg.norm(points - self.centre_m, axis=1) - self.radius_m)

    def given_settings(self) -> dict[str, Any]:
        """None: a sphere result fixes nothing of a later calibration."""
        return {}

    def sensor_points(self, points: FloatArray) -> FloatArray:
        """The points unchanged: this target estimates nothing of the sensor itself."""
        return points


def read_sphere_section(mapping: Mapping[str, Any], quality: Mapping[str, Any]) -> SphereSection:
    """The section from a result file's ``sphere`` mapping (ValueError naming a bad key)."""
    centre = read_vector(mapping, "centre")
    try:
        radius = float(mapping["radius"])
        side = side_from_label(str(mapping["centre_side"]))
    except (KeyError, TypeError, ValueError, InputError) as exc:
        raise ValueError(f"sphere needs a radius (m) and centre_side +y or -y: {exc}") from None
    if not radius > 0.0:
        raise ValueError(f"key radius must be > 0 m, got {radius}")
    sigma = mapping.get("uncertainty_m")
    return SphereSection(
        centre_m=centre,
        radius_m=radius,
        centre_side=side,
        radius_estimated=bool(quality.get("radius_estimated", False)),
        side_estimated=bool(quality.get("centre_side_estimated", False)),
        centre_sigma_m=None if sigma is None else np.asarray(sigma, dtype=np.float64),
        noise_levels=dict(quality.get("noise_estimated") or {}),
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
    }
    #: Pose planning (:mod:`linelaser_calib.core.planning`).
    planner = SpherePlanner()

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
        """The circles of all samples and the rejections."""
        return extract_each(samples, config, seed, extract_feature, progress, "circle", workers)

    def _require(
        self, features: list[SphereFeature], config: SphereConfig, context: SolveContext
    ) -> None:
        """Refuse too few circles; when most profiles are no circles, say it is another target."""
        if len(features) >= config.min_samples:
            return
        shape = [r for r in context.rejections if r.reason.startswith(NOT_A_CIRCLE)]
        if len(shape) >= max(1, len(features)):
            raise ModelMismatch(
                f"the sphere model does not fit these data: {len(shape)} of "
                f"{max(context.n_samples, len(shape) + len(features))} profiles are no circular "
                f"arc ({shape[0].reason}). Likely causes: the scans show another target (a "
                "cylinder's elliptical arcs: {setting:target} cylinder; a seam's V: "
                "{setting:target} "
                "known_point or line); or the profiles are not in metres. No result was written."
            )
        raise DegenerateError(
            f"only {len(features)} profiles show a usable circle; the sphere target needs "
            f"{config.min_samples}. {rejection_digest(context.rejections)}Scan the ball from "
            "more poses with the line across it."
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
        """Maximum likelihood on every point, outlier samples dropped, 1σ and diagnosis."""
        self._require(features, config, context)
        fixed, warnings = self._fixed_point(features, config)
        refine_config = replace(config.refine, estimate_radius=config.radius_m is None)

        def solve(kept: list[int], previous: SphereRefinement | None) -> SphereRefinement:
            chosen = [features[k] for k in kept]
            if previous is None:
                start = SphereState(
                    fixed.T_flange_sensor,
                    fixed.centre_base,
                    fixed.radius_m,
                    np.zeros((len(kept), N_LOCAL)),
                )
            else:
                start = SphereState(
                    previous.state.T_flange_sensor,
                    previous.state.centre_m,
                    previous.state.radius_m,
                    np.zeros((len(kept), N_LOCAL)),
                )
            return refine_sphere(
                np.stack([f.T_base_flange for f in chosen]),
                [f.points for f in chosen],
                start,
                refine_config,
            )

        def flag(outcome: SphereRefinement, kept: list[int]) -> list[Flag]:
            rms = outcome.sample_rms_m()
            median = float(np.median(rms))
            spread = MAD_TO_SIGMA * float(np.median(np.abs(rms - median)))
            limit = max(median + config.outlier_sigmas * spread, 3.0 * outcome.sensor_sigma_m)
            return [
                Flag(
                    float(value / limit),
                    k,
                    f"RMS point-to-sphere distance {value * 1e6:.1f} um, above the "
                    f"{limit * 1e6:.1f} um the other profiles allow",
                )
                for k, value in enumerate(rms)
                if value > limit
            ]

        run = solve_with_rejection(
            len(features), solve, flag, config.max_outlier_fraction, config.min_samples
        )
        outcome = run.outcome
        kept = [features[k] for k in run.kept]
        state = outcome.state
        sigma = np.sqrt(np.maximum(np.diag(outcome.covariance), 0.0))
        lever = float(np.median(np.linalg.norm(fixed.centres_sensor, axis=1)))
        noise = float(np.median([f.circle.noise_m for f in kept]))
        if self._misfit(outcome.rms_m, noise, outcome.robot_sigma_t_m, config) is None:
            # A model that does not fit is refused by check_fit, not called degenerate.
            warnings += self._diagnose(outcome.covariance[:6, :6], lever, config)
        for index, reason in run.left_flagged:
            warnings.append(f"profile {features[index].index} looks like an outlier: {reason}")
        rms = outcome.sample_rms_m()
        section = SphereSection(
            state.centre_m,
            state.radius_m,
            fixed.side,
            radius_estimated=config.radius_m is None,
            side_estimated=config.centre_side is None,
            centre_sigma_m=sigma[6:9],
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

    def check_features(self, features: list[Any], config: SphereConfig) -> None:
        """Nothing beyond extraction: each profile's shape is checked there (its circle's
        residual against the profile's own noise), and the solve refuses data in which most
        profiles are no circles (it knows the rejections)."""

    def _misfit(
        self, rms_m: float, noise_m: float, robot_sigma_t_m: float | None, config: SphereConfig
    ) -> str | None:
        """Why the default method's sphere does not explain the data, or None."""
        if rms_m > config.circle.max_noise_ratio * noise_m:
            return mismatch_message("sphere", rms_m, noise_m)
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
