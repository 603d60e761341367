"""Issue 21's bad-input catalogue: every command that reads user data or numeric options, fed a
malformed file or option, exits with the code of its class (2: usage, an option's value out of
its range found by the parser; 65: bad input data, found on reading) and one line on standard
error that names the culprit (the file, the column or row, the option, the value or the allowed
range), never a traceback; a refused ``rig run`` leaves no run folder behind.

The commands run in-process (``panto.cli.main``), each refused before any real work.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from panto.cli import main
from panto.fmu_src.models import default_parameters
from panto.rig.dataset import Dataset, RunMetadata

PROFILE = str(Path(__file__).resolve().parent.parent / "rig" / "profiles" / "sine_1hz.json")
IO = ["--inputs", "eta=height", "p=pressure", "--outputs", "F_c=force"]


def _plain_tables(folder: Path) -> None:
    """A good plain table and its spoiled copies (header only, text, NaN, inf, time order)."""
    t = np.arange(400) / 100.0
    good = pd.DataFrame({"time": t, "height": 2.0 + 0.01 * np.sin(3 * t),
                         "pressure": 4.0 + 0.1 * np.sin(t), "force": 100.0 + 5 * np.sin(3 * t),
                         "bar": 1.9 + 0.01 * np.sin(3 * t)})
    good.to_csv(folder / "good.csv", index=False)
    good.iloc[:0].to_csv(folder / "header.csv", index=False)
    text = good.astype(object)
    text.loc[5, "force"] = "abc"
    text.to_csv(folder / "text.csv", index=False)
    for name, column, value in (("nan", "force", np.nan), ("inf", "force", np.inf),
                                ("backwards", "time", 0.03), ("repeated", "time", 0.04)):
        spoiled = good.copy()
        spoiled.loc[5, column] = value
        spoiled.to_csv(folder / f"{name}.csv", index=False)
    good.to_parquet(folder / "parquet.csv")  # a Parquet file under a .csv name
    spoiled = good.copy()
    spoiled.loc[5, "force"] = 1e300
    spoiled.to_csv(folder / "huge.csv", index=False)
    spoiled = good.copy()  # a force held constant, varying only by rounding
    spoiled["force"] = 100.0 + 1e-12 * np.sin(3 * t)
    spoiled.to_csv(folder / "constant.csv", index=False)
    for key in ("a", "b"):  # an HDF5 file with two tables: which one is not guessed
        good.to_hdf(folder / "two.h5", key=key)


def _rig_datasets(folder: Path) -> None:
    """A dataset of the product (CSV + side file) and spoiled copies with the same side file."""
    t = np.arange(1000) / 500.0
    Dataset(t, {"force": 100.0 + np.sin(t), "height": 2.0 + 0.01 * np.sin(t)},
            {"force": "N", "height": "m"},
            RunMetadata(sample_rate=500.0, source="emulator")).write(folder / "run.csv")
    lines = (folder / "run.csv").read_text().splitlines(keepends=True)
    text, backwards = list(lines), list(lines)
    text[6] = text[6].replace(text[6].split(",")[1], "abc")
    backwards[6] = backwards[4]
    huge = list(lines)
    huge[6] = huge[6].replace(huge[6].split(",")[1], "1e300")
    for name, body in (("r_header", lines[:1]), ("r_text", text), ("r_backwards", backwards),
                       ("r_huge", huge), ("r_rate", lines)):
        (folder / f"{name}.csv").write_text("".join(body))
        shutil.copy(folder / "run.csv.json", folder / f"{name}.csv.json")
    side = json.loads((folder / "r_rate.csv.json").read_text())  # 100 Hz over a 500 Hz time column
    side["metadata"]["sample_rate"] = 100.0
    (folder / "r_rate.csv.json").write_text(json.dumps(side))


def _profiles(folder: Path) -> None:
    """The sine profile with its sine, or a chirp, above the 250 Hz Nyquist frequency."""
    profile = json.loads(Path(PROFILE).read_text())
    profile["motor"]["signals"] = [{"kind": "sine", "frequency": 300.0, "amplitude": 0.01}]
    (folder / "fast_sine.json").write_text(json.dumps(profile))
    profile["motor"]["signals"] = [{"kind": "chirp", "f_start": 1.0, "f_stop": 260.0,
                                    "duration": 10.0, "amplitude": 0.01}]
    (folder / "fast_chirp.json").write_text(json.dumps(profile))


def _parameter_files(folder: Path) -> None:
    """Pantograph parameter files: m_c in pounds (refused) and in grams (converted)."""
    document = default_parameters("Pantograph").to_dict()
    (folder / "pantograph.json").write_text(json.dumps(document))
    for name, value, unit in (("in_lb", 15.0, "lb"), ("in_g", 7000.0, "g")):
        document["parameters"]["m_c"].update(value=value, unit=unit)
        (folder / f"{name}.json").write_text(json.dumps(document))
    document["parameters"]["m_c"].update(value=7.0, unit="kg")
    (folder / "in_kg.json").write_text(json.dumps(document))


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    """The malformed inputs of the catalogue, made once."""
    folder = tmp_path_factory.mktemp("bad_input")
    _plain_tables(folder)
    _rig_datasets(folder)
    _parameter_files(folder)
    _profiles(folder)
    (folder / "bogus.fmu").write_text("not a zip archive")
    (folder / "a_file").write_text("an output folder cannot be made under a file")
    (folder / "imperfections.json").write_text('{"bar_mass": 0.5, "gremlins": 1}')
    (folder / "camera.json").write_text("{}")
    return folder


#: (id, command line with {f} for the files' folder, fragments the one error line must hold)
CASES = [
    # rig check: the product's datasets
    ("check-header-only", "rig check {f}/r_header.csv --any-channels", ["r_header.csv", "no data rows"]),
    ("check-text-cell", "rig check {f}/r_text.csv --any-channels", ["r_text.csv", "'force'", "row 6", "'abc'"]),
    ("check-backwards-time", "rig check {f}/r_backwards.csv --any-channels", ["r_backwards.csv", "not strictly increasing", "row 5"]),
    ("check-parquet-named-csv", "rig check {f}/parquet.csv", ["parquet.csv", "Parquet"]),
    ("check-missing", "rig check {f}/nowhere", ["nowhere", "no such file or run folder"]),
    ("check-huge-value", "rig check {f}/r_huge.csv --any-channels", ["r_huge.csv", "'force'", "1e+300", "row 5", "plausible range", "1e+12"]),
    ("check-side-file-rate", "rig check {f}/r_rate.csv --any-channels", ["r_rate.csv", "r_rate.csv.json", "100 Hz", "500 Hz"]),
    # rig profile
    ("profile-sine-above-nyquist", "rig profile {f}/fast_sine.json --out {f}/preview", ["fast_sine.json", "frequency = 300", "Nyquist", "250 Hz"]),
    ("profile-chirp-above-nyquist", "rig profile {f}/fast_chirp.json --out {f}/preview", ["fast_chirp.json", "f_stop = 260", "Nyquist", "250 Hz"]),
    # preprocess
    ("preprocess-header-only", "preprocess {f}/r_header.csv --out {f}/o.csv", ["r_header.csv", "no data rows"]),
    ("preprocess-parquet-named-csv", "preprocess {f}/parquet.csv --out {f}/o.csv", ["parquet.csv", "Parquet"]),
    ("preprocess-rate-0", "preprocess {f}/run.csv --rate 0 --out {f}/o.csv", ["--rate", "0", "> 0"]),
    ("preprocess-rate-negative", "preprocess {f}/run.csv --rate -5 --out {f}/o.csv", ["--rate", "-5", "> 0"]),
    ("preprocess-unwritable-out", "preprocess {f}/run.csv --out {f}/a_file/o.csv", ["--out", "a_file", "not a folder"]),
    # identify on plain tables
    ("identify-header-only", "identify {f}/header.csv --model two-mass {io}", ["header.csv", "no data rows"]),
    ("identify-text-cell", "identify {f}/text.csv --model two-mass {io}", ["text.csv", "'force'", "line 7", "'abc'"]),
    ("identify-nan", "identify {f}/nan.csv --model two-mass {io}", ["nan.csv", "'force'", "nan", "row 5"]),
    ("identify-inf", "identify {f}/inf.csv --model two-mass {io}", ["inf.csv", "'force'", "inf", "row 5"]),
    ("identify-huge-value", "identify {f}/huge.csv --model two-mass {io}", ["huge.csv", "'force'", "1e+300", "row 5", "plausible range", "1e+12"]),
    ("identify-constant-force", "identify {f}/constant.csv --model two-mass {io}", ["constant.csv", "'F_c'", "'force'", "constant", "nothing to fit"]),
    ("identify-dataset-side-file-rate", "identify {f}/r_rate.csv --model two-mass {io}", ["r_rate.csv", "r_rate.csv.json", "100 Hz", "500 Hz"]),
    ("identify-backwards-time", "identify {f}/backwards.csv --model two-mass {io}", ["backwards.csv", "not strictly increasing", "0.03"]),
    ("identify-repeated-time", "identify {f}/repeated.csv --model two-mass {io}", ["repeated.csv", "not strictly increasing", "0.04 s then 0.04 s"]),
    ("identify-parquet-named-csv", "identify {f}/parquet.csv --model two-mass {io}", ["parquet.csv", "Parquet"]),
    ("identify-missing", "identify {f}/nowhere.csv --model two-mass {io}", ["nowhere.csv", "no such file"]),
    ("identify-dataset-text-cell", "identify {f}/r_text.csv --model two-mass {io}", ["r_text.csv", "'force'", "'abc'"]),
    ("identify-rate-0", "identify {f}/good.csv --model two-mass {io} --rate 0", ["--rate", "> 0"]),
    ("identify-max-evaluations-0", "identify {f}/good.csv --model two-mass {io} --max-evaluations 0", ["--max-evaluations", "0", ">= 1"]),
    ("identify-multistart-negative", "identify {f}/good.csv --model two-mass {io} --multistart -1", ["--multistart", "-1", ">= 0"]),
    ("identify-train-samples-reversed", "identify {f}/good.csv --model two-mass {io} --train-samples 5:2", ["--train-samples", "'5:2'", "no rows"]),
    ("identify-train-samples-outside", "identify {f}/good.csv --model two-mass {io} --train-samples 5000:6000", ["good.csv", "5000:6000", "0 of 400"]),
    ("identify-unwritable-out", "identify {f}/good.csv --model two-mass {io} --out {f}/a_file/fit", ["--out", "a_file"]),
    # compare
    ("compare-rate-0", "compare {f}/good.csv {f}/good.csv {io} --rate 0", ["--rate", "> 0"]),
    ("compare-text-cell", "compare {f}/text.csv {f}/good.csv {io}", ["text.csv", "'force'", "'abc'"]),
    # diagnose
    ("diagnose-nan", "diagnose --train {f}/nan.csv --validate {f}/good.csv --model two-mass {io}", ["nan.csv", "'force'"]),
    ("diagnose-constant-force", "diagnose --train {f}/good.csv --validate {f}/constant.csv --model two-mass {io}", ["constant.csv", "'F_c'", "nothing to fit"]),
    ("diagnose-repeated-time", "diagnose --train {f}/good.csv --validate {f}/repeated.csv --model two-mass {io}", ["repeated.csv", "not strictly increasing"]),
    ("diagnose-unknown-option", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --option foo=bar", ["--option", "'foo'", "two-mass"]),
    ("diagnose-folds-0", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --folds 0", ["--folds", ">= 1"]),
    ("diagnose-sample-rate-negative", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --sample-rate -5", ["--sample-rate", "-5"]),
    ("diagnose-option-not-a-name", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --option substeps=abc", ["--option", "substeps=abc", "'two-mass'", "an integer"]),
    ("diagnose-option-out-of-range", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --option substeps=0", ["--option", "substeps=0", "at least 1"]),
    ("diagnose-option-not-a-bool", "diagnose --train {f}/good.csv --validate {f}/good.csv --model linear-2 --inputs u=height --outputs y=force --option centre=maybe", ["--option", "centre=maybe", "'linear-2'", "true", "false"]),
    ("diagnose-option-delay-out-of-range", "diagnose --train {f}/good.csv --validate {f}/good.csv --model linear-2 --inputs u=height --outputs y=force --option input_delay=-3", ["--option", "input_delay=-3", "-3", "from 0 to"]),
    ("diagnose-unknown-candidate", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --candidates offset nosuch", ["--candidates", "'nosuch'", "coulomb_friction"]),
    ("diagnose-unknown-role", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --roles nosuch=F_c", ["--roles", "'nosuch'", "position", "actuators"]),
    ("diagnose-role-of-no-signal", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --roles force=nosuch", ["--roles", "force=nosuch", "eta", "F_c"]),
    ("diagnose-max-evaluations-0", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --max-evaluations 0", ["--max-evaluations", ">= 1"]),
    ("diagnose-workers-0", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --workers 0", ["--workers", "0", ">= 1"]),
    ("diagnose-hdf5-which-table", "diagnose --train {f}/two.h5 --validate {f}/good.csv --model two-mass {io}", ["two.h5", "'a'", "'b'", "--key"]),
    ("diagnose-hdf5-unknown-key", "diagnose --train {f}/two.h5:c --validate {f}/good.csv --model two-mass {io}", ["two.h5", "'c'", "'a'", "'b'"]),
    ("diagnose-unwritable-json", "diagnose --train {f}/good.csv --validate {f}/good.csv --model two-mass {io} --json {f}/a_file/d.json", ["--json", "a_file"]),
    # doe
    ("doe-duration-0", "doe --duration 0 --out {f}/doe", ["--duration", "> 0"]),
    ("doe-duration-negative", "doe --duration -3 --out {f}/doe", ["--duration", "-3"]),
    ("doe-population-0", "doe --population 0 --out {f}/doe", ["--population", ">= 1"]),
    ("doe-pantograph-file-for-two-mass", "doe --model two-mass --parameters {f}/pantograph.json --out {f}/doe", ["pantograph.json", "'Pantograph'", "two-mass"]),
    ("doe-unit-in-pounds", "doe --parameters {f}/in_lb.json --out {f}/doe", ["in_lb.json", "'m_c'", "'lb'", "'kg'"]),
    # linearise
    ("linearise-negative-pressure", "linearise --p -1", ["--p", "-1", ">= 0"]),
    ("linearise-pantograph-file-for-two-mass", "linearise --model TwoMass --parameters {f}/pantograph.json", ["pantograph.json", "'Pantograph'", "'TwoMass'"]),
    ("linearise-unit-in-pounds", "linearise --parameters {f}/in_lb.json", ["in_lb.json", "'m_c'", "'lb'", "'kg'"]),
    ("linearise-unwritable-json", "linearise --json {f}/a_file/l.json", ["--json", "a_file"]),
    # video
    ("render-scale-0", "video render {f}/nowhere --out {f}/v.mp4 --scale 0", ["--scale", "> 0"]),
    ("render-duration-0", "video render {f}/nowhere --out {f}/v.mp4 --duration 0", ["--duration", "> 0"]),
    ("setup-video-missing", "video setup {f}/nowhere.mp4 --camera {f}/camera.json --out {f}/setup.json", ["nowhere.mp4", "not found"]),
    ("setup-frame-negative", "video setup {f}/nowhere.mp4 --camera {f}/camera.json --frame -1 --out {f}/s.json", ["--frame", ">= 0"]),
    # sync
    ("sync-run-missing", "sync {f}/nowhere {f}/good.csv --out {f}/merged", ["nowhere", "no such file or run folder"]),
    ("sync-parquet-named-csv", "sync {f}/parquet.csv {f}/good.csv --out {f}/merged", ["parquet.csv", "Parquet"]),
    # cosim
    ("cosim-bogus-fmu", "cosim --speed 250 --fmu {f}/bogus.fmu", ["--fmu", "bogus.fmu", "not an FMU"]),
    ("cosim-time-step-0", "cosim --speed 250 --time-step 0", ["--time-step", "> 0"]),
    ("cosim-unwritable-out", "cosim --speed 250 --out {f}/a_file/c", ["--out", "a_file"]),
    # usage
    ("unknown-option", "identify {f}/good.csv --bogus", ["--bogus"]),
]


#: Exit codes by class (panto.cli.EXIT_CODES): usage and bad input data.
USAGE, BAD_INPUT = 2, 65
#: The catalogue's cases refused by the parser (a usage error); the others are bad input.
USAGE_CASES = {"preprocess-rate-0", "preprocess-rate-negative", "identify-rate-0",
               "identify-max-evaluations-0", "identify-multistart-negative", "compare-rate-0",
               "diagnose-folds-0", "diagnose-sample-rate-negative", "doe-duration-0",
               "doe-duration-negative", "doe-population-0", "linearise-negative-pressure",
               "render-scale-0", "render-duration-0", "setup-frame-negative",
               "cosim-time-step-0", "unknown-option", "diagnose-unknown-candidate",
               "diagnose-unknown-role", "diagnose-max-evaluations-0", "diagnose-workers-0"}


def _argv(line: str, folder: Path) -> list[str]:
    return line.replace("{io}", " ".join(IO)).replace("{f}", str(folder)).split()


@pytest.mark.parametrize("line, fragments", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_one_clear_line(line, fragments, files, capsys, request):
    capsys.readouterr()
    code = main(_argv(line, files))
    printed = capsys.readouterr()
    lines = printed.err.strip().splitlines()
    assert code == (USAGE if request.node.callspec.id in USAGE_CASES else BAD_INPUT), printed.err
    assert "Traceback" not in printed.err + printed.out
    assert len(lines) == 1, printed.err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


RIG_RUN_CASES = {
    "duration-negative": (["--duration", "-3"], ["--duration", "-3"]),
    "duration-0": (["--duration", "0"], ["--duration", "> 0"]),
    "duration-not-whole-samples": (["--duration", "0.0013"], ["sine_1hz.json", "whole number"]),
    "bogus-fmu": (["--fmu", "{f}/bogus.fmu"], ["--fmu", "bogus.fmu", "not an FMU"]),
    "unknown-imperfection": (["--imperfections", "{f}/imperfections.json"],
                             ["imperfections.json", "'gremlins'", "bar_mass"]),
    "real-rig-without-io": (["--interface", "virtual", "--channel", "x"], ["--io"]),
}


#: The rig run cases that are usage errors (the others are bad input).
RIG_RUN_USAGE = {"duration-negative", "duration-0", "real-rig-without-io"}


@pytest.mark.parametrize("case", RIG_RUN_CASES)
def test_a_refused_rig_run_leaves_no_run_folder(case, files, tmp_path, capsys):
    options, fragments = RIG_RUN_CASES[case]
    options = [o.replace("{f}", str(files)) for o in options]
    runs = tmp_path / "runs"
    code = main(["rig", "run", PROFILE, "--out", str(runs), *options])
    error = capsys.readouterr().err.strip()
    expected = USAGE if case in RIG_RUN_USAGE else BAD_INPUT
    assert code == expected and "Traceback" not in error and len(error.splitlines()) == 1, error
    assert all(fragment in error for fragment in fragments), error
    assert not runs.exists() or not any(runs.iterdir())


def test_parameter_units_are_converted_not_ignored(files):
    """m_c = 7000 g reads as the file with m_c = 7 kg does, not as 7000 kg nor the default."""
    from panto.fmu_src.parameters import ParameterSet

    specs = default_parameters("Pantograph").specs
    in_g, in_kg = (ParameterSet.load(files / f"{name}.json", specs, "Pantograph")
                   for name in ("in_g", "in_kg"))
    assert in_g["m_c"] == pytest.approx(7.0, rel=1e-12) and in_kg["m_c"] == 7.0
    assert in_g["m_c"] != default_parameters("Pantograph")["m_c"]
    assert all(in_g[name] == in_kg[name] for name in in_kg.names)


def test_diagnosing_a_run_against_itself_warns_that_nothing_is_withheld():
    import numpy as np
    from scipy import signal

    from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
    from panto.identification.estimation.base import IdentificationData

    rng = np.random.default_rng(0)
    u = signal.lfilter([1.0], [1.0, -0.9], rng.normal(size=600))
    y = signal.lfilter([0.2], [1.0, -0.8], u) + 0.01 * rng.normal(size=600)
    run = IdentificationData(np.arange(600) * 0.01, u[:, None], y[:, None], ("u",), ("y",))
    lines: list[str] = []
    diagnose(run, run, structure="linear-2", progress=lines.append,
             options=DiagnosisOptions(max_effects=1, max_refits=1, discovery=False))
    assert any("WARNING: the validation run is the training run" in line for line in lines)


def test_more_free_parameters_than_samples_is_refused_not_a_success():
    import numpy as np

    from panto.identification.estimation.base import IdentificationData, IdentificationError
    from panto.identification.estimation.least_squares import fit_least_squares
    from panto.identification.structures.oscillators import OscillatorStructure

    structure = OscillatorStructure(3, outputs=("F_c",))
    t = np.arange(5) * 0.02
    data = IdentificationData(t, np.column_stack([np.full(5, 1.8), np.full(5, 4.0)]),
                              np.linspace(80, 81, 5)[:, None], ("eta", "p"), ("F_c",))
    with pytest.raises(IdentificationError, match="5 measured output samples for 11 free"):
        fit_least_squares(structure, data, free=structure.default_free())
