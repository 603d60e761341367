"""NSGA-II identification (panto.identification.estimation.genetic): the front, recovery, parallel populations, polish."""
import sys
import types
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
from scipy import signal

from panto.identification.estimation.base import IdentificationData, IdentificationError, ModelStructure
from panto.identification.estimation import genetic
from panto.identification.estimation.genetic import ParetoResult, fit_pareto, polish_cost
from panto.identification.estimation.plots import plot_pareto

PERIOD = 0.02


class Oscillator(ModelStructure):
    """Unit mass on a spring k and damper c, driven by the force b u.

    Outputs: the position ``y_cb = x`` and the suspension force ``F_c = k x + c v``.
    Both depend on all three parameters, so they can be fitted together.
    """

    name = "test-oscillator"
    input_names = ("u",)
    output_names = ("y_cb", "F_c")
    parameter_names = ("k", "c", "b")

    def nominal(self):
        return {"k": 50.0, "c": 3.0, "b": 2.0}

    def bounds(self):
        return {"k": (5.0, 500.0), "c": (0.5, 20.0), "b": (0.2, 20.0)}

    def simulate(self, parameters, data):
        p = {**self.nominal(), **parameters}
        if p["k"] <= 0 or p["c"] < 0:
            raise IdentificationError(f"k = {p['k']} and c = {p['c']} must be positive")
        augmented = np.zeros((3, 3))
        augmented[:2, :2] = [[0.0, 1.0], [-p["k"], -p["c"]]]
        augmented[1, 2] = p["b"]
        step = _expm(augmented * data.sample_period)   # zero-order hold
        ad, bd = step[:2, :2], step[:2, 2]
        denominator = [1.0, -np.trace(ad), np.linalg.det(ad)]
        adjugate_part = np.array([[-ad[1, 1], ad[0, 1]], [ad[1, 0], -ad[0, 0]]]) @ bd
        columns = []
        for c in ([1.0, 0.0], [p["k"], p["c"]]):
            numerator = [0.0, np.dot(c, bd), np.dot(c, adjugate_part)]
            columns.append(signal.lfilter(numerator, denominator, data.input("u")))
        return np.column_stack(columns)


def _expm(matrix):
    """Matrix exponential by eigen-decomposition (distinct eigenvalues; a 3 x 3 here)."""
    values, vectors = np.linalg.eig(matrix)
    return np.real(vectors @ np.diag(np.exp(values)) @ np.linalg.inv(vectors))


class Conflicting(ModelStructure):
    """One gain for two channels: ``y_cb = a u1`` and ``F_c = a u2``; the data has a = 1 on the
    first and a = 2 on the second, so the true Pareto set is 1 <= a <= 2. ``a > 2.5`` is invalid
    (to exercise infeasible candidates)."""

    name = "test-conflicting"
    input_names = ("u1", "u2")
    output_names = ("y_cb", "F_c")
    parameter_names = ("a",)

    def nominal(self):
        return {"a": 1.0}

    def bounds(self):
        return {"a": (0.0, 3.0)}

    def simulate(self, parameters, data):
        a = parameters.get("a", 1.0)
        if a > 2.5:
            raise IdentificationError(f"a = {a} is beyond the valid range")
        return a * data.inputs


def _aprbs(n, seed, levels=(-1.0, 1.0), hold=25):
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(*levels, size=n // hold + 1), hold)[:n]


def oscillator_data(truth, n=1500):
    t = np.arange(n) * PERIOD
    u = _aprbs(n, 3)
    empty = IdentificationData(t, u[:, None], np.zeros((n, 2)), ("u",), ("y_cb", "F_c"))
    y = Oscillator().simulate(truth, empty)
    return IdentificationData(t, u[:, None], y, ("u",), ("y_cb", "F_c"), source="simulated")


def conflicting_data(n=400):
    t = np.arange(n) * PERIOD
    u = np.c_[_aprbs(n, 1), _aprbs(n, 2)]
    return IdentificationData(t, u, u * [1.0, 2.0], ("u1", "u2"), ("y_cb", "F_c"))


def dominates(a, b):
    """Fits (maximised): a dominates b."""
    return np.all(a >= b) and np.any(a > b)


@pytest.fixture(scope="module")
def conflicting_front():
    return fit_pareto(Conflicting(), conflicting_data(), free=["a"], population=24,
                      generations=25, seed=4)


def test_front_is_non_dominated_and_spans_the_trade_off(conflicting_front):
    result = conflicting_front
    fits = result.objectives
    assert len(result.front) >= 5
    for i, a in enumerate(fits):
        assert not any(dominates(b, a) for j, b in enumerate(fits) if j != i)
    gains = np.array([p["a"] for p in result.front])
    assert np.all((gains > 1.0 - 1e-3) & (gains < 2.0 + 1e-3)), "outside the true Pareto set"
    assert gains.min() < 1.1 and gains.max() > 1.9, "the front does not span the trade-off"
    # Each end of the front is (nearly) perfect on one objective: fit 100 % at a = 1 and a = 2.
    assert fits[:, 0].max() > 95.0 and fits[:, 1].max() > 95.0


def test_objectives_equal_the_fit_of_each_solution(conflicting_front):
    data = conflicting_data()
    for parameters, fits in zip(conflicting_front.front, conflicting_front.objectives):
        y_hat = parameters["a"] * data.inputs
        expected = 100 * (1 - np.linalg.norm(data.outputs - y_hat, axis=0)
                          / np.linalg.norm(data.outputs - data.outputs.mean(axis=0), axis=0))
        assert fits == pytest.approx(expected)


def test_infeasible_candidates_are_penalised_not_fatal(conflicting_front):
    assert sum(h["infeasible"] for h in conflicting_front.history) > 0
    assert all(p["a"] <= 2.5 for p in conflicting_front.front)
    assert conflicting_front.n_evaluations == 24 * 25
    assert len(conflicting_front.history) == 25


def test_pick_rules_choose_the_ends_and_the_middle(conflicting_front):
    best_force = conflicting_front.pick(rule="best:F_c")
    best_bar = conflicting_front.pick(rule="best:y_cb")
    knee = conflicting_front.pick()
    assert best_force.parameters["a"] == pytest.approx(2.0, abs=0.05)
    assert best_bar.parameters["a"] == pytest.approx(1.0, abs=0.05)
    assert 1.2 < knee.parameters["a"] < 1.8
    weighted = conflicting_front.pick(weights=[0.0, 1.0])
    assert weighted.parameters == best_force.parameters
    assert best_force.method == "nsga2" and best_force.free == ("a",)
    data = conflicting_data()
    assert best_force.fit_on(data, ("y_cb", "F_c")) == pytest.approx(best_force.fit)
    with pytest.raises(IdentificationError, match="not an objective"):
        conflicting_front.pick(rule="best:xi")


def test_ga_recovers_known_parameters_on_noise_free_data():
    truth = {"k": 120.0, "c": 4.0, "b": 3.0}
    lines = []
    result = fit_pareto(Oscillator(), oscillator_data(truth, n=750), free=["k", "c", "b"],
                        population=30, generations=25, seed=1, progress=lines.append)
    chosen = result.pick()
    for name, value in truth.items():
        assert chosen.parameters[name] == pytest.approx(value, rel=0.1), name
    assert min(chosen.fit.values()) > 90.0
    assert len(lines) == 25 and "generation 25/25" in lines[-1]
    best = np.array([h["best_fit"] for h in result.history])
    assert np.all(np.diff(best, axis=0) >= -1e-9), "best fit so far must not decrease"


def _fake_least_squares(shift):
    """A stand-in for fit_least_squares that moves every free parameter by `shift` (relative)."""
    def fit(structure, data, *, free, initial, **options):
        moved = dict(initial)
        moved.update({name: initial[name] * (1 + shift) for name in free})
        return genetic.make_result(
            ParetoResult(structure, tuple(free), ("y_cb", "F_c"), (), np.empty((0, 2)),
                         np.empty((0, 2)), (), {}, 0, 0.0), moved, {}, method="lm",
            success=True, message="fake", details={})
    return fit


def test_polish_keeps_the_pareto_solution_when_least_squares_is_worse(monkeypatch,
                                                                      conflicting_front):
    fake = types.ModuleType("panto.identification.estimation.least_squares")
    fake.fit_least_squares = _fake_least_squares(0.3)
    monkeypatch.setitem(sys.modules, "panto.identification.estimation.least_squares", fake)
    data = conflicting_data()
    chosen = conflicting_front.pick(rule="best:F_c")
    kept = conflicting_front.polish(chosen, data)
    assert kept.parameters == chosen.parameters
    assert kept.details["polish"]["kept"] == "pareto"


def test_polish_by_levenberg_marquardt_never_worsens(tmp_path):
    pytest.importorskip("panto.identification.estimation.least_squares")
    truth = {"k": 120.0, "c": 4.0, "b": 3.0}
    data = oscillator_data(truth)
    rng = np.random.default_rng(7)
    noisy = IdentificationData(data.time, data.inputs,
                               data.outputs + 0.02 * data.outputs.std(axis=0)
                               * rng.normal(size=data.outputs.shape),
                               data.input_names, data.output_names)
    result = fit_pareto(Oscillator(), noisy, free=["k", "c", "b"], population=16,
                        generations=4, seed=2)
    for index in range(min(3, len(result.front))):
        chosen = result.pick(index)
        polished = result.polish(chosen, noisy)
        assert polish_cost(list(polished.fit.values())) <= \
            polish_cost(list(chosen.fit.values())) + 1e-12
        summary = polished.details["polish"]
        assert summary["before"] == pytest.approx(chosen.fit)
    assert plot_pareto(result, tmp_path / "pareto.png", picked=chosen, polished=polished)
    assert (tmp_path / "pareto.png").stat().st_size > 10_000


def test_population_evaluated_on_a_process_pool_gives_the_same_front():
    data = conflicting_data()
    serial = fit_pareto(Conflicting(), data, free=["a"], population=12, generations=3, seed=9)
    with ProcessPoolExecutor(max_workers=2) as pool:
        parallel = fit_pareto(Conflicting(), data, free=["a"], population=12, generations=3,
                              seed=9, executor=pool)
    assert parallel.objectives == pytest.approx(serial.objectives)


def test_population_evaluated_on_a_local_dask_cluster():
    distributed = pytest.importorskip("distributed")
    data = oscillator_data({"k": 120.0, "c": 4.0, "b": 3.0}, n=300)
    serial = fit_pareto(Oscillator(), data, free=["k", "c"], population=8, generations=2,
                        seed=5)
    with distributed.LocalCluster(n_workers=2, processes=False, threads_per_worker=1,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        parallel = fit_pareto(Oscillator(), data, free=["k", "c"], population=8,
                              generations=2, seed=5, executor=client)
    assert parallel.objectives == pytest.approx(serial.objectives)
    assert parallel.n_evaluations == 16


def test_bad_options_are_named():
    data = conflicting_data()
    with pytest.raises(IdentificationError, match="'q'"):
        fit_pareto(Conflicting(), data, free=["q"])
    with pytest.raises(IdentificationError, match="objective 'xi'"):
        fit_pareto(Conflicting(), data, free=["a"], objectives=("xi", "F_c"))
    with pytest.raises(IdentificationError, match="bounds of 'a'"):
        fit_pareto(Conflicting(), data, free=["a"], bounds={"a": (1.0, float("inf"))})


def test_search_stops_once_a_candidate_reaches_a_target_fit():
    data = conflicting_data()
    # The best compromise here has a least-squares cost of about 0.21 (fits about 68 % / 67 %).
    target = polish_cost([66.0, 66.0])
    result = fit_pareto(Conflicting(), data, free=["a"], population=12, generations=40,
                        seed=3, stop=lambda record: record["best_cost"] <= target)
    assert result.history[-1]["best_cost"] <= target
    assert len(result.history) < 40 and result.n_evaluations == 12 * len(result.history)
    costs = [h["best_cost"] for h in result.history]
    assert costs == sorted(costs, reverse=True)
