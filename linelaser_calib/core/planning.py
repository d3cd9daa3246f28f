"""Pose planning: the next flange poses that most reduce the hand-eye's predicted uncertainty.

Model
-----
A target that can be planned for implements :class:`Plannable` next to its folder (e.g.
``core/targets/cylinder/plan.py``). From its rough placement (a result, a given axis, or a
few exploratory scans) it predicts the noise-free profile at any sensor pose by intersecting
the laser fan's rays with its surface (:meth:`Plannable.ray_depths`), proposes sensor poses
that obey its own scanning rules (:meth:`Plannable.candidate_views`), and gives the
information (G×G, hand-eye first) that one profile at a pose adds to its default maximum
likelihood problem at the current estimate (:meth:`Plannable.information`). The target
computes that information through its own problem builder and the shared solver's
:func:`~linelaser_calib.core.solver.normal_equations` on one sample at a time, so that the
planner predicts exactly the information the calibration will see; each sample's pose
correction is marginalised in its own Schur complement, so the per-pose contributions add.

Criterion
---------
The planner adds poses greedily. At each step it takes the candidate that maximises
log det of the marginal information of the hand-eye (the 6×6 Schur complement after the
target's own parameters are eliminated), starting from the information of the samples
already taken: a D-optimal design. An exchange pass (Fedorov's) then swaps any chosen pose
for a candidate that raises the log det further, until no swap does, and the poses are put
back in greedy order, so that every prefix of the plan is a good plan too.

D-optimality is preferred to A-optimality (the trace of the covariance) because the hand-eye
mixes rotations (rad) and translations (m): the trace adds rad² to m², so its choice depends
on the units and on an arbitrary lever, whereas log det only shifts by a constant when the
units change, so the chosen poses do not.
D-optimality also minimises the volume of the hand-eye's confidence ellipsoid, and a greedy
choice of a log det is close to the best subset (the criterion is submodular on added
information). On the cylinder at the paper's noise, the D-optimal 20 poses come within 1 % of
the 20 that minimise the translation's variance (trace, m²), at a smaller rotation 1σ.

Candidates
----------
The target draws candidate sensor poses by its scanning rules; the planner keeps drawing
until it holds ``CANDIDATES_PER_POSE`` feasible ones per pose to plan (at least
``MIN_CANDIDATES``; drawing stops after ``MAX_DRAWS_PER_CANDIDATE`` draws per candidate
wanted). Most draws fail a constraint (an upright shaft on a table rejects every view from
below), and a greedy choice from too few feasible candidates is little better than a random
one: at 36 candidates the 20 poses' 1σ is 5 % (translation) and 12 % (rotation) above that
from 300.

Noise levels
------------
The per-pose information uses the target's configured noise levels, or, when the plan
starts from a result whose section carries re-estimated ones (``noise_levels``: sensor σ,
robot σ_t and σ_r), those: they are what the next calibration will meet.

Constraints
-----------
Every proposed pose passes :func:`feasible`: the outermost rays of the fan miss the target
(the whole arc is in view), every hit lies within the measuring range, enough rays hit, the
flange stays within a reach box around the first pose, the sensor and flange stay above the
table and away from the target, the laser does not point upwards, and the sensor does not
look towards the robot's base.

Stop rule
---------
Planning stops early once every predicted 1σ of the hand-eye is within the user's goal
(translation, m, and rotation, rad).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from .errors import DegenerateError, InputError
from .geometry import FloatArray, invert_transform
from .settings_text import setting
from .solver import N_HAND_EYE, Linearisation, Residuals, SolverConfig, normal_equations
from .targets.base import Shape, Target
from .types import BoolArray, Sample

#: Prior information added to every global parameter before planning from no samples
#: (1 per rad² and per m²): negligible next to one profile's (~1e8), it only keeps the
#: information invertible.
WEAK_PRIOR_INFORMATION = 1.0
#: The base frame's upward direction (REP 103: z up); the table is a plane of constant z.
UP = np.array([0.0, 0.0, 1.0])
#: Solver settings of :func:`per_sample_information` (unit weights are given explicitly).
UNIT_WEIGHTS = SolverConfig(loss="linear")
#: Feasible candidates gathered per pose to plan.
CANDIDATES_PER_POSE = 30
#: Fewest feasible candidates gathered.
MIN_CANDIDATES = 200
#: Most candidates drawn per feasible candidate wanted.
MAX_DRAWS_PER_CANDIDATE = 40
#: Most sweeps of the exchange pass over the chosen poses.
MAX_EXCHANGE_SWEEPS = 5
#: Noise levels a result's section may carry, re-estimated (m, m, rad).
NOISE_LEVELS = ("sensor_sigma_m", "robot_sigma_t_m", "robot_sigma_r_rad")
#: Smallest rise of the log det for which the exchange pass swaps a pose.
EXCHANGE_GAIN = 1e-6


@dataclass(frozen=True)
class PlanConstraints:
    """Where the planner may put the sensor (base frame, SI units).

    Defaults are scanCONTROL-like and match the simulator's ``ur_scancontrol`` preset.

    Attributes
    ----------
    z_min_m, z_max_m : float
        Measuring range along the sensor's z axis, m. Default 0.07-0.15 m.
    fan_half_angle_rad : float
        Half opening of the laser fan, rad. Default 25°.
    resolution : int
        Rays of the fan. Default 640.
    min_hit_fraction : float
        Fewest rays that must hit the target, as a share of ``resolution``. Default 0.15.
    reach_centre_m : (3,) floats or None
        Centre of the reach box of the flange, m; None: the first sample's flange position
        (or the target's centre when there is no sample).
    reach_half_extent_m : float
        Half side of the reach box, m. Default 0.25.
    table_height_m : float or None
        Height (base z) of the table; the sensor and flange origins must stay
        ``clearance_m`` above it. Default 0 (the robot stands on the table); None: no table.
    max_view_up : float
        Largest upward component of the sensor's viewing direction (its z axis): 0 (default)
        forbids a laser pointing upwards.
    robot_cone_rad : float
        The horizontal viewing direction must stay more than this angle away from the
        direction to the robot's base (the base origin). Default 30°.
    clearance_m : float
        Distance the sensor and flange origins keep from the target, m. Default 0.03.
    """

    z_min_m: float = 0.07
    z_max_m: float = 0.15
    fan_half_angle_rad: float = math.radians(25.0)
    resolution: int = 640
    min_hit_fraction: float = 0.15
    reach_centre_m: tuple[float, float, float] | None = None
    reach_half_extent_m: float = 0.25
    table_height_m: float | None = 0.0
    max_view_up: float = 0.0
    robot_cone_rad: float = math.radians(30.0)
    clearance_m: float = 0.03

    def __post_init__(self) -> None:
        if not 0.0 < self.z_min_m < self.z_max_m:
            raise InputError(
                f"the measuring range must satisfy 0 < z_min < z_max, got {self.z_min_m} and "
                f"{self.z_max_m} m"
            )
        if not 0.0 < self.fan_half_angle_rad < math.pi / 2:
            raise InputError(
                f"the fan half angle must lie in (0, 90) deg, got "
                f"{math.degrees(self.fan_half_angle_rad):.1f} deg"
            )
        if self.resolution < 16:
            raise InputError(f"the fan needs at least 16 rays, got {self.resolution}")
        if not (self.reach_half_extent_m > 0.0 and self.clearance_m >= 0.0):
            raise InputError("the reach box must be positive and the clearance non-negative")

    def ray_directions(self) -> FloatArray:
        """Unit ray directions of the fan in the sensor frame (resolution, 3), y = 0; evenly
        spaced in x at any depth."""
        tau = np.linspace(-1.0, 1.0, self.resolution) * math.tan(self.fan_half_angle_rad)
        d = np.stack([tau, np.zeros_like(tau), np.ones_like(tau)], axis=1)
        return np.asarray(d / np.linalg.norm(d, axis=1, keepdims=True))


class Plannable(Protocol):
    """What a target provides to be planned for (see the module docstring).

    ``placement`` is the target's own object: its rough pose and finite extent in the base
    frame (for the cylinder: axis, radius and the axial span of the shaft). ``extent`` is a
    target-specific span (the cylinder's axial span (lo, hi), m) or None: taken from the
    points of the samples then. A target offers a planner through its ``planner`` attribute.
    """

    numbers_setting: str
    numbers_help: str

    def placement_from_section(
        self, section: Any, config: Any, extent: Any, points_base: FloatArray | None
    ) -> Any:
        """The placement from a result's section (a calibration of the same set-up)."""
        ...

    def placement_from_numbers(
        self, numbers: list[float], config: Any, extent: Any, points_base: FloatArray | None
    ) -> Any:
        """The placement from numbers the user typed (the user setting
        ``numbers_setting``, SI units)."""
        ...

    def placement_from_features(
        self, features: list[Any], T_flange_sensor: FloatArray, config: Any, extent: Any
    ) -> Any:
        """The rough placement from a few exploratory scans and an initial hand-eye."""
        ...

    def sample_points(self, features: list[Any]) -> list[FloatArray]:
        """The points (N_j, 3) of each feature the default problem uses, sensor frame, m."""
        ...

    def ray_depths(
        self, placement: Any, T_base_sensor: FloatArray, directions: FloatArray
    ) -> FloatArray:
        """Distance (K, N) along each ray (N, 3; sensor frame) to the target's surface from
        each sensor pose (K, 4, 4), m; NaN where the ray misses."""
        ...

    def candidate_views(
        self, placement: Any, constraints: PlanConstraints, rng: np.random.Generator, n: int
    ) -> FloatArray:
        """``n`` sensor poses T_base_sensor (n, 4, 4) drawn by the target's scanning rules
        (not yet checked by :func:`feasible`)."""
        ...

    def clearance(self, placement: Any, points: FloatArray) -> FloatArray:
        """Distance (K,) of points (K, 3) from the target's solid, m."""
        ...

    def centre(self, placement: Any) -> FloatArray:
        """The middle of the target (3,), m."""
        ...

    def information(
        self,
        placement: Any,
        T_flange_sensor: FloatArray,
        points_sensor: list[FloatArray],
        T_base_flange: FloatArray,
        config: Any,
    ) -> FloatArray:
        """Information (M, G, G) that each sample (profile points (N_j, 3) in the sensor
        frame at flange pose (4, 4)) adds to the default problem at the estimate
        (hand-eye first, θ in rad about the sensor axes then ρ in m; pose correction
        marginalised)."""
        ...


#: One point of a 1σ curve: (poses taken, 1σ translation (3,) m, 1σ rotation (3,) rad).
SigmaPoint = tuple[int, FloatArray, FloatArray]


@dataclass(frozen=True)
class PlannedPose:
    """One planned pose and the predicted 1σ of the hand-eye once it is taken.

    Attributes
    ----------
    T_base_flange : ndarray, shape (4, 4)
    T_base_sensor : ndarray, shape (4, 4)
    sigma_translation_m : ndarray, shape (3,)
        Flange axes, m.
    sigma_rotation_rad : ndarray, shape (3,)
        Small angles about the sensor axes, rad.
    """

    T_base_flange: FloatArray
    T_base_sensor: FloatArray
    sigma_translation_m: FloatArray
    sigma_rotation_rad: FloatArray


@dataclass(frozen=True)
class Plan:
    """Outcome of :func:`plan_poses`.

    Attributes
    ----------
    poses : list of PlannedPose
        In the order chosen.
    sigma_translation_m, sigma_rotation_rad : ndarray, shape (3,), or None
        Predicted 1σ from the samples already taken (None when there are too few).
    goal_reached : bool
        The last pose's predicted 1σ is within the goal.
    candidates : int
        Feasible candidates the poses were chosen from.
    taken : int
        Samples already taken that the plan starts from.
    """

    poses: list[PlannedPose]
    sigma_translation_m: FloatArray | None
    sigma_rotation_rad: FloatArray | None
    goal_reached: bool
    candidates: int
    taken: int


def predicted_curve(plan: Plan) -> list[SigmaPoint]:
    """(poses, 1σ translation (3,) m, 1σ rotation (3,) rad) after each planned pose, counting
    the samples taken before them; poses whose hand-eye is not yet determined (fewer than 3
    in all) are left out. The first point is the samples' own, when they determine it."""
    start: list[SigmaPoint] = []
    if plan.sigma_translation_m is not None and plan.sigma_rotation_rad is not None:
        start = [(plan.taken, plan.sigma_translation_m, plan.sigma_rotation_rad)]
    return start + [
        (plan.taken + k + 1, pose.sigma_translation_m, pose.sigma_rotation_rad)
        for k, pose in enumerate(plan.poses)
        if plan.taken + k + 1 >= 3
    ]


def required_radius(radius_m: float | None, title: str) -> float:
    """The target's radius, m, which a placement from numbers or scans needs.

    Raises
    ------
    InputError
        None given.
    """
    if radius_m is None:
        raise InputError(
            f"the planner needs the {title}'s radius: give "
            "{setting:radius_m} (m) or a result YAML ({setting:from_result})"
        )
    return radius_m


def per_sample_information(linearisation: Linearisation) -> FloatArray:
    """Information (M, G, G) each sample adds to the global parameters, its own pose
    correction marginalised (the solver's Schur complement on one sample at a time, with
    unit weights: the Gaussian information at the linearisation point)."""
    n_samples, _, n_global = linearisation.J_global.shape
    out = np.empty((n_samples, n_global, n_global))
    residuals = linearisation.residuals
    for j in range(n_samples):
        one = slice(j, j + 1)
        sample = replace(
            linearisation,
            residuals=Residuals(residuals.points[one], residuals.pose_prior[one]),
            J_global=linearisation.J_global[one],
            J_local=linearisation.J_local[one],
        )
        weights = np.ones_like(sample.residuals.points)
        out[j] = normal_equations(sample, UNIT_WEIGHTS, weights).schur_information()
    return out


def marginal_hand_eye(information: FloatArray) -> FloatArray:
    """Information (..., 6, 6) of the hand-eye with the target's parameters eliminated.

    Parameters
    ----------
    information : ndarray, shape (..., G, G)
        Hand-eye first.
    """
    h, o = slice(0, N_HAND_EYE), slice(N_HAND_EYE, None)
    I_ho = information[..., h, o]
    solved = np.linalg.solve(information[..., o, o], np.swapaxes(I_ho, -1, -2))
    return np.asarray(information[..., h, h] - I_ho @ solved)


def predicted_sigma(information: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Predicted 1σ of the hand-eye: translation (3,) in m, rotation (3,) in rad."""
    covariance = np.linalg.inv(marginal_hand_eye(information))
    sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return sigma[3:], sigma[:3]


def feasible(
    plannable: Plannable,
    placement: Any,
    T_base_sensor: FloatArray,
    T_flange_sensor: FloatArray,
    constraints: PlanConstraints,
    reach_centre_m: FloatArray,
) -> BoolArray:
    """Which sensor poses (K, 4, 4) obey every constraint (see the module docstring).

    The cheap checks run first; the fan is cast only from the poses that pass them.
    """
    sensor = T_base_sensor[:, :3, 3]
    flange = (T_base_sensor @ invert_transform(T_flange_sensor))[:, :3, 3]
    ok = np.all(np.abs(flange - reach_centre_m) <= constraints.reach_half_extent_m, axis=1)
    up = UP
    if constraints.table_height_m is not None:
        floor = constraints.table_height_m + constraints.clearance_m
        ok &= (sensor @ up >= floor) & (flange @ up >= floor)
    view = T_base_sensor[:, :3, 2]
    ok &= view @ up <= constraints.max_view_up
    ok &= robot_angle(T_base_sensor, up) > constraints.robot_cone_rad
    ok &= plannable.clearance(placement, sensor) >= constraints.clearance_m
    ok &= plannable.clearance(placement, flange) >= constraints.clearance_m
    directions = constraints.ray_directions()
    depth = plannable.ray_depths(placement, T_base_sensor[ok], directions)
    hit = np.isfinite(depth)
    z = np.where(hit, depth, 0.0) * directions[:, 2]
    in_range = (z >= constraints.z_min_m) & (z <= constraints.z_max_m)
    whole_arc = ~hit[:, 0] & ~hit[:, -1] & np.all(~hit | in_range, axis=1)
    ok[ok] = whole_arc & (hit.sum(axis=1) >= constraints.min_hit_fraction * constraints.resolution)
    return np.asarray(ok)


def robot_angle(T_base_sensor: FloatArray, up: FloatArray) -> FloatArray:
    """Angle (K,) between each sensor's horizontal viewing direction and the horizontal
    direction from the sensor to the base origin, rad (0: looking straight at the robot)."""
    view = T_base_sensor[:, :3, 2]
    to_base = -T_base_sensor[:, :3, 3]
    view_h = view - np.outer(view @ up, up)
    base_h = to_base - np.outer(to_base @ up, up)
    norms = np.linalg.norm(view_h, axis=1) * np.linalg.norm(base_h, axis=1)
    cosine = np.sum(view_h * base_h, axis=1) / np.maximum(norms, 1e-12)
    return np.asarray(np.where(norms > 1e-12, np.arccos(np.clip(cosine, -1.0, 1.0)), math.pi))


def predicted_profiles(
    plannable: Plannable,
    placement: Any,
    T_base_sensor: FloatArray,
    constraints: PlanConstraints,
) -> list[FloatArray]:
    """The noise-free profile (hits only, (N_k, 3) sensor frame, m) at each sensor pose."""
    directions = constraints.ray_directions()
    depth = plannable.ray_depths(placement, T_base_sensor, directions)
    return [d[np.isfinite(d), None] * directions[np.isfinite(d)] for d in depth]


def gather_candidates(
    plannable: Plannable,
    placement: Any,
    T_flange_sensor: FloatArray,
    constraints: PlanConstraints,
    reach_centre_m: FloatArray,
    rng: np.random.Generator,
    wanted: int,
) -> tuple[FloatArray, int]:
    """Up to ``wanted`` feasible sensor poses (K, 4, 4), drawn in batches sized by the share
    of feasible draws so far, and the number of poses drawn."""
    kept: list[FloatArray] = []
    found = drawn = 0
    budget = MAX_DRAWS_PER_CANDIDATE * wanted
    batch = 4 * wanted
    while found < wanted and drawn < budget:
        size = min(batch, budget - drawn)
        views = plannable.candidate_views(placement, constraints, rng, size)
        drawn += size
        ok = feasible(plannable, placement, views, T_flange_sensor, constraints, reach_centre_m)
        kept.append(views[ok])
        found += int(ok.sum())
        batch = math.ceil(1.2 * (wanted - found) * drawn / max(found, 1)) + 1
    return np.concatenate(kept)[:wanted], drawn


def log_det_marginal(information: FloatArray) -> FloatArray:
    """log det (...,) of the hand-eye's marginal information of each (..., G, G)."""
    _, logdet = np.linalg.slogdet(marginal_hand_eye(information))
    return np.asarray(logdet)


def within(sigma: tuple[FloatArray, FloatArray], goal: tuple[float, float] | None) -> bool:
    """Every 1σ (translation (3,) m, rotation (3,) rad) is within the goal (m, rad)."""
    return goal is not None and bool(np.all(sigma[0] <= goal[0]) and np.all(sigma[1] <= goal[1]))


def greedy_order(
    information: FloatArray,
    gains: FloatArray,
    n: int,
    goal: tuple[float, float] | None,
    available: BoolArray,
) -> list[int]:
    """Up to ``n`` of the available candidates, each the one that raises the log det most
    given ``information`` (G, G) and those before it; stops once the goal is reached."""
    open_ = available.copy()
    chosen: list[int] = []
    while len(chosen) < n and open_.any():
        best = int(np.argmax(np.where(open_, log_det_marginal(information + gains), -np.inf)))
        open_[best] = False
        information = information + gains[best]
        chosen.append(best)
        if within(predicted_sigma(information), goal):
            break
    return chosen


def exchange(information: FloatArray, gains: FloatArray, chosen: list[int]) -> list[int]:
    """Fedorov's exchange: swap each chosen candidate for the one that, with the others,
    gives the largest log det, while that rises by more than ``EXCHANGE_GAIN``."""
    chosen = list(chosen)
    for _ in range(MAX_EXCHANGE_SWEEPS):
        swapped = False
        for k in range(len(chosen)):
            others = chosen[:k] + chosen[k + 1 :]
            logdet = log_det_marginal(information + gains[others].sum(axis=0) + gains)
            logdet[others] = -np.inf
            best = int(np.argmax(logdet))
            if logdet[best] > logdet[chosen[k]] + EXCHANGE_GAIN:
                chosen[k], swapped = best, True
        if not swapped:
            break
    return chosen


def choose(
    information: FloatArray, gains: FloatArray, n: int, goal: tuple[float, float] | None
) -> list[int]:
    """Greedy choice, exchange pass, then the exchanged set in greedy order (module
    docstring); the greedy choice stays when the exchanged set misses a goal it reached."""
    greedy = greedy_order(information, gains, n, goal, np.ones(len(gains), dtype=bool))
    swapped = exchange(information, gains, greedy)
    if set(swapped) == set(greedy):
        return greedy
    mask = np.zeros(len(gains), dtype=bool)
    mask[swapped] = True
    ordered = greedy_order(information, gains, len(swapped), goal, mask)
    final = information + gains[ordered].sum(axis=0)
    if within(predicted_sigma(information + gains[greedy].sum(axis=0)), goal) and not within(
        predicted_sigma(final), goal
    ):
        return greedy
    return ordered


def plan_poses(
    plannable: Plannable,
    placement: Any,
    T_flange_sensor: FloatArray,
    config: Any,
    n: int,
    rng: np.random.Generator,
    constraints: PlanConstraints | None = None,
    current: tuple[list[FloatArray], FloatArray] | None = None,
    goal: tuple[float, float] | None = None,
    candidates: int | None = None,
) -> Plan:
    """D-optimal choice of up to ``n`` flange poses (see the module docstring).

    Parameters
    ----------
    plannable : Plannable
    placement : target placement
        The target's rough pose and extent.
    T_flange_sensor : ndarray, shape (4, 4)
        Current estimate of the hand-eye.
    config : target config
        The target's settings (noise levels, radius known or not).
    n : int
        Poses to plan (fewer when the goal is reached first).
    rng : numpy.random.Generator
        Draws the candidates.
    constraints : PlanConstraints, optional
    current : (list of ndarray (N_j, 3), ndarray (M, 4, 4)), optional
        Profile points (sensor frame, m) and flange poses of the samples already taken.
    goal : (float, float), optional
        Stop once every predicted 1σ is within (translation m, rotation rad).
    candidates : int, optional
        Feasible candidates to choose from; default ``CANDIDATES_PER_POSE`` per pose, at
        least ``MIN_CANDIDATES``.

    Raises
    ------
    InputError
        ``n`` below 1.
    DegenerateError
        No candidate pose satisfies the constraints (the message names the likely cause).
    """
    if n < 1:
        raise InputError(f"the number of poses to plan must be >= 1, got {n}")
    limits = PlanConstraints() if constraints is None else constraints
    points, T_current = ([], np.zeros((0, 4, 4))) if current is None else current
    if limits.reach_centre_m is not None:
        reach = np.asarray(limits.reach_centre_m, dtype=np.float64)
    elif len(T_current):
        reach = T_current[0, :3, 3]
    else:
        reach = plannable.centre(placement)
    wanted = max(MIN_CANDIDATES, CANDIDATES_PER_POSE * n) if candidates is None else candidates
    T_sensor, drawn = gather_candidates(
        plannable, placement, T_flange_sensor, limits, reach, rng, wanted
    )
    if not len(T_sensor):
        raise DegenerateError(
            f"none of {drawn} candidate sensor poses satisfies the constraints: the "
            "flange must stay within the reach box (half side "
            f"{limits.reach_half_extent_m * 1e3:.0f} mm around "
            f"{np.array2string(reach * 1e3, precision=0)} mm), the sensor above the table and "
            "the whole arc within the measuring range; check the target's placement and the "
            "reach box"
        )
    T_flange = T_sensor @ invert_transform(T_flange_sensor)
    profiles = predicted_profiles(plannable, placement, T_sensor, limits)
    all_info = plannable.information(
        placement,
        T_flange_sensor,
        list(points) + profiles,
        np.concatenate([T_current, T_flange]),
        config,
    )
    G = all_info.shape[1]
    information = WEAK_PRIOR_INFORMATION * np.eye(G) + all_info[: len(points)].sum(axis=0)
    gains = all_info[len(points) :]
    start = predicted_sigma(information) if len(points) >= 3 else (None, None)
    chosen: list[PlannedPose] = []
    for best in choose(information, gains, n, goal):
        information = information + gains[best]
        sigma_t, sigma_r = predicted_sigma(information)
        chosen.append(PlannedPose(T_flange[best], T_sensor[best], sigma_t, sigma_r))
    reached = within((chosen[-1].sigma_translation_m, chosen[-1].sigma_rotation_rad), goal)
    return Plan(chosen, start[0], start[1], reached, len(T_sensor), len(points))


def fan_shape(plan: Plan, constraints: PlanConstraints) -> Shape:
    """The laser fan of every planned pose as line segments (for RViz markers): from the
    sensor origin to both ends of the measuring window, and the window's near and far edges.
    """
    tan_fan = math.tan(constraints.fan_half_angle_rad)
    z_lo, z_hi = constraints.z_min_m, constraints.z_max_m
    window = np.array(
        [
            [-tan_fan * z_lo, 0.0, z_lo],
            [tan_fan * z_lo, 0.0, z_lo],
            [-tan_fan * z_hi, 0.0, z_hi],
            [tan_fan * z_hi, 0.0, z_hi],
        ]
    )
    local = np.array([[0.0, 0.0, 0.0], window[2], [0.0, 0.0, 0.0], window[3], *window])
    segments = [
        local @ pose.T_base_sensor[:3, :3].T + pose.T_base_sensor[:3, 3] for pose in plan.poses
    ]
    points = np.concatenate(segments) if segments else np.zeros((0, 3))
    return Shape("line", points, 0.0005, "planned_fans", (1.0, 0.2, 0.2, 0.8))


def with_noise_levels(config: Any, levels: Mapping[str, float] | None) -> Any:
    """The target's settings with the noise levels a result re-estimated (its section's
    ``noise_levels``: any of ``sensor_sigma_m``, ``robot_sigma_t_m`` and
    ``robot_sigma_r_rad`` of the settings' ``refine``, m and rad); unchanged without them.

    Raises
    ------
    InputError
        A level that is not one of those, or not a positive number.
    """
    if not levels:
        return config
    for key, value in levels.items():
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if key not in NOISE_LEVELS or not (number and math.isfinite(value) and value > 0.0):
            raise InputError(
                f"the result's quality.noise_estimated.{key} must be one of "
                f"{', '.join(NOISE_LEVELS)} with a positive value (m or rad), got {value!r}"
            )
    return replace(
        config, refine=replace(config.refine, **{k: float(v) for k, v in levels.items()})
    )


def plannable(target: Target[Any]) -> Plannable:
    """The target's planner.

    Raises
    ------
    InputError
        The target has none.
    """
    planner: Plannable | None = getattr(target, "planner", None)
    if planner is None:
        raise InputError(
            f"poses cannot be planned for the {target.title} target yet: record its poses by "
            "hand (the recording guide gives the rules)"
        )
    return planner


def plan_for_target(
    target: Target[Any],
    config: Any,
    T_flange_sensor: FloatArray,
    n: int,
    *,
    samples: list[Sample] | None = None,
    section: Any = None,
    numbers: list[float] | None = None,
    extent: Any = None,
    constraints: PlanConstraints | None = None,
    goal: tuple[float, float] | None = None,
    seed: int = 0,
) -> Plan:
    """Plan poses for a target from its rough placement and the samples taken so far.

    The placement comes from ``section`` (a result's target section), else from ``numbers``
    (the target's ``numbers_setting``), else from the samples' features (exploratory scans)
    with ``T_flange_sensor`` as the initial hand-eye.

    Parameters
    ----------
    target : Target
    config : target config
    T_flange_sensor : ndarray, shape (4, 4)
        Current or initial hand-eye.
    n : int
    samples : list of Sample, optional
        Samples already taken (their information is the planner's start).
    section, numbers, extent : optional
        See above and :class:`Plannable`. A section's re-estimated noise levels replace the
        configured ones (:func:`with_noise_levels`).
    constraints : PlanConstraints, optional
    goal : (float, float), optional
        (translation m, rotation rad).
    seed : int

    Raises
    ------
    InputError, DegenerateError
        No placement can be formed, or no pose is feasible.
    """
    planner = plannable(target)
    features: list[Any] = []
    if samples:
        features, _ = target.extract(samples, config, seed, lambda *_: None)
    points = planner.sample_points(features)
    T_current = np.array([f.T_base_flange for f in features]).reshape(-1, 4, 4)
    T_sensor = T_current @ T_flange_sensor
    points_base = (
        np.concatenate([p @ T[:3, :3].T + T[:3, 3] for p, T in zip(points, T_sensor, strict=True)])
        if points
        else None
    )
    if section is not None:
        config = with_noise_levels(config, getattr(section, "noise_levels", None))
        placement = planner.placement_from_section(section, config, extent, points_base)
    elif numbers is not None:
        placement = planner.placement_from_numbers(numbers, config, extent, points_base)
    else:
        if not features:
            raise DegenerateError(
                f"none of the {len(samples or [])} exploratory scans shows the {target.title}: "
                f"scan it from 3 or more poses first, or give its placement with "
                f"{setting(planner.numbers_setting)} or "
                "{setting:from_result} RESULT.yaml"
            )
        placement = planner.placement_from_features(features, T_flange_sensor, config, extent)
    return plan_poses(
        planner,
        placement,
        T_flange_sensor,
        config,
        n,
        np.random.default_rng(seed),
        constraints,
        (points, T_current) if points else None,
        goal,
    )
