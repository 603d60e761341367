"""The structures' comparison (panto.identification.estimation.comparison, thesis section 4.8)."""
import csv
import json

import numpy as np
import pytest
from scipy import signal

from panto.identification.estimation.base import (IdentificationData, IdentificationError, Identifier,
                                 ModelStructure)
from panto.identification.estimation.comparison import ComparisonTable, compare_structures
from panto.identification.estimation.plots import plot_comparison, plot_validation
from panto.identification.structures.registry import all_identifiers, comparison_identifiers
from panto.identification.estimation.least_squares import fit_least_squares

PERIOD = 0.02
OUTPUTS = ("y_cb", "F_c")


class Lag(ModelStructure):
    """First-order lag with time constant tau and a gain per output: y_j = K_j / (tau s + 1) u
    (exact discretisation for inputs held over a sample)."""

    name = "lag"
    input_names = ("u",)
    output_names = OUTPUTS
    parameter_names = ("tau", "K1", "K2")

    def nominal(self):
        return {"tau": 0.2, "K1": 1.0, "K2": 1.0}

    def bounds(self):
        return {"tau": (0.01, 5.0), "K1": (0.01, 100.0), "K2": (0.01, 100.0)}

    def simulate(self, parameters, data):
        p = {**self.nominal(), **parameters}
        pole = np.exp(-data.sample_period / p["tau"])
        unit = signal.lfilter([0.0, 1.0 - pole], [1.0, -pole], data.input("u"))
        return np.column_stack([p["K1"] * unit, p["K2"] * unit])


class Static(ModelStructure):
    """No dynamics: y_j = K_j u."""

    name = "static"
    input_names = ("u",)
    output_names = OUTPUTS
    parameter_names = ("K1", "K2")

    def nominal(self):
        return {"K1": 1.0, "K2": 1.0}

    def bounds(self):
        return {"K1": (0.01, 100.0), "K2": (0.01, 100.0)}

    def simulate(self, parameters, data):
        p = {**self.nominal(), **parameters}
        return np.column_stack([p["K1"] * data.input("u"), p["K2"] * data.input("u")])


def _identify_with(structure):
    def identify(data, *, executor=None, progress=None, **options):
        return fit_least_squares(structure, data, free=structure.parameter_names,
                                 executor=executor, progress=progress, **options)
    return identify


def _explode(data, **options):
    raise RuntimeError("solver exploded")


LAG = Identifier("lag", "first-order lag (the truth)", _identify_with(Lag()))
STATIC = Identifier("static", "static gains", _identify_with(Static()))
BROKEN = Identifier("broken", "always fails", _explode)


def _data(u, noise, seed):
    n = len(u)
    t = np.arange(n) * PERIOD
    frame = IdentificationData(t, u[:, None], np.zeros((n, 2)), ("u",), OUTPUTS)
    y = Lag().simulate({"tau": 0.35, "K1": 0.5, "K2": 40.0}, frame)
    y = y + noise * y.std(axis=0) * np.random.default_rng(seed).normal(size=y.shape)
    return IdentificationData(t, u[:, None], y, ("u",), OUTPUTS, source=f"simulated-{seed}")


@pytest.fixture(scope="module")
def runs():
    rng = np.random.default_rng(0)
    aprbs = np.repeat(rng.uniform(-1, 1, 40), 25)
    ramps = np.interp(np.arange(1000), [0, 200, 450, 700, 1000], [0, 1, -0.5, 0.8, 0])
    return _data(aprbs, 0.03, 1), _data(ramps, 0.03, 2)


@pytest.fixture(scope="module")
def table(runs):
    lines = []
    result = compare_structures(*runs, structures=[STATIC, BROKEN, LAG], progress=lines.append)
    return result, lines


def test_the_structure_that_made_the_data_ranks_first_on_validation(table):
    result, _ = table
    assert result.ranking()[0] == "lag"
    assert result.ranking(on="training")[0] == "lag"
    lag = result.row("lag")
    assert lag.success and lag.n_free == 3
    # 3 % noise: the true structure sits near the noise floor, 100 (1 - 0.03) = 97 %.
    for output in OUTPUTS:
        assert lag.fit_validation[output] > 95.0
        assert lag.fit_validation[output] > result.row("static").fit_validation[output]


def test_a_failing_structure_is_a_row_with_its_message(table):
    result, lines = table
    broken = result.row("broken")
    assert not broken.success and "solver exploded" in broken.message
    assert broken.n_free is None and np.isnan(broken.fit_validation["F_c"])
    assert result.ranking()[-1] == "broken"
    assert [r.structure for r in result.rows] == ["static", "broken", "lag"]
    assert any("broken: failed" in line for line in lines)


def test_validation_fit_is_the_free_run_fit_on_the_validation_data(table, runs):
    result, _ = table
    lag = result.row("lag")
    validation = runs[1]
    simulated = Lag().simulate(lag.result.parameters, validation)
    for j, output in enumerate(OUTPUTS):
        y = validation.output(output)
        expected = 100 * (1 - np.linalg.norm(y - simulated[:, j]) / np.linalg.norm(y - y.mean()))
        assert lag.fit_validation[output] == pytest.approx(expected)


def test_table_is_written_as_markdown_csv_json_and_plots(table, runs, tmp_path):
    result, _ = table
    text = result.to_markdown()
    assert text.count("\n") == 2 + len(result.rows) - 1
    assert "| lag | 3 |" in text and "failed: RuntimeError: solver exploded" in text
    with open(result.to_csv(tmp_path / "t.csv")) as handle:
        rows = list(csv.DictReader(handle))
    assert [r["structure"] for r in rows] == ["static", "broken", "lag"]
    assert float(rows[2]["fit_validation_F_c_percent"]) == pytest.approx(
        result.row("lag").fit_validation["F_c"], abs=0.05)
    data = json.loads(open(result.write_json(tmp_path / "t.json")).read())
    assert data["ranking_validation"][0] == "lag"
    assert data["rows"][1]["fit_validation"]["F_c"] is None
    assert plot_comparison(result, tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size > 10_000
    written = plot_validation(result, runs[1], tmp_path / "validation")
    assert sorted(p.name for p in written) == ["validation_lag.png", "validation_static.png"]


def test_default_structures_are_the_registered_ones_in_the_comparison():
    chosen = comparison_identifiers()
    registered = all_identifiers()
    assert {i.name for i in chosen} == {n for n, i in registered.items() if i.in_comparison}
    assert "physical-linear" in {i.name for i in chosen}
    assert "collector-head" not in {i.name for i in chosen}


def test_bad_options_are_named(runs):
    with pytest.raises(IdentificationError, match="nonexistent"):
        compare_structures(*runs, structures=comparison_identifiers(["nonexistent"]))
    with pytest.raises(IdentificationError, match="options for structures not compared"):
        compare_structures(*runs, structures=[LAG], options={"static": {}})
    assert isinstance(compare_structures(*runs, structures=[]), ComparisonTable)
