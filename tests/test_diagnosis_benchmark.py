"""The diagnosis benchmark's machinery: the draw, the cost of a hidden effect measured against its
effect-free twin (checked against the analytic cost of a force offset), the scores and confusion
matrix, blindness (the diagnosis never receives the runs' truth metadata) and the files."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from panto.identification.diagnosis import pipeline as diagnosis_module
from panto.identification.diagnosis.pipeline import DiagnosisOptions
from panto.identification.diagnosis.benchmark import (LIBRARY_DRAW, OUTSIDE_DRAW, STRONG, BenchmarkCase,
                                                BenchmarkResult, CaseOutcome, confusion_matrix,
                                                draw_cases, gap_closed, run_case, score_outcomes)
from panto.identification.diagnosis.benchmark_report import write_benchmark


def _holds_truth(value) -> bool:
    """Whether any mapping inside `value` carries a non-empty ``truth`` or the imperfections."""
    if isinstance(value, dict):
        if value.get("truth") or "imperfections" in value or "pantograph_parameters" in value:
            return True
        return any(_holds_truth(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return any(_holds_truth(v) for v in value)
    return False


def test_the_draw_is_stratified_reproducible_and_uses_different_runs():
    cases = draw_cases(20, 3)
    assert cases == draw_cases(20, 3) and cases != draw_cases(20, 4)
    kinds = [c.kind for c in cases]
    assert kinds.count("library") == 12 and kinds.count("none") == 4 \
        and kinds.count("outside") == 4
    assert {c.label for c in cases if c.kind == "library"} == set(LIBRARY_DRAW)
    assert {c.label for c in cases if c.kind == "outside"} <= set(OUTSIDE_DRAW)
    assert all(c.train_seed != c.validation_seed for c in cases)
    assert all(c.settings == {} for c in cases if c.label == "none")
    with pytest.raises(ValueError, match="cases"):
        draw_cases(0, 1)


def _outcome(label: str, kind: str, predicted: str, cost: float, closed: float = math.nan):
    case = BenchmarkCase(0, kind, label, 1.0, {}, 1, 2)
    verdict = predicted if predicted in ("none", "unexplained") else "effect"
    return CaseOutcome(case, verdict, () if verdict != "effect" else (predicted,), predicted,
                       cost, {}, {}, {}, closed, 0.0)


def test_scores_count_only_strong_effects_and_name_false_alarms():
    outcomes = [_outcome("offset", "library", "offset", 20.0, 0.9),
                _outcome("offset", "library", "input_delay", 12.0),
                _outcome("coulomb_friction", "library", "none", STRONG / 2),  # too weak to count
                _outcome("none", "none", "none", 0.0), _outcome("none", "none", "offset", 0.0),
                _outcome("none", "none", "unexplained", 0.0),
                _outcome("hysteresis", "outside", "unexplained", 9.0),
                _outcome("gain_drift", "outside", "offset", 9.0)]
    scores = score_outcomes(outcomes)
    assert scores["strong_cases"] == 2 and scores["top1_accuracy"] == pytest.approx(0.5)
    assert scores["top1_accuracy_all_library"] == pytest.approx(1 / 3)
    assert scores["false_alarm_rate"] == pytest.approx(1 / 3)
    assert scores["none_unexplained_rate"] == pytest.approx(1 / 3)
    assert scores["unexplained_rate_outside"] == pytest.approx(0.5)
    assert scores["gap_closed_median"] == pytest.approx(0.9)
    matrix = confusion_matrix(outcomes)
    assert matrix["offset"] == {"offset": 1, "input_delay": 1}
    assert sum(matrix["none"].values()) == 3


def test_gap_closed_is_the_share_of_the_gap_to_the_clean_nominal_removed():
    # Before: F_c residual energy 0.2^2 + 0.1^2 = 0.05; the clean nominal leaves 0.1^2 = 0.01;
    # an augmented model at 90 % leaves 0.01 too: all of the 0.04 gap removed.
    before = {"F_c": 100 * (1 - math.sqrt(0.05)), "y_cb": 95.0}
    after = {"F_c": 90.0, "y_cb": 95.0}
    clean = {"F_c": 90.0, "y_cb": 95.0}
    assert gap_closed(before, after, clean) == pytest.approx(1.0)
    assert gap_closed(before, before, clean) == pytest.approx(0.0)
    halfway = {"F_c": 100 * (1 - math.sqrt(0.03)), "y_cb": 95.0}
    assert gap_closed(before, halfway, clean) == pytest.approx(0.5)
    assert math.isnan(gap_closed(before, after, before))  # no gap to close


@pytest.fixture(scope="module")
def offset_outcome(tmp_path_factory):
    """A hidden force offset, diagnosed blind (the diagnosis is wrapped to check its inputs)."""
    seen = []
    real = diagnosis_module.diagnose

    def spy(train, validation, **options):
        seen.append((train.metadata, validation.metadata))
        return real(train, validation, **options)

    diagnosis_module.diagnose = spy
    try:
        case = BenchmarkCase(0, "library", "offset", 8.0, {"force_offset": 8.0}, 11, 12)
        outcome = run_case(case, duration=6.0, folder=str(tmp_path_factory.mktemp("bench")),
                           diagnose_options=DiagnosisOptions(candidates=("offset",), max_effects=1,
                                                          max_evaluations=60))
    finally:
        diagnosis_module.diagnose = real
    return outcome, seen


def test_the_diagnosis_never_receives_the_truth(offset_outcome):
    outcome, seen = offset_outcome
    assert len(seen) == 1 and not outcome.error
    for train_metadata, validation_metadata in seen:
        assert "dataset" in train_metadata  # the recording's metadata is there ...
        assert not _holds_truth(dict(train_metadata)) and not _holds_truth(
            dict(validation_metadata))  # ... without what generated it


def test_the_cost_of_an_offset_matches_its_analytic_value(offset_outcome):
    outcome, _ = offset_outcome
    # An offset c on F_c: fit(y + c, y) = 100 (1 - |c| sqrt(N) / ||F - mean F||); the lasers
    # are untouched by a force offset.
    assert outcome.fit_effect["y_cb"] == pytest.approx(100.0)
    analytic = 100.0 * 8.0 / outcome.spread["F_c"]
    assert outcome.signal_cost == pytest.approx(analytic, rel=0.02)
    # What it costs the model is the drop from the nominal fitted without the effect, never
    # more than the signal itself costs (the nominal's preload absorbs part of an offset).
    drop = max(outcome.fit_clean[o] - outcome.fit_before[o] for o in outcome.fit_clean)
    assert outcome.cost == pytest.approx(max(drop, 0.0))
    assert outcome.cost <= outcome.signal_cost + 1.0
    # The outcome is scored from the diagnosis' own fits (whatever it answered).
    assert outcome.predicted == (outcome.effects[0] if outcome.verdict == "effect"
                                 else outcome.verdict)
    expected = gap_closed(outcome.fit_before, outcome.fit_after, outcome.fit_clean)
    assert outcome.gap_closed == pytest.approx(expected, nan_ok=True)
    if outcome.verdict != "effect" and math.isfinite(outcome.gap_closed):
        assert outcome.gap_closed == pytest.approx(0.0)


def test_the_files_are_written(offset_outcome, tmp_path):
    outcome, _ = offset_outcome
    result = BenchmarkResult((outcome,), score_outcomes([outcome]), confusion_matrix([outcome]),
                             {"cases": 1, "seed": 0, "duration_s": 8.0,
                              "structure": "physical-linear", "strong_fit_points": STRONG})
    paths = write_benchmark(result, tmp_path / "bench.json")
    data = json.loads(paths["json"].read_text())
    assert data["confusion"] == {"offset": {outcome.predicted: 1}}
    assert data["cases"][0]["case"]["label"] == "offset"
    assert "| offset |" in paths["markdown"].read_text()
    assert paths["png"].read_bytes()[:4] == b"\x89PNG"
