"""Benchmark: does the diagnosis name withheld effects in plants it was not written against?
(issue 24, "Benchmark families the diagnosis was not written against").

Run by hand; writes ``benchmarks/diagnosis_families_<split>.json`` and ``.md``
(``..._<split>_quick`` with ``--quick``)::

    .venv/bin/python benchmarks/diagnosis_families.py [--cases 30] [--split tune|heldout]
        [--skip N] [--workers 1] [--quick] [--out PATH]
        [--options adequacy=true global_fit=true ...]
        [--i-am-not-tuning] [--quiet]

Cases (``benchmarks/effect_plants.py``): two- and three-mass oscillators with one hidden effect
each (ten of the diagnosis' vocabulary, four outside it: Bouc-Wen hysteresis, a sign-blind
sensor, creep, a time-varying gain) or none (``clean``), strength drawn per seed, one or two
inputs, one to three outputs, APRBS / multisine / chirp / ramps, 50-500 Hz, 20-120 s, SNR
20-40 dB; a training and a validation run each. Case ``i`` of the sequence has the label
``LABELS[i % 15]``, the family ``FAMILIES[(i // 15) % 2]`` and the seed ``i``.

Split by seed: a case whose ``zlib.crc32("family/seed") % 4 == 0`` belongs to the HELD-OUT
split, every other to the TUNING split. ``--split heldout`` refuses to run without
``--i-am-not-tuning``: whoever tunes thresholds looks at the tuning split only.

Per case :func:`panto.identification.diagnose` ``(train, validation, structure=two-mass |
three-mass, options=...)`` (``--options`` sets :class:`DiagnosisOptions` fields; ``global_fit=true``
gives the default :class:`GlobalFitOptions`). Scored: the outcome (the first effect named, else
the verdict) against the label (``clean`` -> ``none``; a library effect -> its name;
out-of-library -> ``unexplained``), the detectability from the truth (fit points the effect costs
the true plant on the validation run, the largest over outputs; *strong* when >= 2), and the gap
closed (share of validation residual energy removed) on the output where the effect costs most.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import effect_plants  # noqa: E402  (the sibling benchmark module)

FAMILIES = ("two-mass", "three-mass")
#: Detectability [fit points] from which a case is *strong* (the issue's relevance floor).
STRONG = 2.0
#: The right outcome of each label.
EXPECTED = {"clean": "none", **{e: e for e in effect_plants.LIBRARY},
            **{e: "unexplained" for e in effect_plants.OUT_OF_LIBRARY}}


def split_of(family: str, seed: int) -> str:
    """``"heldout"`` when ``crc32("family/seed") % 4 == 0``, else ``"tune"``."""
    return "heldout" if effect_plants.stable_hash(f"{family}/{seed}") % 4 == 0 else "tune"


def case_sequence(split: str, *, quick: bool = False) -> Iterator[effect_plants.CaseSpec]:
    """The cases of `split` in order (module notes), without end."""
    labels = effect_plants.LABELS
    index = 0
    while True:
        family = FAMILIES[(index // len(labels)) % len(FAMILIES)]
        if split_of(family, index) == split:
            yield effect_plants.draw_spec(family, labels[index % len(labels)], index, quick=quick)
        index += 1


def parse_options(pairs: list[str]) -> dict[str, Any]:
    """``key=value`` strings to :class:`DiagnosisOptions` keyword arguments (checked by building
    the options once); raises ValueError naming the key and value."""
    from panto.identification.diagnosis.pipeline import DiagnosisOptions

    fields = {f.name: f for f in dataclasses.fields(DiagnosisOptions)}
    raw = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or key not in fields or key == "roles":
            raise ValueError(f"--options {pair!r}: expected key=value with key one of "
                             f"{sorted(set(fields) - {'roles'})}")
        raw[key] = value
    diagnosis_options(raw)
    return raw


def diagnosis_options(raw: Mapping[str, str]):
    """The :class:`DiagnosisOptions` for the raw ``key=value`` strings of :func:`parse_options`."""
    from panto.identification.diagnosis.pipeline import DiagnosisOptions
    from panto.identification.estimation.global_fit import GlobalFitOptions

    values = {}
    defaults = DiagnosisOptions()
    for key, text in raw.items():
        lowered = text.strip().lower()
        default = getattr(defaults, key)
        if key == "global_fit" or isinstance(default, bool):
            if lowered not in ("true", "false", "yes", "no", "1", "0", "none"):
                raise ValueError(f"--options {key}={text!r}: expected true or false")
            on = lowered in ("true", "yes", "1")
            values[key] = (GlobalFitOptions() if on else None) if key == "global_fit" else on
        elif isinstance(default, int):
            try:
                values[key] = int(text)
            except ValueError:
                raise ValueError(f"--options {key}={text!r}: expected an integer") from None
        else:
            values[key] = tuple(t.strip() for t in text.split(",") if t.strip())
    try:
        return DiagnosisOptions(**values)
    except Exception as error:  # the options' own check names the field
        raise ValueError(f"--options: {error}") from None


def to_data(case: effect_plants.EffectCase, index: int):
    """Run `index` (0 training, 1 validation) of `case` as ``IdentificationData``."""
    from panto.identification.estimation.base import IdentificationData

    run, names = case.runs[index], case.spec.outputs
    units = {"eta": "m", "p": "bar", "F_c": "N", "y_cb": "m", "xi": "m"}
    return IdentificationData(run["time"], np.column_stack([run["eta"], run["p"]]),
                              np.column_stack([run["outputs"][n] for n in names]), ("eta", "p"),
                              names, {n: units[n] for n in ("eta", "p") + names},
                              f"{case.spec.name} ({('training', 'validation')[index]})")


def unabsorbed(case: effect_plants.EffectCase) -> dict[str, float]:
    """Per output: fit points [%] on the validation run that no refitted nominal can take from the
    effect - the true plant's validation fit less that of the nominal structure fitted to the
    NOISE-FREE training run, started from the plant's true parameters (so near its optimum).

    Independent of the diagnosis under test (only the oscillator structure and the least-squares
    estimator are used): an effect a nominal absorbs (a lag the fitted masses and dampers
    imitate) leaves nothing the withheld data can attribute to it, whatever it costs the plant's
    own parameters (the detectability)."""
    from panto.identification.estimation.base import IdentificationData
    from panto.identification.estimation.least_squares import fit_least_squares
    from panto.identification.structures.oscillators import OscillatorStructure

    train, validation = case.runs
    names = case.spec.outputs
    structure = OscillatorStructure(case.plant.masses, outputs=names)
    clean = IdentificationData(train["time"], np.column_stack([train["eta"], train["p"]]),
                               np.column_stack([train["clean"][n] for n in names]), ("eta", "p"),
                               names, {}, f"{case.spec.name} (noise-free training)")
    start = {k: float(v) for k, v in case.plant.truth.items() if k in structure.parameter_names}
    free = structure.default_free()
    result = fit_least_squares(structure, clean, free=free, initial=start, max_evaluations=600)
    other = IdentificationData(validation["time"],
                               np.column_stack([validation["eta"], validation["p"]]),
                               np.column_stack([validation["outputs"][n] for n in names]),
                               ("eta", "p"), names, {}, "validation")
    simulated = structure.simulate(result.parameters, other)
    return {n: case.ceiling[n] - effect_plants.fit(validation["outputs"][n], simulated[:, j])
            for j, n in enumerate(names)}


def run_case(spec: effect_plants.CaseSpec, raw_options: Mapping[str, str],
             quiet: bool = False) -> dict:
    """Simulate and diagnose one case; the record of :func:`score` (an ``error`` on failure)."""
    from panto.fmu_src.frame_stack import keep_stack_chunks
    from panto.identification.diagnosis.pipeline import diagnose

    keep_stack_chunks()  # this program's processes, as the command line's (its module notes)
    started = time.perf_counter()
    record: dict[str, Any] = {"name": spec.name, "split": split_of(spec.family, spec.seed),
                              **dataclasses.asdict(spec)}
    try:
        case = effect_plants.effect_case(spec)
        record.update(setting=dict(case.plant.setting), detectability=dict(case.detectability),
                      strongest=case.strongest, ceiling=dict(case.ceiling),
                      step_drift=dict(case.step_drift), reproducible=case.reproducible,
                      simulation_s=time.perf_counter() - started)
        try:
            record["unabsorbed"] = unabsorbed(case)
        except Exception as error:  # the reference fit failing is recorded, not fatal
            record["unabsorbed_error"] = f"{type(error).__name__}: {error}"
        say(f"{spec.name}: simulated in {record['simulation_s']:.0f} s, detectability "
            f"{case.strongest:.1f} points; diagnosing", quiet)
        begun = time.perf_counter()
        result = diagnose(to_data(case, 0), to_data(case, 1), structure=spec.family,
                          options=diagnosis_options(raw_options),
                          progress=None if quiet else (lambda line: say(f"  {spec.name}: {line}")))
        record.update(verdict=result.verdict, effects=list(result.effects),
                      alternatives={step.effect: list(step.alternatives)
                                    for step in result.steps if step.alternatives},
                      fit_before=dict(result.fit_before), fit_after=dict(result.fit_after),
                      gap_closed=dict(result.gap_closed()), diagnosis_s=time.perf_counter() - begun,
                      gap_significant=bool(result.gap.get("significant")),
                      remaining_significant=bool(result.remaining_gap.get("significant")),
                      systematic_before=_systematic(result.gap),
                      systematic_after=_systematic(result.remaining_gap),
                      summary=result.summary,
                      black_box_validation=(result.adequacy or {}).get("black_box_validation_fit"))
    except Exception as error:  # a failed case is recorded, never lost
        record.update(error=f"{type(error).__name__}: {error}",
                      traceback=traceback.format_exc(limit=-4).splitlines())
    record["wall_s"] = time.perf_counter() - started
    return score(record)


def _systematic(gap: dict) -> dict:
    """Per output: the fit points the residual's input-explained part costs (the gap tests'
    ``systematic_cost``; None where not computed)."""
    return {o: (v or {}).get("systematic_cost") for o, v in (gap.get("per_output") or {}).items()}


def effect_gap_closed(before: float | None, after: float | None,
                      ceiling: float | None) -> float | None:
    """Share of the gap between the nominal and the true plant removed, on one output.

    ``[(1 - f_before)^2 - (1 - f_after)^2] / [(1 - f_before)^2 - (1 - f_true)^2]`` with the
    validation fits as fractions and ``f_true`` the true plant's fit on the same noisy run (the
    ``ceiling``): the measurement noise, which no model removes, is not part of this gap
    (:func:`panto.identification.diagnosis.benchmark.gap_closed`'s definition). 1 means the
    diagnosed model predicts as well as the plant itself; None where the fitted nominal is
    already within 0.1 fit points of the plant (no gap to close) or a fit is missing.
    """
    if before is None or after is None or ceiling is None or ceiling - before < 0.1:
        return None
    from panto.identification.diagnosis.benchmark import gap_closed

    return gap_closed({"o": before}, {"o": after}, {"o": ceiling})


def score(record: dict) -> dict:
    """Add ``outcome``, ``expected``, ``correct``, ``strong``, ``gap_closed_main`` (share of
    the validation residual energy removed, noise included), ``effect_gap_closed_main``
    (:func:`effect_gap_closed`: share of the gap to the true plant removed) and
    ``nominal_left``: per output, the true plant's validation fit less the fitted nominal's
    (fit points the nominal really misses; near zero when it absorbs the effect)."""
    outcome = "error" if "error" in record else \
        (record["effects"][0] if record["verdict"] == "effect" and record.get("effects")
         else record["verdict"])
    detectability = record.get("detectability") or {}
    main = max(detectability, key=detectability.get) if detectability else None
    closed = (record.get("gap_closed") or {}).get(main)
    before = record.get("fit_before") or {}
    record["nominal_left"] = {k: v - before[k] for k, v in (record.get("ceiling") or {}).items()
                              if k in before}
    # the first name's equally supported alternatives (the diagnosis' "the runs cannot tell")
    first = (record.get("alternatives") or {}).get(record["effects"][0], []) \
        if record.get("effects") else []
    record.update(outcome=outcome, expected=EXPECTED[record["label"]],
                  correct=outcome == EXPECTED[record["label"]],
                  correct_or_tied=outcome == EXPECTED[record["label"]]
                  or (record.get("verdict") == "effect" and EXPECTED[record["label"]] in first),
                  strong=record.get("strongest", 0.0) >= STRONG, main_output=main,
                  gap_closed_main=closed,
                  effect_gap_closed_main=effect_gap_closed(
                      before.get(main), (record.get("fit_after") or {}).get(main),
                      (record.get("ceiling") or {}).get(main)),
                  unabsorbable=max((record.get("unabsorbed") or {"": -math.inf}).values())
                  >= STRONG)
    return record


def say(message: str, quiet: bool = False) -> None:
    """Progress on stderr."""
    if not quiet:
        print(message, file=sys.stderr, flush=True)


# --- summary ----------------------------------------------------------------------------------

def _share(records: list[dict], key: str = "correct") -> dict:
    right = sum(1 for r in records if r.get(key))
    return {"right": right, "cases": len(records),
            "share": right / len(records) if records else None}


def summarise(records: list[dict]) -> dict:
    """The issue's scores, strong and weak apart, and a confusion matrix."""
    library = [r for r in records if r["label"] in effect_plants.LIBRARY]
    outside = [r for r in records if r["label"] in effect_plants.OUT_OF_LIBRARY]
    clean = [r for r in records if r["label"] == "clean"]
    named = [r for r in library if r["correct"] and r["gap_closed_main"] is not None]

    def median_gap(group: list[dict], key: str = "gap_closed_main") -> float | None:
        values = [r[key] for r in group if r.get(key) is not None]
        return float(np.median(values)) if values else None

    summary = {
        "library_top1_strong": _share([r for r in library if r["strong"]]),
        "library_top1_weak": _share([r for r in library if not r["strong"]]),
        "library_top1_strong_reproducible": _share([r for r in library if r["strong"]
                                                    and r.get("reproducible", True)]),
        "library_top1_all": _share(library),
        "library_top1_or_tied_strong": _share([r for r in library if r["strong"]],
                                              "correct_or_tied"),
        "library_top1_or_tied_all": _share(library, "correct_or_tied"),
        "library_top1_unabsorbable": _share([r for r in library if r.get("unabsorbable")]),
        "library_top1_absorbable": _share([r for r in library if r["strong"]
                                           and not r.get("unabsorbable")]),
        "library_top1_nominal_misses": _share([r for r in library if max(
            (r.get("nominal_left") or {"": -math.inf}).values()) >= STRONG]),
        "clean_none": _share(clean),
        "out_of_library_unexplained_strong": _share([r for r in outside if r["strong"]]),
        "out_of_library_unexplained_weak": _share([r for r in outside if not r["strong"]]),
        "out_of_library_unexplained_all": _share(outside),
        "out_of_library_unexplained_unabsorbable": _share([r for r in outside
                                                           if r.get("unabsorbable")]),
        "gap_closed_median_named_strong": median_gap([r for r in named if r["strong"]]),
        "gap_closed_median_named_all": median_gap(named),
        "gap_closed_median_named_strong_reproducible": median_gap(
            [r for r in named if r["strong"] and r.get("reproducible", True)]),
        "effect_gap_closed_median_named_strong": median_gap(
            [r for r in named if r["strong"]], "effect_gap_closed_main"),
        "effect_gap_closed_median_named_all": median_gap(named, "effect_gap_closed_main"),
        "effect_gap_closed_median_named_strong_reproducible": median_gap(
            [r for r in named if r["strong"] and r.get("reproducible", True)],
            "effect_gap_closed_main"),
        "errors": sum(1 for r in records if r["outcome"] == "error"),
        "per_label": {label: {"all": _share([r for r in records if r["label"] == label]),
                              "strong": _share([r for r in records if r["label"] == label
                                                and r["strong"]])}
                      for label in effect_plants.LABELS},
    }
    columns = ["none", "unexplained", *effect_plants.LIBRARY, "error"]
    summary["confusion"] = {
        kind: {"columns": columns,
               "rows": {label: [sum(1 for r in records if r["label"] == label
                                    and r["outcome"] == column and keep(r)) for column in columns]
                        for label in effect_plants.LABELS}}
        for kind, keep in (("strong", lambda r: r["strong"]),
                           ("weak", lambda r: not r["strong"]))}
    return summary


# --- report -----------------------------------------------------------------------------------

def _cell(share: Mapping[str, Any]) -> str:
    if not share["cases"]:
        return "-"
    return f"{share['right']}/{share['cases']} ({100.0 * share['share']:.0f} %)"


def _percent(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{100.0 * value:.0f} %"


def markdown(report: dict) -> str:
    """The report as markdown: settings, scores, confusion matrices, every case."""
    s, settings = report["summary"], report["settings"]
    lines = [f"# Diagnosis on independent benchmark families: {settings['split']} split",
             "", f"`{settings['command']}`" + (
                 f" (scores recomputed later: `{settings['rescored']}`)"
                 if settings.get("rescored") else ""), "",
             f"{len(report['cases'])} cases{'' if report['complete'] else ' (INCOMPLETE)'}, "
             f"options {settings['options'] or 'default'}, {settings['workers']} worker(s), "
             f"{settings['wall_s']:.0f} s, {settings['platform']}. Plants: "
             "`benchmarks/effect_plants.py`; strong = the effect costs the true plant >= "
             f"{STRONG:g} fit points on the validation run (some output). *Nominal misses*: "
             "the true plant's validation fit less the fitted nominal's (what a refitted "
             "nominal cannot absorb of the effect). *Unabsorbed*: the same, with the nominal "
             "fitted to the noise-free training run from the plant's true parameters instead "
             "(independent of the diagnosis: what no refitted nominal can take from the effect).",
             "",
             "| score | strong | weak | all |", "|---|---|---|---|",
             f"| top-1 name, library effects | {_cell(s['library_top1_strong'])} | "
             f"{_cell(s['library_top1_weak'])} | {_cell(s['library_top1_all'])} |",
             f"| top-1 name, or the first name's equally supported alternative (\"the runs "
             f"cannot tell A from B\"; not the issue's score) | "
             f"{_cell(s.get('library_top1_or_tied_strong', _share([])))} | | "
             f"{_cell(s.get('library_top1_or_tied_all', _share([])))} |",
             f"| `unexplained`, out-of-library | {_cell(s['out_of_library_unexplained_strong'])} | "
             f"{_cell(s['out_of_library_unexplained_weak'])} | "
             f"{_cell(s['out_of_library_unexplained_all'])} |",
             f"| `none`, clean | | | {_cell(s['clean_none'])} |",
             f"| top-1 name, strong library effects whose free run is reproducible (the true "
             f"plant at half the step within {STRONG:g} points) | "
             f"{_cell(s.get('library_top1_strong_reproducible', _share([])))} | | |",
             f"| top-1 name, library effects the fitted nominal misses by >= {STRONG:g} points "
             f"(filtered) | | | {_cell(s['library_top1_nominal_misses'])} |",
             f"| top-1 name, library effects no refitted nominal absorbs (*unabsorbed* >= "
             f"{STRONG:g} points) | | | {_cell(s['library_top1_unabsorbable'])} |",
             f"| top-1 name, strong library effects a refitted nominal absorbs (*unabsorbed* < "
             f"{STRONG:g}) | | | {_cell(s['library_top1_absorbable'])} |",
             f"| `unexplained`, out-of-library effects no refitted nominal absorbs "
             f"(*unabsorbed* >= {STRONG:g} points) | | | "
             f"{_cell(s.get('out_of_library_unexplained_unabsorbable', _share([])))} |",
             f"| median gap closed where named right | "
             f"{_percent(s['gap_closed_median_named_strong'])} | | "
             f"{_percent(s['gap_closed_median_named_all'])} |",
             f"| median gap closed where named right, free run reproducible (filtered) | "
             f"{_percent(s.get('gap_closed_median_named_strong_reproducible'))} | | |",
             f"| median share of the gap to the true plant closed where named right (noise "
             f"not counted as gap) | {_percent(s.get('effect_gap_closed_median_named_strong'))} "
             f"| | {_percent(s.get('effect_gap_closed_median_named_all'))} |",
             f"| the same, free run reproducible (filtered) | "
             f"{_percent(s.get('effect_gap_closed_median_named_strong_reproducible'))} | | |",
             "", "*Gap closed*: the share of the validation residual energy removed on the "
             "output the effect costs most, measurement noise included (the noise no model "
             "removes, so a weak effect caps it far below 100 %); *gap to the true plant*: the "
             "share of the energy between the fitted nominal and the true plant removed "
             "(`effect_gap_closed`).", "",
             f"Errors: {s['errors']}.", "", "## Per label", "",
             "| label | expected | right (strong) | right (all) |", "|---|---|---|---|"]
    lines += [f"| {label} | `{EXPECTED[label]}` | {_cell(v['strong'])} | {_cell(v['all'])} |"
              for label, v in s["per_label"].items()]
    for kind in ("strong", "weak"):
        matrix = s["confusion"][kind]
        lines += ["", f"## Confusion matrix, {kind} cases (rows: label; columns: outcome)", "",
                  "| label | " + " | ".join(matrix["columns"]) + " |",
                  "|---" * (len(matrix["columns"]) + 1) + "|"]
        lines += [f"| {label} | " + " | ".join(str(n) if n else "." for n in row) + " |"
                  for label, row in matrix["rows"].items()]
    lines += ["", "## Every case", "",
              "| case | excitation | Hz | s | inputs | outputs | SNR dB | strength | "
              "detectability | unabsorbed | nominal misses | outcome | right | gap closed | "
              "gap to the true plant closed | wall s |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["cases"]:
        detect = ", ".join(f"{k} {v:.1f}" for k, v in (r.get("detectability") or {}).items())
        left = ", ".join(f"{k} {v:.1f}" for k, v in (r.get("nominal_left") or {}).items())
        kept = ", ".join(f"{k} {v:.1f}" for k, v in (r.get("unabsorbed") or {}).items())
        outcome = r.get("error", r["outcome"]) if r["outcome"] == "error" else \
            ", ".join(e + (f" (or {' or '.join(a)})" if (a := (r.get("alternatives") or {})
                                                            .get(e)) else "")
                      for e in r.get("effects") or []) or r["outcome"]
        lines.append(f"| {r['name']} | {r['excitation']} | {r['rate']:g} | {r['duration']:g} | "
                     f"{r['inputs']} | {', '.join(r['outputs'])} | {r['snr_db']:.0f} | "
                     f"{r['strength']:.2f} | {detect} | {kept or '-'} | {left or '-'} | "
                     f"{outcome} | "
                     f"{'yes' if r['correct'] else 'no'} | {_percent(r['gap_closed_main'])} | "
                     f"{_percent(r.get('effect_gap_closed_main'))} | {r['wall_s']:.0f} |")
    return "\n".join(lines) + "\n"


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_report(out: Path, records: list[dict], settings: dict, complete: bool) -> None:
    """``out.json`` and ``out.md`` (records in case order)."""
    order = {name: i for i, name in enumerate(settings["cases"])}
    records = sorted(records, key=lambda r: order[r["name"]])
    report = {"settings": settings, "complete": complete, "summary": summarise(records),
              "cases": records}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.with_suffix(".json").write_text(json.dumps(_plain(report), indent=1) + "\n")
    out.with_suffix(".md").write_text(markdown(report))


def rescore(path: Path, quiet: bool = False) -> int:
    """Score the stored report ``path`` (``.json``) again and rewrite its ``.json`` and ``.md``.

    Only the scores are recomputed from each case's recorded outcome, fits and truth; the runs,
    their settings and the command that produced them are kept, the rescoring is noted in
    ``settings["rescored"]``. 2 when the file cannot be read or is not such a report.
    """
    try:
        report = json.loads(path.read_text())
        records = [score(dict(r)) for r in report["cases"]]
        settings = {**report["settings"], "rescored": f"benchmarks/diagnosis_families.py "
                                                      f"--rescore {path.name}"}
        write_report(path.with_suffix(""), records, settings, report.get("complete", True))
    except (OSError, ValueError, KeyError, TypeError) as error:
        print(f"error: cannot rescore {path}: {error}", file=sys.stderr)
        return 2
    say(f"rescored {path} ({len(records)} cases)", quiet)
    return 0


# --- command line -----------------------------------------------------------------------------

def named_spec(name: str, quick: bool) -> effect_plants.CaseSpec:
    """The case ``family/label/seed`` (a record's ``name``); ValueError naming what is wrong."""
    parts = name.split("/")
    if len(parts) != 3 or parts[0] not in FAMILIES or \
            parts[1] not in effect_plants.LABELS or not parts[2].isdigit():
        raise ValueError(f"--names {name!r}: expected FAMILY/LABEL/SEED with FAMILY in "
                         f"{', '.join(FAMILIES)}, LABEL in "
                         f"{', '.join(effect_plants.LABELS)} and SEED a whole number")
    return effect_plants.draw_spec(parts[0], parts[1], int(parts[2]), quick=quick)


def parse_arguments(argv: list[str] | None) -> argparse.Namespace:
    """The command line (module notes); refuses the held-out split without the guard."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", type=int, default=None,
                        help="cases of the split, in sequence order (default 30; 6 with --quick)")
    parser.add_argument("--skip", type=int, default=0,
                        help="leave out the split's first N cases (cases already looked at)")
    parser.add_argument("--split", choices=("tune", "heldout"), default="tune")
    parser.add_argument("--i-am-not-tuning", action="store_true",
                        help="required for --split heldout: nothing will be tuned on its scores")
    parser.add_argument("--workers", type=int, default=1, help="cases in parallel processes")
    parser.add_argument("--quick", action="store_true", help="short runs (20 s, <= 100 Hz)")
    parser.add_argument("--out", default=None, help="output path without suffix")
    parser.add_argument("--options", nargs="*", default=[], metavar="KEY=VALUE",
                        help="DiagnosisOptions fields, e.g. adequacy=true global_fit=true")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--names", nargs="+", default=None, metavar="FAMILY/LABEL/SEED",
                        help="run these cases instead of a split's sequence (cases already looked "
                             "at, e.g. a record's misses re-run with newer code; never a "
                             "judgement)")
    parser.add_argument("--rescore", default=None, metavar="REPORT.json",
                        help="score a stored report again with this version's scores (no case "
                             "is run; every recorded outcome and fit is kept) and rewrite it")
    arguments = parser.parse_args(argv)
    if arguments.rescore:
        return arguments
    if arguments.names:
        try:
            arguments.specs = [named_spec(name, arguments.quick) for name in arguments.names]
        except ValueError as error:
            parser.error(str(error))
    if arguments.split == "heldout" and not arguments.i_am_not_tuning and not arguments.names:
        parser.error("--split heldout is the held-out split: it runs only with --i-am-not-tuning "
                     "(tune on --split tune)")
    if arguments.workers < 1 or (arguments.cases is not None and arguments.cases < 1):
        parser.error("--workers and --cases must be at least 1")
    if arguments.skip < 0:
        parser.error("--skip must be at least 0")
    try:
        arguments.raw_options = parse_options(arguments.options)
    except ValueError as error:
        parser.error(str(error))
    return arguments


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (module notes); 0 when every case ran, 1 when some failed."""
    arguments = parse_arguments(argv)
    if arguments.rescore:
        return rescore(Path(arguments.rescore), arguments.quiet)
    if arguments.names:
        specs = arguments.specs
    else:
        sequence = case_sequence(arguments.split, quick=arguments.quick)
        for _ in range(arguments.skip):
            next(sequence)
        specs = [next(sequence) for _ in range(arguments.cases or (6 if arguments.quick else 30))]
    count = len(specs)
    split = "named" if arguments.names else arguments.split
    suffix = "_quick" if arguments.quick else ""
    out = Path(arguments.out or HERE / f"diagnosis_families_{split}{suffix}")
    started = time.perf_counter()
    settings = {"split": split, "quick": arguments.quick, "options": arguments.raw_options,
                "workers": arguments.workers, "cases": [s.name for s in specs],
                "command": "benchmarks/diagnosis_families.py " + " ".join(sys.argv[1:] if argv is None
                                                                         else argv),
                "platform": f"{platform.python_version()}, {os.cpu_count()} CPUs", "wall_s": 0.0}
    records: list[dict] = []

    def done(record: dict) -> None:
        records.append(record)
        settings["wall_s"] = time.perf_counter() - started
        say(f"[{len(records)}/{count}] {record['name']}: {record['outcome']} (expected "
            f"{record['expected']}, detectability {record.get('strongest', math.nan):.1f}, "
            f"{record['wall_s']:.0f} s)", arguments.quiet)
        write_report(out, records, settings, complete=len(records) == count)

    if arguments.workers == 1:
        for spec in specs:
            done(run_case(spec, arguments.raw_options, arguments.quiet))
    else:
        with ProcessPoolExecutor(arguments.workers, max_tasks_per_child=1) as pool:
            futures = [pool.submit(run_case, spec, arguments.raw_options, arguments.quiet)
                       for spec in specs]
            for future in as_completed(futures):
                done(future.result())
    say(f"wrote {out.with_suffix('.md')} and .json", arguments.quiet)
    return 1 if any(r["outcome"] == "error" for r in records) else 0


if __name__ == "__main__":
    sys.exit(main())
