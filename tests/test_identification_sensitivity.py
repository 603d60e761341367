"""Eigenvalue sensitivity of the linearised pantograph (panto.identification.structures.sensitivity, thesis Fig. 4.9)."""
import json

import numpy as np
import pytest

from panto.fmu_src.models import default_parameters
from panto.identification.structures.plots import plot_eigenvalue_sensitivity
from panto.identification.structures.sensitivity import (TABLE_4_1, eigenvalue_sensitivity, linearised_eigenvalues,
                                        match_modes, elastic_rod_modes)

MASSES = ("m1", "m2", "m3", "m4", "m_c")
DAMPERS = ("c1", "c2", "c3", "c_c")
STIFFNESSES = ("k", "k_c", "k_ph")
UNDAMPED = {name: 0.0 for name in DAMPERS}


@pytest.fixture(scope="module")
def defaults():
    params = default_parameters("Pantograph")
    return dict(zip(params.names, params.vector().tolist()))


@pytest.fixture(scope="module")
def table_4_1():
    return eigenvalue_sensitivity()


def test_a_zero_valued_parameter_leaves_the_eigenvalues_unchanged():
    # k_c3 (cubic head-suspension stiffening) is 0 in Table 4.1: 0.9 * 0 = 1.1 * 0 = 0.
    result = eigenvalue_sensitivity(names=("k_c3", "m_c"))
    zero = result.shift("k_c3")
    assert zero.relative_shift == 0.0 and zero.message == ""
    assert np.array_equal(zero.eigenvalues[0], result.nominal)
    assert result.shift("m_c").relative_shift > 0.01
    assert result.ranking == ["m_c", "k_c3"]


def test_scaling_every_mass_by_s_divides_the_eigenvalues_by_sqrt_s(defaults):
    # M -> s M with the weights m g unchanged (g -> g / s) and C -> sqrt(s) C keeps the
    # equilibrium and K; then s M (lambda/sqrt(s))^2 + sqrt(s) C lambda/sqrt(s) + K = 0 exactly.
    s = 1.7
    scaled = {name: defaults[name] * s for name in MASSES}
    scaled.update({name: defaults[name] * np.sqrt(s) for name in DAMPERS})
    scaled["g"] = defaults["g"] / s
    nominal = linearised_eigenvalues(None, 2.0, 4.0)
    changed = match_modes(nominal, linearised_eigenvalues(scaled, 2.0, 4.0))
    assert changed == pytest.approx(nominal / np.sqrt(s), rel=1e-9)


def test_undamped_model_is_conservative_and_follows_rayleigh_monotonicity():
    # Without dampers the linearised eigenvalues lie on the imaginary axis; a stiffer spring
    # raises and a heavier body lowers every natural frequency (Rayleigh quotient).
    result = eigenvalue_sensitivity(UNDAMPED, names=MASSES + STIFFNESSES, factors=(0.9, 1.1))
    scale = np.abs(result.nominal).max()
    assert np.abs(result.nominal.real).max() < 1e-9 * scale
    nominal = np.abs(result.nominal)
    for shift in result.shifts:
        assert np.abs(shift.eigenvalues.real).max() < 1e-9 * scale, shift.name
        lower, higher = np.abs(shift.eigenvalues)
        sign = 1.0 if shift.name in STIFFNESSES else -1.0
        assert np.all(sign * (higher - nominal) >= -1e-9 * scale), shift.name
        assert np.all(sign * (lower - nominal) <= 1e-9 * scale), shift.name


def test_head_parameters_are_among_the_most_influential_as_in_the_thesis(table_4_1):
    # Thesis section 4.5: m_c and k_ph have the strongest influence; the pressure gain k_p only
    # moves the equilibrium, the light rods m2, m3 hardly matter.
    top = table_4_1.ranking[:4]
    assert "m_c" in top and "k_ph" in top
    assert set(table_4_1.ranking[-4:]) & {"k_p", "m3", "m2"}
    assert len(table_4_1.shifts) == len(TABLE_4_1) == 13
    # Thesis: robust to +-10 %: no eigenvalue moves by more than ~10 %.
    assert max(s.relative_shift for s in table_4_1.shifts) < 0.1


def test_m4_leads_only_through_the_rod_mode_and_m_c_k_ph_lead_the_others_as_in_the_thesis(
        table_4_1, defaults):
    # Fig. 4.9 (docs/thesis.md): the rod-elastic mode (spring k on delta) becomes infinitely fast
    # as the rod is made rigid, omega ~ sqrt(k): k x100 -> x10, k x10^4 -> x100 (asymptotically).
    rod = elastic_rod_modes()
    assert len(rod) == 2 and table_4_1.nominal[rod[0]] == pytest.approx(
        np.conj(table_4_1.nominal[rod[1]]))
    stiff = {f: np.abs(match_modes(table_4_1.nominal, linearised_eigenvalues(
        {"k": defaults["k"] * f}, 2.0, 4.0))[rod[0]]) for f in (100.0, 1e4)}
    assert stiff[1e4] / stiff[100.0] == pytest.approx(10.0, rel=0.02)
    # m4 heads the all-mode ranking because it heads the rod mode's ranking; without the rod
    # mode the collector-head mass and the contact stiffness lead, as the thesis says.
    others = [i for i in range(len(table_4_1.nominal)) if i not in rod]
    assert table_4_1.ranking[0] == table_4_1.ranking_over(rod)[0] == "m4"
    assert set(table_4_1.ranking_over(others)[:2]) == {"m_c", "k_ph"}


def test_identified_parameters_are_varied_about_and_results_are_written(tmp_path, defaults):
    stiffer = eigenvalue_sensitivity({"k_ph": 50000.0}, names=("k_ph", "m_c"))
    assert stiffer.parameters["k_ph"] == 50000.0
    assert stiffer.natural_frequencies_hz.max() > eigenvalue_sensitivity(
        names=("m_c",)).natural_frequencies_hz.max()
    data = json.loads(open(stiffer.write_json(tmp_path / "s.json")).read())
    assert data["ranking"] == stiffer.ranking and data["eta"] == 2.0
    assert "| 1 |" in stiffer.to_markdown()
    plot_eigenvalue_sensitivity(stiffer, tmp_path / "s.png")
    assert (tmp_path / "s.png").stat().st_size > 10_000


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="'mass'"):
        eigenvalue_sensitivity(names=("mass",))
    with pytest.raises(ValueError, match="factors"):
        eigenvalue_sensitivity(names=("m_c",), factors=(0.0,))


def test_panto_sensitivity_command_writes_the_ranking(tmp_path, capsys):
    from panto.fmu_src.models import default_parameters
    from panto.cli import main

    parameters = default_parameters("Pantograph").with_values({"k_ph": 50000.0})
    path = parameters.save(tmp_path / "identified.json")
    code = main(["sensitivity", "--parameters", str(path), "--names", "k_c3", "m_c", "k_ph",
                 "--json", str(tmp_path / "s.json"), "--out", str(tmp_path / "s.png")])
    assert code == 0
    data = json.loads((tmp_path / "s.json").read_text())
    assert data["ranking"][-1] == "k_c3"
    assert data["parameters"]["k_ph"]["value"] == 50000.0
    assert "| 1 |" in capsys.readouterr().out and (tmp_path / "s.png").exists()
