"""Fisher information, optimality criteria and the line example (thesis sections 5.2-5.3)."""
import numpy as np
import pytest
from scipy.stats import chi2

from panto.identification.design.fisher import (
    a_optimality,
    cramer_rao_covariance,
    criterion_cost,
    d_optimality,
    design_line_experiment,
    e_optimality,
    fisher_information,
    line_fisher_closed_form,
    line_sensitivities,
)


def _chi_square_band(n_realisations: int, tail: float = 5e-4) -> tuple[float, float]:
    """Band of sample variance / true variance holding with probability 1 - 2 tail."""
    dof = n_realisations - 1
    return chi2.ppf(tail, dof) / dof, chi2.ppf(1 - tail, dof) / dof


@pytest.mark.parametrize("n_points", [2, 3, 7])
def test_line_fisher_matrix_equals_its_closed_form(n_points):
    rng = np.random.default_rng(n_points)
    points = rng.uniform(-1, 1, n_points)
    fisher = fisher_information(line_sensitivities(points), 0.04)
    closed = line_fisher_closed_form(points, 0.04)
    assert fisher == pytest.approx(closed, rel=1e-12)
    if n_points == 2:  # det M = (x1 - x2)^2 / sigma^4 (section 5.3)
        assert np.linalg.det(fisher) == pytest.approx((points[0] - points[1]) ** 2 / 0.04 ** 2)


def test_per_output_noise_weights_each_output_and_stacks_are_scored_at_once():
    rng = np.random.default_rng(3)
    psi = rng.normal(size=(5, 40, 2, 3))          # 5 candidates, 40 samples, 2 outputs
    variance = np.array([0.5, 2.0])
    fisher = fisher_information(psi, variance)
    assert fisher.shape == (5, 3, 3)
    by_hand = sum(np.outer(psi[1, k, j], psi[1, k, j]) / variance[j]
                  for k in range(40) for j in range(2))
    assert fisher[1] == pytest.approx(by_hand, rel=1e-12)
    with pytest.raises(ValueError, match="noise_variance"):
        fisher_information(psi, np.array([1.0, 2.0, 3.0]))
    with pytest.raises(ValueError, match="positive"):
        fisher_information(psi[0, :, 0], -1.0)


def test_criteria_agree_with_their_definitions_and_flag_singular_matrices():
    rng = np.random.default_rng(4)
    factor = rng.normal(size=(6, 4, 4))
    matrices = factor @ np.swapaxes(factor, 1, 2) + 0.1 * np.eye(4)
    for matrix, a, d, e in zip(matrices, a_optimality(matrices), d_optimality(matrices),
                               e_optimality(matrices)):
        assert a == pytest.approx(np.trace(np.linalg.inv(matrix)))
        assert d == pytest.approx(np.log(np.linalg.det(matrix)))
        assert e == pytest.approx(min(np.linalg.eigvals(matrix).real))
    singular = np.diag([1.0, 0.0])
    assert a_optimality(singular) == np.inf and d_optimality(singular) == -np.inf
    assert criterion_cost(matrices[0], "D") == pytest.approx(-d_optimality(matrices[0]))
    with pytest.raises(ValueError, match="criterion"):
        criterion_cost(matrices[0], "G")
    assert cramer_rao_covariance(matrices[0]) @ matrices[0] == pytest.approx(np.eye(4), abs=1e-9)


@pytest.mark.parametrize("criterion", ["A", "D", "E"])
def test_two_point_design_is_plus_minus_one_with_zero_covariance_for_every_criterion(criterion):
    design = design_line_experiment(2, criterion=criterion, noise_variance=0.01)
    assert design.points == pytest.approx([-1.0, 1.0], abs=1e-6)
    assert design.covariance[0, 1] == pytest.approx(0.0, abs=1e-8)
    assert design.covariance == pytest.approx(0.01 * np.eye(2) / 2, rel=1e-6)


def test_three_points_put_the_third_at_an_end_point_or_at_zero_for_zero_covariance():
    free = design_line_experiment(3)
    assert np.all(np.isclose(np.abs(free.points), 1.0, atol=1e-6))
    assert {-1.0, 1.0} <= set(np.round(free.points, 6))
    assert np.exp(free.value) == pytest.approx(8.0, rel=1e-6)      # 3 * 3 - 1^2
    assert abs(free.covariance[0, 1]) > 0.1                         # covariance introduced
    balanced = design_line_experiment(3, zero_covariance=True)
    assert balanced.points == pytest.approx([-1.0, 0.0, 1.0], abs=1e-6)
    assert np.exp(balanced.value) == pytest.approx(6.0, rel=1e-6)  # 3 * 2 - 0
    assert balanced.covariance[0, 1] == pytest.approx(0.0, abs=1e-8)
    assert free.value > balanced.value


def test_cramer_rao_bound_matches_the_monte_carlo_spread_of_least_squares_estimates():
    rng = np.random.default_rng(5)
    points, sigma, n_realisations = np.array([-1.0, -0.2, 0.5, 1.0, 1.0]), 0.3, 400
    bound = cramer_rao_covariance(fisher_information(line_sensitivities(points), sigma ** 2))
    regressor = line_sensitivities(points)
    measured = regressor @ np.array([0.7, -0.4]) + sigma * rng.normal(size=(n_realisations, 5))
    estimates = np.linalg.lstsq(regressor, measured.T, rcond=None)[0].T
    low, high = _chi_square_band(n_realisations)
    ratios = estimates.var(axis=0, ddof=1) / np.diag(bound)
    assert np.all((ratios > low) & (ratios < high)), ratios
    correlation_bound = bound[0, 1] / np.sqrt(bound[0, 0] * bound[1, 1])
    assert np.corrcoef(estimates.T)[0, 1] == pytest.approx(correlation_bound, abs=0.2)


def test_line_design_rejects_bad_requests():
    with pytest.raises(ValueError, match="n_points"):
        design_line_experiment(1)
    with pytest.raises(ValueError, match="interval"):
        design_line_experiment(2, interval=(1.0, -1.0))
