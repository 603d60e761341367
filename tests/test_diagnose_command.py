"""``panto diagnose`` as a user meets it (issue 24, "Robust command"): any file format and suffix
case reads the same numbers, HDF5 tables are found by name, the fit budget and the workers reach
the diagnosis, every failure class has its exit code, a refit that diverges is rejected with its
reason in the report, and the summary sentence agrees with the analysis it sums up.

The bad options and files themselves (one clear line, code 2 or 65) are in
``tests/test_bad_input.py``.
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import scipy.io
from scipy import signal

from panto.cli import main
from panto.identification.data.loading import LoadOptions, load_identification_data
from panto.identification.estimation.base import IdentificationData

OPTIONS = LoadOptions(inputs={"u": "u"}, outputs={"y": "y"})


def _run(seed: int, n: int = 1500, limit: float | None = None) -> IdentificationData:
    """A first-order plant ``y[k] = 0.8 y[k-1] + 0.2 u[k-1]`` driven by coloured noise, its
    input clipped at `limit` (a saturation) when given; 100 Hz, small sensor noise."""
    rng = np.random.default_rng(seed)
    u = 0.5 * signal.lfilter([1.0], [1.0, -0.9], rng.normal(size=n))
    drive = u if limit is None else np.clip(u, -limit, limit)
    y = signal.lfilter([0.0, 0.2], [1.0, -0.8], drive) + 0.005 * rng.normal(size=n)
    return IdentificationData(np.arange(n) * 0.01, u[:, None], y[:, None], ("u",), ("y",))


def _frame(data: IdentificationData) -> pd.DataFrame:
    return pd.DataFrame({"time": data.time, "u": data.inputs[:, 0], "y": data.outputs[:, 0]})


def _write_v73_mat(path, frame: pd.DataFrame) -> None:
    """A MATLAB v7.3 file: HDF5 after a 512-byte user block holding MATLAB's 128-byte header
    (text, then version 0x0200 and the endianness mark ``IM``), vectors stored N x 1."""
    import tables

    with tables.open_file(str(path), "w", user_block_size=512) as handle:
        for name in frame:
            handle.create_array("/", name, frame[name].to_numpy()[:, None])
    header = b"MATLAB 7.3 MAT-file, written by a test".ljust(116) + bytes(8) + b"\x00\x02IM"
    with open(path, "r+b") as stream:
        stream.write(header)


def _hdf5_variants(folder, frame: pd.DataFrame) -> dict[str, str]:
    """The same table in every HDF5 layout read: source -> key (None: the only table)."""
    import tables

    frame.to_hdf(folder / "fixed.H5", key="run")
    frame.to_hdf(folder / "table.hdf5", key="run", format="table")
    with tables.open_file(str(folder / "plain.h5"), "w") as handle:
        group = handle.create_group("/", "signals")
        for name in frame:
            handle.create_array(group, name, frame[name].to_numpy()[:, None])
    with tables.open_file(str(folder / "compound.h5"), "w") as handle:
        handle.create_table("/", "records", frame.to_records(index=False))
    frame.iloc[::-1].to_hdf(folder / "two.h5", key="other")
    frame.to_hdf(folder / "two.h5", key="wanted")
    return {"fixed.H5": None, "table.hdf5": None, "plain.h5": None, "compound.h5": None,
            "two.h5:wanted": None, "two.h5": "wanted"}


def test_every_format_and_suffix_case_reads_the_same_numbers(tmp_path):
    frame = _frame(_run(0, n=300))
    frame.to_csv(tmp_path / "run.csv", index=False)
    reference = load_identification_data(tmp_path / "run.csv", OPTIONS)
    frame.to_csv(tmp_path / "run.CSV", index=False)
    frame.to_parquet(tmp_path / "run.PARQUET")
    scipy.io.savemat(tmp_path / "run.MAT", {c: frame[c].to_numpy() for c in frame})
    _write_v73_mat(tmp_path / "v73.mat", frame)
    sources = {"run.CSV": None, "run.PARQUET": None, "run.MAT": None, "v73.mat": None,
               **_hdf5_variants(tmp_path, frame)}
    for source, key in sources.items():
        data = load_identification_data(str(tmp_path / source),
                                        LoadOptions(inputs={"u": "u"}, outputs={"y": "y"},
                                                    key=key))
        np.testing.assert_allclose(data.outputs, reference.outputs, rtol=0, atol=1e-12,
                                   err_msg=source)
        np.testing.assert_allclose(data.inputs, reference.inputs, rtol=0, atol=1e-12)
        assert data.sample_period == pytest.approx(reference.sample_period, rel=1e-9), source


def test_a_key_is_refused_for_a_file_that_holds_one_table(tmp_path):
    _frame(_run(0, n=50)).to_csv(tmp_path / "run.csv", index=False)
    with pytest.raises(ValueError, match=r"run\.csv: --key 'x': only an HDF5 file"):
        load_identification_data(tmp_path / "run.csv", LoadOptions(
            inputs={"u": "u"}, outputs={"y": "y"}, key="x"))


def test_two_tables_of_one_hdf5_file_train_and_validate_from_the_command_line(tmp_path):
    """End to end: ``FILE.h5:KEY`` for each run, one worker, a small fit budget; the clean
    first-order plant is within the noise of ``linear-2``; the JSON summary is written."""
    path = tmp_path / "runs.h5"
    _frame(_run(0, n=600)).to_hdf(path, key="train")
    _frame(_run(1, n=600)).to_hdf(path, key="validation")
    out = tmp_path / "diagnosis.json"
    code = main(["diagnose", "--train", f"{path}:train", "--validate", f"{path}:validation",
                 "--model", "linear-2", "--inputs", "u=u", "--outputs", "y=y", "--workers", "1",
                 "--max-evaluations", "60", "--candidates", "offset", "saturation",
                 "--max-effects", "1", "--json", str(out), "-q"])
    assert code == 0
    document = json.loads(out.read_text())
    assert document["verdict"] == "none"
    assert document["fit_before"]["y"] > 95.0


@pytest.fixture
def recorded(monkeypatch):
    """``diagnose`` replaced by a recorder that ends as the test says (its options kept)."""
    import panto.identification.diagnosis.pipeline as pipeline

    calls: dict = {}

    def fake(train, validation, *, structure, structure_options, options, progress):
        calls.update(options=options, structure_options=structure_options)
        raise calls["raise"]

    monkeypatch.setattr(pipeline, "diagnose", fake)
    return calls


def _command(folder) -> list[str]:
    for name, seed in (("train", 0), ("validation", 1)):
        _frame(_run(seed, n=200)).to_csv(folder / f"{name}.csv", index=False)
    return ["diagnose", "--train", str(folder / "train.csv"), "--validate",
            str(folder / "validation.csv"), "--model", "linear-2", "--inputs", "u=u",
            "--outputs", "y=y", "-q"]


@pytest.mark.parametrize("raised, code", [(KeyboardInterrupt(), 4), (KeyError("bug"), 3),
                                          (ValueError("bad data"), 65)],
                         ids=["aborted-4", "internal-3", "bad-input-65"])
def test_caps_and_options_reach_the_diagnosis_and_each_failure_has_its_code(
        tmp_path, recorded, capsys, raised, code):
    recorded["raise"] = raised
    argv = _command(tmp_path) + ["--max-evaluations", "37", "--workers", "1", "--option",
                                 "centre=false", "input_delay=2", "--roles", "position=y"]
    assert main(argv) == code
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "Traceback" not in error[0]
    options = recorded["options"]
    assert (options.max_evaluations, options.workers) == (37, 1)
    assert recorded["structure_options"] == {"centre": False, "input_delay": 2}
    assert options.roles.position == "y" and options.roles.force is None


def test_a_usage_error_is_code_2_before_any_work(tmp_path, recorded, capsys):
    recorded["raise"] = AssertionError("the diagnosis must not start")
    assert main(_command(tmp_path) + ["--workers", "-1"]) == 2
    assert "--workers" in capsys.readouterr().err and "options" not in recorded


def test_without_caps_the_diagnosis_keeps_its_defaults(tmp_path, recorded):
    from panto.identification.diagnosis.pipeline import DiagnosisOptions

    recorded["raise"] = ValueError("stop")
    main(_command(tmp_path))
    defaults = DiagnosisOptions()
    assert recorded["options"].max_evaluations == defaults.max_evaluations
    assert recorded["options"].workers == defaults.workers


def _diagnose_saturation(**options):
    from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose

    return diagnose(_run(0, limit=0.5), _run(1, limit=0.5), structure="linear-2",
                    options=DiagnosisOptions(candidates=("saturation",), max_effects=1,
                                             discovery=False, adequacy=False, workers=1))


def test_a_refit_that_diverges_is_rejected_with_its_reason_in_the_report(monkeypatch):
    """The saturation the plant has is found (control); when the refitted model's free run on
    the validation run diverges (forced: NaN from 3 s on), the candidate is rejected, the reason
    is in the trial and in report.md, and the verdict names no effect."""
    import panto.identification.diagnosis.refit as refit
    from panto.identification.diagnosis.augmentations import AugmentedStructure
    from panto.identification.diagnosis.report import markdown_report

    control = _diagnose_saturation()
    assert control.verdict == "effect" and control.effects == ("saturation",)

    honest = refit.simulate

    def diverging(model, data):
        y = np.array(honest(model, data), float)
        if isinstance(model.structure, AugmentedStructure):
            y[data.time >= 3.0] = np.nan
        return y

    monkeypatch.setattr(refit, "simulate", diverging)
    result = _diagnose_saturation()
    tried = result.rounds[0]["tried"]
    assert [t["effect"] for t in tried] == ["saturation"] and not tried[0]["accepted"]
    assert "diverges" in tried[0]["message"] and "t = 3 s" in tried[0]["message"]
    assert result.verdict == "unexplained" and result.effects == ()
    assert "saturation" not in result.summary.split(";")[0]
    text = markdown_report(result, [])
    assert "Candidates rejected" in text and "free run diverges" in text


GAP = {"significant": True, "reasons": ["y residual correlates with u"], "below_relevance": []}
NO_GAP = {"significant": False, "reasons": [], "below_relevance": []}
SMALL_GAP = {"significant": False, "reasons": [],
             "below_relevance": ["y residual correlates with u at lag 3"]}
WHERE = {"text": "in y (fit 80.0 %), 60 % of its residual power in 1-2 Hz"}


@pytest.mark.parametrize("verdict, effects, gap, remaining, where", [
    ("none", (), NO_GAP, NO_GAP, WHERE),
    ("none", (), SMALL_GAP, SMALL_GAP, WHERE),
    ("unexplained", (), GAP, GAP, WHERE),
    ("unexplained", (), GAP, GAP, {"text": ""}),
    ("effect", ("saturation",), GAP, NO_GAP, WHERE),
    ("effect", ("saturation", "extra_mode"), GAP, GAP, WHERE),
    ("effect", ("saturation",), NO_GAP, NO_GAP, WHERE),
    ("effect", ("extra_mode",), SMALL_GAP, SMALL_GAP, WHERE),
], ids=["none", "none-flag-below-floor", "unexplained", "unexplained-nowhere", "effect",
        "effect-gap-remains", "effect-unflagged", "effect-small-flag"])
def test_the_summary_never_contradicts_the_verdict(verdict, effects, gap, remaining, where):
    """'Within the noise' only for ``none``; effect names only for ``effect``; a test flag is
    not denied; an unflagged gap that an effect closes is said to be so; nothing dangles."""
    from panto.identification.diagnosis.pipeline import _summary
    from panto.identification.diagnosis.report import gap_sentence

    before, after = {"y": 80.0}, {"y": 95.0 if effects else 80.0}
    text = _summary(verdict, effects, before, after, where, remaining, gap)
    assert ("within the noise" in text) == (verdict == "none")
    assert any(e in text for e in ("saturation", "extra_mode")) == (verdict == "effect")
    assert ("no candidate closes" in text) == (verdict == "unexplained")
    assert ("a significant gap remains" in text) == (verdict == "effect"
                                                     and remaining["significant"])
    if gap["below_relevance"] and verdict == "none":
        assert gap["below_relevance"][0] in text and "independent of the inputs" not in text
    if verdict == "effect" and not gap["significant"]:
        assert "had not flagged" in text
    assert not text.rstrip().endswith(("lies", ":", ";", ","))
    sentence = gap_sentence(gap, effects)
    assert ("within the noise" in sentence) == (not gap["significant"])
    assert ("yet adding" in sentence) == (bool(effects) and not gap["significant"])
