"""The profile-to-profile dispersion check that widens a 1σ the noise model understates."""

from __future__ import annotations

import numpy as np
import pytest

from linelaser_calib.core.solver import (
    Linearisation,
    Residuals,
    Solution,
    SolverConfig,
    lm,
    normal_equations,
    recording_widening,
    sample_dispersion,
    solve_damped,
    widen_covariance,
)
from linelaser_calib.core.verdict import warning_kind

G, K = 4, 40
LINEAR = SolverConfig(loss="linear")


def _solved(
    rng: np.random.Generator,
    samples: int,
    point_sigma: float,
    prior_sigma_scale: float,
    shared_sigma: float = 0.0,
) -> Solution[None]:
    """A linear block problem solved exactly: K points per sample, G globals, 6 locals.

    The model weighs each point with σ 1 and each pose correction with prior precision
    ``precision``; the data have point noise ``point_sigma``, corrections drawn with
    ``prior_sigma_scale`` times the prior's σ, and (``shared_sigma``) a depth offset shared
    by all of a sample's points, which the model does not know.
    """
    J_global = rng.normal(size=(samples, K, G)) + 0.5
    J_local = rng.normal(size=(samples, K, 6))
    precision = np.full(6, 4.0)
    sqrt_info = np.sqrt(precision)
    corrections = rng.normal(size=(samples, 6)) * prior_sigma_scale / sqrt_info
    noise = point_sigma * rng.normal(size=(samples, K))
    noise += shared_sigma * rng.normal(size=(samples, 1))
    y = np.einsum("mkl,ml->mk", J_local, corrections) + noise
    # Residual(x, δ) = J_g x + J_l δ − y: one exact Gauss–Newton step from zero.
    start = Linearisation(
        residuals=Residuals(-y, np.zeros((samples, 6))),
        J_global=J_global,
        J_local=J_local,
        pose_prior_sqrt_information=sqrt_info,
    )
    step_global, step_local = solve_damped(normal_equations(start, LINEAR), 0.0)
    e = -y + J_global @ step_global + np.einsum("mkl,ml->mk", J_local, step_local)
    at_solution = Linearisation(
        residuals=Residuals(e, step_local * sqrt_info),
        J_global=J_global,
        J_local=J_local,
        pose_prior_sqrt_information=sqrt_info,
    )
    return Solution(
        state=None,
        residuals=at_solution.residuals,
        normal=normal_equations(at_solution, LINEAR),
        cost_history=[0.0],
        iterations=1,
        converged=True,
    )


def test_dispersion_is_one_where_the_noise_model_holds() -> None:
    rng = np.random.default_rng(3)
    solution = _solved(rng, 400, 1.0, 1.0)
    ratio = sample_dispersion(solution, 1.0, 1.0)
    assert ratio is not None and ratio.shape == (G,)
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio


def test_dispersion_takes_the_variance_factors_into_account() -> None:
    # Points twice as noisy and an arm half as erring as configured: with the variance
    # factors the model's prediction (4 and 0.25) the ratio is still about 1, without them
    # it is not.
    rng = np.random.default_rng(4)
    solution = _solved(rng, 400, 2.0, 0.5)
    ratio = sample_dispersion(solution, 4.0, 0.25)
    assert ratio is not None and np.all((ratio > 0.8) & (ratio < 1.25)), ratio
    unscaled = sample_dispersion(solution, 1.0, 1.0)
    assert unscaled is not None and np.all(unscaled > 2.0), unscaled


def test_dispersion_sees_an_error_shared_by_a_profiles_points() -> None:
    rng = np.random.default_rng(5)
    solution = _solved(rng, 400, 1.0, 1.0, shared_sigma=0.6)
    ratio = sample_dispersion(solution, 1.0, 1.0)
    assert ratio is not None and np.all(ratio > 2.0), ratio


def test_dispersion_is_the_same_taken_a_chunk_of_samples_at_a_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A long recording's jackknife runs over chunks of samples (bounded memory): 400 samples
    # in chunks of 64 give the ratio of one pass over all of them.
    solution = _solved(np.random.default_rng(7), 400, 1.0, 1.0, shared_sigma=0.3)
    whole = sample_dispersion(solution, 1.0, 1.0)
    monkeypatch.setattr(lm, "DISPERSION_CHUNK_SAMPLES", 64)
    chunked = sample_dispersion(solution, 1.0, 1.0)
    assert whole is not None and chunked is not None
    np.testing.assert_allclose(chunked, whole, rtol=1e-12)


def test_dispersion_needs_more_samples_than_globals() -> None:
    rng = np.random.default_rng(6)
    assert sample_dispersion(_solved(rng, G + 4, 1.0, 1.0), 1.0, 1.0) is None


def test_widen_covariance_scales_each_sigma_and_keeps_correlations() -> None:
    covariance = np.array([[4.0, 1.0, 0.0], [1.0, 1.0, 0.5], [0.0, 0.5, 9.0]])
    widened = widen_covariance(covariance, np.array([4.0, 0.5, 1.0]))
    sigma = np.sqrt(np.diag(widened))
    np.testing.assert_allclose(sigma, [4.0, 1.0, 3.0], rtol=1e-12)
    before = covariance / np.outer(np.sqrt(np.diag(covariance)), np.sqrt(np.diag(covariance)))
    np.testing.assert_allclose(widened / np.outer(sigma, sigma), before, rtol=1e-12)
    assert widen_covariance(covariance, None) is covariance


def test_a_warning_names_the_axis_that_scatters_beyond_twice_its_sigma() -> None:
    from linelaser_calib.core.solver import dispersion_warning

    assert dispersion_warning(None) is None
    assert dispersion_warning(np.array([1.0, 3.9, 1.0, 1.0, 1.0, 1.0, 50.0])) is None
    text = dispersion_warning(np.array([1.0, 1.0, 1.0, 1.0, 9.0, 1.0]))
    assert text is not None and "3.0 times" in text and "translation along y" in text


def test_the_recordings_variance_factor_widens_the_seam_targets_1_sigma() -> None:
    """A recording whose views scatter as modelled widens nothing; one whose views scatter
    4 times the modelled variance doubles the 1σ and says so as profile scatter."""
    rng = np.random.default_rng(0)
    modelled = rng.chisquare(2, 200)
    assert recording_widening(modelled, 2, 10)[0] < 1.2
    assert recording_widening(modelled, 2, 10)[1] is None
    factor, text = recording_widening(4.5 * modelled, 2, 10)
    assert 1.8 < factor < 2.4
    assert text is not None and warning_kind(text).id == "profile-scatter"
