"""The robot's pose error shared by neighbouring views (:mod:`~linelaser_calib.core.
shared_pose`): learned from the residuals, counted in the line's, known point's, cylinder's and
sphere's 1σ."""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import replace
from functools import cache
from unittest import mock

import numpy as np
from scipy.spatial.transform import Rotation

from linelaser_calib.core.geometry import rotvec_from_matrix
from linelaser_calib.core.pairing import PairingConfig, pair_profiles
from linelaser_calib.core.shared_pose import (
    ViewsLinearised,
    pose_separations,
    shared_pose_error,
)
from linelaser_calib.core.subsets import model_sigma, statistical_sigma
from linelaser_calib.core.targets import get_target
from linelaser_calib.core.targets.base import SolveContext, TargetSolution
from linelaser_calib.core.targets.cylinder import CylinderConfig
from linelaser_calib.core.targets.cylinder import target as cylinder_target
from linelaser_calib.core.targets.line.config import LineConfig
from linelaser_calib.core.types import Sample
from linelaser_calib.sim.clutter import field_offsets
from linelaser_calib.sim.line import line_scenario_from_preset, simulate_line
from linelaser_calib.sim.presets import scenario_from_preset
from linelaser_calib.sim.robot import draw_errors, error_transforms
from linelaser_calib.sim.simulate import SimulatedData, simulate

#: Views of the synthetic sweep, their step (m) and the global parameters.
VIEWS, STEP_M, GLOBALS = 60, 0.005, 6


def _sweep(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flange poses 5 mm apart along x, and each view's Jacobians: of its two residuals on the
    globals (M, 2, G), and on its pose error in units of the prior (M, 2, 6), both changing
    slowly along the sweep as a line's views do."""
    T = np.tile(np.eye(4), (VIEWS, 1, 1))
    T[:, 0, 3] = STEP_M * np.arange(VIEWS)
    phase = np.linspace(0.0, 3.0, VIEWS)[:, None, None]
    X = np.sin(phase * rng.uniform(0.5, 2.0, (1, 2, GLOBALS)) + rng.uniform(0, 6, (1, 2, GLOBALS)))
    A = 3.0 * np.cos(phase * rng.uniform(0.5, 2.0, (1, 2, 6)) + rng.uniform(0, 6, (1, 2, 6)))
    return T, X, A


def _draw(rng: np.random.Generator, A: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Residuals (M, 2): unit corner noise plus the pose errors with correlation K (M, M)."""
    e = np.linalg.cholesky(K + 1e-9 * np.eye(len(K))) @ rng.normal(size=(len(K), 6))
    return np.einsum("mkl,ml->mk", A, e) + rng.normal(size=(len(K), 2))


def _views(y: np.ndarray, X: np.ndarray, A: np.ndarray, T: np.ndarray) -> ViewsLinearised:
    return ViewsLinearised(y, X, A, np.ones(6), np.zeros(0), np.zeros((0, GLOBALS)), T)


def _per_view(X: np.ndarray, A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The per-view estimate (each view's pose error alone, as the refinement solves it) and
    the covariance that model states."""
    V0 = np.eye(2) + A @ A.transpose(0, 2, 1)
    Z = np.linalg.solve(V0, X)
    H = np.einsum("mkg,mkh->gh", X, Z)
    return np.linalg.solve(H, np.einsum("mkg,mk->g", Z, y)), np.linalg.inv(H)


def test_a_shared_pose_error_is_learned_and_counted_in_the_1_sigma() -> None:
    """Pose errors shared over about 8 neighbouring views scatter the per-view estimate more
    than its own covariance says; the learned sharing's covariance matches the scatter."""
    rng = np.random.default_rng(1)
    T, X, A = _sweep(rng)
    K = np.exp(-pose_separations(T, T) / 0.8)  # e⁻¹ at 8 views
    estimates, stated = [], None
    for _ in range(400):
        x, stated = _per_view(X, A, _draw(rng, A, K))
        estimates.append(x)
    spread = np.std(estimates, axis=0)
    assert stated is not None
    assert np.all(spread > 1.5 * np.sqrt(np.diag(stated)))  # the per-view 1σ is too small
    learned = [shared_pose_error(_views(_draw(rng, A, K), X, A, T)) for _ in range(4)]
    sigma = np.mean([np.sqrt(np.diag(s.covariance)) for s in learned if s is not None], axis=0)
    assert np.all(np.abs(sigma / spread - 1.0) < 0.3), sigma / spread


def test_independent_pose_errors_keep_the_per_view_1_sigma() -> None:
    rng = np.random.default_rng(2)
    T, X, A = _sweep(rng)
    y = _draw(rng, A, np.eye(VIEWS))
    learned = shared_pose_error(_views(y, X, A, T))
    assert learned is not None
    ratio = np.sqrt(np.diag(learned.covariance) / np.diag(_per_view(X, A, y)[1]))
    assert np.all(np.abs(ratio - 1.0) < 0.25), ratio


def widening(solution: TargetSolution) -> np.ndarray:
    """The factors (6,) for the profiles' scatter a solution widened its 1σ by (1 where none)."""
    return np.ones(6) if solution.sigma_widening is None else solution.sigma_widening


def _line_ridge(
    seed: int, cell_field: bool = False, bumped: int | None = None
) -> tuple[TargetSolution, np.ndarray, int]:
    """The line target's default solve of ``line_ridge`` (``cell_field``: with issue 29's
    cell's smooth field of the flange pose added to the recorded poses, 0.4 mm and 0.02 deg
    over 0.1 m, about seven times the stated 0.03 mm; ``bumped``: that sample's pose alone
    0.3 mm off along base y), its |error| / 1σ per axis and the profiles recorded."""
    scenario = line_scenario_from_preset("line_ridge")
    data = simulate_line(scenario, seed)
    pairing = PairingConfig(
        max_linear_speed_m_s=0.0,
        max_angular_speed_rad_s=0.0,
        clock_offset_s=-scenario.rig.latency_s,
    )
    samples = pair_profiles(data.profiles, data.poses, pairing).samples
    if cell_field:
        T = np.stack([s.T_base_flange for s in samples])
        shift, turn = (
            field_offsets(
                np.random.default_rng(seed + k),
                replace(scenario.rig, robot_field_m=(size,) * 3, robot_field_length_m=0.1),
                T[:, :3, 3],
            )
            for k, size in ((0, 4e-4), (1, np.radians(0.02)))
        )
        T[:, :3, :3] = Rotation.from_rotvec(turn).as_matrix() @ T[:, :3, :3]
        T[:, :3, 3] += shift
        if bumped is not None:
            T[bumped, 1, 3] += 3e-4
        samples = [replace(s, T_base_flange=t) for s, t in zip(samples, T, strict=True)]
    target, config = get_target("line"), LineConfig()
    features, _ = target.extract(samples, config, 0, lambda *_: None)
    solution = target.solve_default(features, config, SolveContext(n_samples=len(samples)))
    truth = data.truth.T_flange_sensor
    error = np.r_[
        rotvec_from_matrix(truth[:3, :3].T @ solution.T_flange_sensor[:3, :3]),
        solution.T_flange_sensor[:3, 3] - truth[:3, 3],
    ]
    assert solution.sigma_rotation_rad is not None and solution.sigma_translation_m is not None
    sigma = np.r_[solution.sigma_rotation_rad, solution.sigma_translation_m]
    return solution, np.abs(error) / sigma, len(samples)


def test_line_ridge_seed_6_is_within_3_sigma() -> None:
    """Regression: the simulated arm's error on ``line_ridge`` is drawn at 8 points of the
    sweep and blended, so about six neighbouring views share it; with each view's error
    taken as independent, seed 6 came out 3.79 of its 1σ off (rotation about sensor z).
    The widening is named (``sigma_shared``), so that the self-check judges the robot's
    error against the 1σ without it (:func:`~linelaser_calib.core.subsets.model_sigma`), as
    the cylinder's and the sphere's."""
    solution, z, _ = _line_ridge(6)
    assert np.all(z <= 3.0), z
    assert solution.sigma_shared is not None and float(np.max(solution.sigma_shared)) > 1.2
    noise, statistical = model_sigma(solution), statistical_sigma(solution)
    assert noise is not None and statistical is not None
    np.testing.assert_allclose(
        noise * widening(solution) * solution.sigma_shared, statistical, rtol=1e-9
    )


def test_a_line_whose_arm_errs_far_beyond_its_prior_is_within_3_sigma_and_warned() -> None:
    """Issue 29's cell field on ``line_ridge``: with the shared error bounded by the stated
    prior seed 1 came out 7.1 of its 1σ off; learned as a smooth error over each view's own
    it is within 3 and a warning names the larger error. The views that err with their
    neighbours are all used; one whose pose alone is 0.3 mm off is set aside, its
    neighbours not explaining it."""
    solution, z, recorded = _line_ridge(1, cell_field=True, bumped=25)
    assert np.all(z <= 3.0), z
    assert any("the robot's pose error is about" in w for w in solution.warnings)
    (aside,) = solution.rejections
    assert aside.index == 25 and "given its neighbours" in aside.reason
    assert len(solution.samples_used) == recorded - 1


def _regional(T: np.ndarray, seed: int, per_anchor: int, scenario: object) -> np.ndarray:
    """Flange poses (M, 4, 4) with the rig's error drawn at every ``per_anchor``-th view of a
    nearest-neighbour tour of them and blended between (1: each view's own)."""
    D = pose_separations(T, T)
    order = [0]
    while len(order) < len(T):
        order.append(min(set(range(len(T))) - set(order), key=lambda j: D[order[-1], j]))
    position = np.argsort(order)
    rng = np.random.default_rng(seed)
    errors = draw_errors(rng, scenario, len(T) // per_anchor + 2)  # type: ignore[arg-type]
    weight = position % per_anchor / per_anchor
    return T @ error_transforms(scenario, errors, position // per_anchor, weight)  # type: ignore[arg-type]


@cache
def _small_cylinder() -> SimulatedData:
    return simulate(scenario_from_preset("ur_scancontrol", n_poses=40, resolution=320), 1)


def _cylinder_z(per_anchor: int) -> dict[str, np.ndarray]:
    """|error| / 1σ of a small cylinder recording (``ur_scancontrol``, 40 poses, seed 1) whose
    arm errs by region (``per_anchor`` 4) or per pose (1), with the per-view 1σ and with the
    shared error counted; and the two 1σ."""
    data = _small_cylinder()
    truth = data.truth
    T = _regional(truth.T_base_flange_true, 1, per_anchor, truth.scenario)
    samples = [Sample(k, p.stamp_ns, T[k], p.points) for k, p in enumerate(data.profiles)]
    target, config = get_target("cylinder"), CylinderConfig()
    features, _ = target.extract(samples, config, 0, lambda *_: None)
    out = {}
    for name in ("per-view", "shared"):
        with (
            mock.patch.object(cylinder_target, "with_shared", lambda r, _=None: (r, None, None))
            if name == "per-view"
            else nullcontext()
        ):
            solution = target.solve_default(features, config, SolveContext(n_samples=len(samples)))
        X, X_true = solution.T_flange_sensor, truth.T_flange_sensor
        error = np.r_[rotvec_from_matrix(X_true[:3, :3].T @ X[:3, :3]), X[:3, 3] - X_true[:3, 3]]
        assert solution.sigma_rotation_rad is not None and solution.sigma_translation_m is not None
        sigma = np.r_[solution.sigma_rotation_rad, solution.sigma_translation_m]
        out[name], out[f"sigma {name}"] = np.abs(error) / sigma, sigma
    return out


def test_a_cylinder_whose_arm_errs_by_region_is_within_its_1_sigma() -> None:
    """The arm's error drawn at every 4th view of the tour and blended: the per-view 1σ left
    the hand-eye 3.2 of it off; counting the error the views share holds it within 1.5.
    Where each pose errs alone the 1σ widens by at most 15 %."""
    regional = _cylinder_z(4)
    assert regional["per-view"].max() > 2.5, regional["per-view"]
    assert regional["shared"].max() < 1.5, regional["shared"]
    independent = _cylinder_z(1)
    ratio = independent["sigma shared"] / independent["sigma per-view"]
    assert np.all((ratio >= 1.0) & (ratio < 1.15)), ratio
