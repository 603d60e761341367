"""The benchmark of the diagnosis' nominal fit on the families' clean cases
(benchmarks/global_fit_families.py): its cases come from the split asked for, and on a two-mass
clean case the diagnosis' nominal fit reaches the optimum of the fit started at the plant's
true parameters (a known optimum, from a plant written apart from the fitted structure)."""
from __future__ import annotations

from fixtures.excitations import load_benchmark


def test_cases_alternate_the_families_within_the_split_asked_for():
    bench, families = load_benchmark("global_fit_families"), load_benchmark("diagnosis_families")
    for split in ("tune", "heldout"):
        chosen = bench.cases(split, 6)
        assert [f for f, _ in chosen] == ["two-mass", "three-mass"] * 3
        assert all(families.split_of(f, s) == split for f, s in chosen)
        assert len({s for _, s in chosen}) == 6
    assert min(s for _, s in bench.cases("heldout", 6)) >= bench.HELDOUT_START


def test_the_diagnosis_nominal_reaches_the_truth_started_optimum_on_a_two_mass_clean_case():
    row = load_benchmark("global_fit_families").run_case("two-mass", 3)
    assert row["cost"] <= row["reference_cost"] * 1.001, row


def test_skip_leaves_out_the_first_cases_of_the_split():
    bench = load_benchmark("global_fit_families")
    assert bench.cases("heldout", 4, skip=2) == bench.cases("heldout", 6)[2:]
