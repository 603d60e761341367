"""The shared pieces of identification: the data container, the fit metric, the registry."""
import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationData, IdentificationError, fit_percent
from panto.identification.structures.registry import identifier


def _data(n=100, **changes):
    t = np.arange(n) * 0.02
    values = dict(time=t, inputs=np.c_[np.sin(t), np.cos(t)], outputs=np.c_[t, t ** 2],
                  input_names=("eta", "p"), output_names=("F_c", "y_cb"), source="test.csv")
    values.update(changes)
    return IdentificationData(**values)


def test_fit_is_100_for_a_perfect_model_0_for_the_mean_and_negative_when_worse():
    rng = np.random.default_rng(0)
    y = rng.normal(size=500)
    assert fit_percent(y, y) == pytest.approx(100.0)
    assert fit_percent(y, np.full_like(y, y.mean())) == pytest.approx(0.0)
    assert fit_percent(y, -y) < 0.0


def test_fit_matches_its_definition_per_output_and_skips_missing_samples():
    rng = np.random.default_rng(1)
    y = rng.normal(size=(300, 2))
    y_hat = y + 0.1 * rng.normal(size=y.shape)
    y[5, 1] = np.nan
    fits = fit_percent(y, y_hat)
    ok = np.isfinite(y[:, 1])
    expected = 100 * (1 - np.linalg.norm(y[ok, 1] - y_hat[ok, 1]) / np.linalg.norm(y[ok, 1] - y[ok, 1].mean()))
    assert fits[1] == pytest.approx(expected)
    assert fits[0] == pytest.approx(fit_percent(y[:, 0], y_hat[:, 0]))


def test_data_knows_its_period_columns_and_segments():
    data = _data()
    assert data.sample_period == pytest.approx(0.02)
    assert np.array_equal(data.output("y_cb"), data.outputs[:, 1])
    part = data.segment(0.5, 1.0)
    assert part.time[0] >= 0.5 and part.time[-1] < 1.0 and len(part) == 25
    assert data.select_outputs(["y_cb"]).output_names == ("y_cb",)


@pytest.mark.parametrize("change, message", [
    (dict(time=np.r_[0.0, 0.02, 0.05, np.arange(3, 100) * 0.02]), "uniformly"),
    (dict(input_names=("eta",)), "input and"),
    (dict(inputs=np.c_[np.r_[np.nan, np.zeros(99)], np.zeros(100)]), "input 'eta' holds NaN"),
], ids=["non-uniform time", "wrong names", "NaN input"])
def test_bad_data_is_refused_with_the_source_named(change, message):
    with pytest.raises(IdentificationError, match=message) as error:
        _data(**change)
    assert "test.csv" in str(error.value)


def test_unknown_structure_lists_the_known_ones():
    with pytest.raises(IdentificationError, match="unknown model structure 'no-such'"):
        identifier("no-such")
