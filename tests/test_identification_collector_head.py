"""Collector head (thesis 4.3): the PT2 of eqs. 4.15/4.16 recovers a known head's m, c, k."""
import numpy as np
import pytest
from scipy import signal

from panto.fmu_src.models import Model
from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.structures.collector_head import identify_collector_head, pt2_response
from panto.identification.structures.plots import plot_collector_head


def steps(rng, n, low, high, hold_min, hold_max):
    values, k = np.empty(n), 0
    while k < n:
        hold = rng.integers(hold_min, hold_max)
        values[k:k + hold] = rng.uniform(low, high)
        k += hold
    return values


def head_data(y_cb, xi, force, period):
    t = np.arange(len(force)) * period
    return IdentificationData(t, np.column_stack([force, y_cb]), xi[:, None], ("F_c", "y_cb"),
                              ("xi",), source="test")


@pytest.fixture(scope="module")
def pantograph_run():
    """The linearised pantograph (Table 4.1: m_c 6 kg, c_c 65.8 N s/m, k_c 21073 N/m) driven by
    ramped steps of eta and p, linear between samples, simulated by scipy's lsim at 200 Hz;
    outputs y_cb, xi, F_c."""
    rng = np.random.default_rng(3)
    period, n = 0.005, 8000
    lin = Model("Pantograph").linearise(2.0, 4.0)
    du = np.column_stack([steps(rng, n, -0.02, 0.02, 10, 200), steps(rng, n, -0.4, 0.4, 40, 300)])
    du = signal.lfilter(np.ones(10) / 10, [1.0], du, axis=0)  # 50 ms ramps
    x0 = -np.linalg.solve(lin.A, lin.B @ du[0])
    t = np.arange(n) * period
    y = signal.lsim((lin.A, lin.B, lin.C, lin.D), du, t, X0=x0)[1] + lin.y0
    return y, period, Model("Pantograph").parameters


def test_recovers_the_pantographs_head_from_eq_4_15(pantograph_run):
    y, period, parameters = pantograph_run
    result = identify_collector_head(head_data(y[:, 0], y[:, 1], y[:, 2], period))
    full = result.full
    for value, truth in ((full.mass, parameters["m_c"]), (full.damping, parameters["c_c"]),
                         (full.stiffness, parameters["k_c"])):
        assert value == pytest.approx(truth, rel=0.03)
    assert full.fit > 99.0
    assert full.natural_frequency_hz == pytest.approx(
        np.sqrt(parameters["k_c"] / parameters["m_c"]) / (2 * np.pi), rel=0.02)
    # the force-only model (4.16) ignores the cross bar's motion, which moves a lot here
    assert result.force_only.fit < full.fit


def test_eq_4_16_on_a_still_cross_bar_and_the_h1_estimate(tmp_path):
    rng = np.random.default_rng(5)
    m, c, k, period, n = 13.3, 24.1, 13142.0, 0.02, 6000  # thesis Table of section 4.3
    force = steps(rng, n, -20, 20, 1, 8)
    t = np.arange(n) * period
    delta = signal.lsim(([1.0], [m, c, k]), force, t, interp=False)[1]  # independent path (ZOH)
    # a zero-order-hold force is not linear between samples: resample the truth finely instead
    fine = 10
    t_fine = np.arange(n * fine) * period / fine
    force_fine = np.repeat(force, fine)
    delta = signal.lsim(([1.0], [m, c, k]), force_fine, t_fine)[1][::fine]
    y_cb = np.full(n, 1.9)
    xi = y_cb - delta - 0.004 + 2e-6 * rng.standard_normal(n)
    result = identify_collector_head(head_data(y_cb + 1e-9 * rng.standard_normal(n), xi, force, period))
    fit = result.force_only
    assert fit.mass == pytest.approx(m, rel=0.05)
    assert fit.stiffness == pytest.approx(k, rel=0.05)
    assert fit.damping == pytest.approx(c, rel=0.15)
    assert fit.offset == pytest.approx(0.004, abs=2e-4)
    # the non-parametric H1 estimate agrees with the fitted PT2 below 10 Hz where coherent
    band = (result.frequency > 0.5) & (result.frequency < 10.0) & (result.coherence_force > 0.9)
    assert band.sum() > 20
    ratio = np.abs(result.response_force_only[band]) / np.abs(pt2_response(fit, result.frequency[band]))
    assert np.median(np.abs(np.log(ratio))) < 0.1
    png = plot_collector_head(result, tmp_path / "head.png")
    assert png.stat().st_size > 10_000


def test_missing_head_position_is_named():
    t = np.arange(100) * 0.02
    data = IdentificationData(t, np.column_stack([np.sin(t), np.cos(t)]), np.sin(2 * t)[:, None],
                              ("F_c", "y_cb"), ("something",))
    with pytest.raises(IdentificationError, match="xi"):
        identify_collector_head(data)
