"""Independent starts run in parallel give the serial result (issue 24, "Speed"): the global
fit's polished frequency-response starts, time-domain starts and perturbations on a process
pool, the adequacy's black boxes on a process pool, and a global fit handed the default start's
result instead of refitting it."""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from scipy import signal

from panto.identification.estimation.base import IdentificationData, ModelStructure
from panto.identification.estimation.global_fit import GlobalFitOptions, fit_global
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.structures.adequacy import check_adequacy

OPTIONS = GlobalFitOptions(data_starts=2, perturbations=2)


class _FirstOrder(ModelStructure):
    """``y' = -w y + g u``: a first-order lag (the truth is in the class)."""

    name = "first-order"
    input_names = ("u",)
    output_names = ("y",)
    parameter_names = ("g", "w")

    def nominal(self):
        return {"g": 1.0, "w": 3.0}

    def bounds(self):
        return {"g": (0.05, 50.0), "w": (0.3, 100.0)}

    def linear_system(self, parameters, data):
        p = {**self.nominal(), **parameters}
        return np.array([[-p["w"]]]), np.array([[p["g"]]]), np.eye(1), np.zeros((1, 1))

    def simulate(self, parameters, data):
        system = signal.lti(*self.linear_system(parameters, data))
        return signal.lsim(system, data.inputs[:, 0], data.time)[1][:, None]


@pytest.fixture(scope="module")
def data() -> IdentificationData:
    rng = np.random.default_rng(11)
    n = 1024
    t = np.arange(n) / 50.0
    u = signal.lfilter(*signal.butter(2, 0.3), rng.normal(size=n))
    blank = IdentificationData(t, u[:, None], np.zeros((n, 1)), ("u",), ("y",))
    y = _FirstOrder().simulate({"g": 6.0, "w": 8.0}, blank)[:, 0]
    return IdentificationData(t, u[:, None], (y + 0.05 * y.std() * rng.normal(size=n))[:, None],
                              ("u",), ("y",))


def _starts(result):
    return [(s["origin"], s["cost"], s["parameters"]) for s in
            result.details["global_fit"]["starts"]]


def test_parallel_starts_and_a_given_default_start_give_the_serial_global_fit(data):
    structure = _FirstOrder()
    serial = fit_global(structure, data, free=("g", "w"), options=OPTIONS)
    default = fit_least_squares(structure, data, free=("g", "w"),
                                max_evaluations=OPTIONS.max_evaluations)
    with ProcessPoolExecutor(2) as pool:
        parallel = fit_global(structure, data, free=("g", "w"), default=default,
                              options=GlobalFitOptions(data_starts=2, perturbations=2,
                                                       starts_executor=pool))
    origins = [s[0] for s in _starts(serial)]
    assert origins[0] == "default" and origins[-2:] == ["perturbation 1", "perturbation 2"]
    for (origin, cost, parameters), (origin2, cost2, parameters2) in zip(_starts(serial),
                                                                         _starts(parallel)):
        assert origin == origin2
        assert cost2 == pytest.approx(cost, rel=1e-9, abs=1e-300)
        assert parameters2 == pytest.approx(parameters, rel=1e-7)
    assert len(_starts(parallel)) == len(_starts(serial))
    assert parallel.parameters == pytest.approx(serial.parameters, rel=1e-7)
    assert parallel.parameters == pytest.approx({"g": 6.0, "w": 8.0}, rel=0.05)  # the truth
    assert parallel.details["global_fit"]["verdict"] == serial.details["global_fit"]["verdict"]


def test_black_boxes_fitted_in_parallel_are_the_serial_ones(data):
    structure = _FirstOrder()
    fitted = fit_least_squares(structure, data, free=("g", "w"))
    serial = check_adequacy(structure, fitted, data, orders=(1, 3))
    with ProcessPoolExecutor(2) as pool:
        parallel = check_adequacy(structure, fitted, data, orders=(1, 3), executor=pool)
    assert parallel.order == serial.order and parallel.verdict == serial.verdict
    assert parallel.black_box_fit == pytest.approx(serial.black_box_fit, rel=1e-9)
    assert parallel.nominal_fit == serial.nominal_fit
