"""The diagnosis as files a person opens: ``report.html`` (self-contained, plots embedded as PNG,
rendered from the templates of :mod:`panto.templating`, the look of every report), ``report.json``
(:meth:`~panto.identification.diagnosis.pipeline.Diagnosis.to_dict`) and
``validation_series.csv`` (the validation run's outputs, measured, before and after), plus the
PNGs beside them.

The HTML answers the three questions in order: where the gap lies (validation fit, the residual
spectra, error model, segments and correlations of the nominal model), which effect causes it
(the FROLS ranking per round and every refitted candidate with its tests), how far it shrinks
(fit before/after per output, band and segment energy before/after, effect parameters with
their units, :mod:`~panto.identification.diagnosis.units`). ``report.md`` is the verdict, the fits
and the effect parameters as text; ``report.json`` holds each step's parameter ``units``.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from panto.identification.data.datasets import PANTOGRAPH_UNITS
from panto.identification.diagnosis.residual_plots import plot_bands, plot_output_analysis, plot_series
from panto.identification.diagnosis.units import UNKNOWN, effect_parameter_units
from panto.identification.structures.registry import is_pantograph_structure


def write_report(diagnosis: Any, folder: str | Path, *,
                 units: Mapping[str, str] | None = None) -> dict[str, Path]:
    """Write ``report.json``, the PNG plots, ``validation_series.csv`` (time, measured, nominal
    and augmented outputs of the validation run), ``report.md`` and ``report.html`` into
    `folder`; returns the paths.

    `units` are the data's units by signal name (:attr:`IdentificationData.units`), from which
    the effect parameters' units are derived (:func:`step_units`); for a structure on the rig
    mapping, signals without one take the pantograph models' (``eta`` m, ``p`` bar, ``F_c`` N,
    ``y_cb`` m: the units those models compute in).
    """
    from panto import templating as t

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    units = {**(PANTOGRAPH_UNITS if is_pantograph_structure(diagnosis.structure) else {}),
             **{k: v for k, v in (units or {}).items() if v}}
    step_unit_maps = [step_units(diagnosis, step, units) for step in diagnosis.steps]
    document = diagnosis.to_dict()
    for step, unit_map in zip(document["steps"], step_unit_maps):
        step["units"] = unit_map
    document["data_units"] = units
    json_path = folder / "report.json"
    json_path.write_text(json.dumps(document, indent=2))
    markdown_path = folder / "report.md"
    markdown_path.write_text(markdown_report(diagnosis, step_unit_maps))
    images = [plot_series(diagnosis, folder / "validation.png")]
    bands = plot_bands(diagnosis, folder / "bands.png")
    where_images = []
    for analysis in diagnosis.analysis_before:
        where_images += [Path(p) for p in plot_output_analysis(
            analysis, folder / f"nominal_{analysis.output_name}")]
    series = write_series(diagnosis, folder / "validation_series.csv")
    where = [t.paragraph(diagnosis.where.get("text", "")),
             t.paragraph(gap_sentence(diagnosis.gap, diagnosis.effects)),
             *[t.figure(p) for p in images + where_images]]
    sections = [{"title": "1. Where the gap lies (nominal model, validation run)", "blocks": where},
                {"title": "2. Which effect: ranking on the training residual and refits",
                 "blocks": _which_blocks(diagnosis)},
                {"title": "3. How far the gap shrinks (validation run)",
                 "blocks": _shrink_blocks(diagnosis, bands, step_unit_maps)}]
    html_path = folder / "report.html"
    html_path.write_text(t.render("sections.html.j2", title="Sim-to-real gap diagnosis: "
                                  f"{diagnosis.structure}", written="", head=_head(diagnosis),
                                  sections=sections), encoding="utf-8")
    return {"json": json_path, "html": html_path, "markdown": markdown_path, "images": images + where_images +
            ([bands] if bands else []), **({"series": series} if series else {})}


def write_series(diagnosis: Any, path: Path) -> Path | None:
    """The validation run's measured, nominal (before) and augmented (after) outputs over time
    as a CSV table (``time [s]``, ``<output>_measured``, ``<output>_before``,
    ``<output>_after``, in the data's units); None without series."""
    import pandas as pd

    series = diagnosis.series
    if not series or "time" not in series:
        return None
    columns = {"time [s]": np.asarray(series["time"], float)}
    for j, name in enumerate(diagnosis.output_names):
        for key in ("measured", "before", "after"):
            if key in series:
                columns[f"{name}_{key}"] = np.asarray(series[key], float)[:, j]
    pd.DataFrame(columns).to_csv(path, index=False)
    return path


def _which_blocks(diagnosis: Any) -> list[dict]:
    from panto import templating as t

    blocks = []
    for index, round_ in enumerate(diagnosis.rounds):
        blocks.append(t.heading(f"Round {index + 1}"))
        for output, ranking in round_["ranking"].items():
            rows = [[c["effect"], c["variant"], c["err"], c["significant"]]
                    for c in ranking["candidates"][:6]]
            blocks += [t.paragraph(f"FROLS on {output}"),
                       t.table(["effect", "variant", "ERR", "significant"], rows)]
        rows = [[x["effect"], x["description"], x["delta_bic"], x["significance"],
                 x["improvement"], x["fold_spread"],
                 (t.cell("accepted, then withdrawn: " + x["withdrawn"], "mark")
                  if x.get("withdrawn") else t.cell("accepted", "ok")) if x["accepted"]
                 else rejection(x)]
                for x in round_["tried"]]
        blocks.append(t.table(["effect", "augmentation", "ΔBIC", "|θ|/σ",
                               "validation gain [points]", "fold spread", "decision"], rows))
    return blocks


def gap_sentence(gap: Mapping[str, Any], effects: Any = ()) -> str:
    """The nominal's gap in words, consistent with the verdict: significant with its reasons;
    else within the noise (naming the flags left below the relevance floor), and when effects
    were accepted all the same, that their withheld-data gain found what the tests did not."""
    if gap.get("significant"):
        return "Gap significant: " + "; ".join(gap.get("reasons", []))
    ignored = gap.get("below_relevance") or []
    text = "Gap within the noise by the residual tests" + (
        " (flags below the relevance floor: " + "; ".join(ignored) + ")" if ignored else "")
    if effects:
        text += (f"; yet adding {' then '.join(effects)} improves the withheld fit "
                 "significantly (section 3)")
    return text


def rejection(trial: Mapping[str, Any]) -> str:
    """Why a refitted candidate (a round's ``tried`` entry) was rejected: the tests it failed,
    and for a refit that failed (diverged, no valid model) the error, e.g. ``refit failed
    (non-finite simulation)``."""
    reasons = "; ".join(trial.get("failed", ())) or "rejected"
    message = trial.get("message", "")
    return f"{reasons} ({message})" if message and not trial.get("accepted") else reasons


def _shrink_blocks(diagnosis: Any, bands: Path | None,
                   step_unit_maps: list[Mapping[str, str]]) -> list[dict]:
    from panto import templating as t

    closed = diagnosis.gap_closed()
    blocks = [t.table(["output", "fit before [%]", "fit after [%]",
                       "share of residual energy removed [%]"],
                      [[o, diagnosis.fit_before[o], diagnosis.fit_after[o],
                        _percent(closed[o])] for o in diagnosis.output_names])]
    for step, unit_map in zip(diagnosis.steps, step_unit_maps):
        rows = [[n, v, _spread(step, n), unit_map.get(n, UNKNOWN)]
                for n, v in step.parameters.items()]
        blocks += [t.heading(step.effect), t.paragraph(step.description)]
        if step.evidence:
            blocks.append(t.paragraph(_evidence_text(step)))
        if warning := _not_converged(step):
            blocks.append(t.paragraph(warning))
        blocks += [t.table(["parameter", "value", "± (1 σ)", "unit"], rows),
                   t.table(["output", "fit before [%]", "fit after [%]",
                            "residual energy removed [%]"],
                           [[o, step.fit_before[o], step.fit_after[o],
                             _percent(step.energy_removed[o])] for o in step.fit_before])]
    if bands is not None:
        blocks.append(t.figure(bands))
    if diagnosis.steps:
        blocks.append(t.paragraph("Remaining gap: " + ("; ".join(diagnosis.remaining_gap["reasons"])
                                                       if diagnosis.remaining_gap["significant"]
                                                       else "within the noise")))
    return blocks


def _evidence_text(step: Any) -> str:
    """Why a step whose withheld fit did not rise was accepted (:attr:`Step.evidence`)."""
    return (f"Accepted on the {step.evidence}, not on the fit sample by sample: the free run of a "
            "head that leaves the wire may not follow the record (each landing's instant depends "
            "on the last bits of the state), so the fits below can drop although the contact "
            "force's statistics are reproduced.")


def _spread(step: Any, name: str) -> float | str:
    """A step's parameter's standard deviation; where the refit gave one that is not finite,
    what that means: the run does not determine it (a limit no sample reaches, a parameter at
    its bound), never a number (NaN, shown as "–", where none was recorded)."""
    std = step.std.get(name)
    if std is None:
        return math.nan
    return float(std) if math.isfinite(float(std)) else NOT_DETERMINED


#: The spread cell of a parameter the run does not determine.
NOT_DETERMINED = "not determined by the run"


def _not_converged(step: Any) -> str:
    """A warning when the step's refit stopped on its simulation budget
    (:attr:`~panto.identification.diagnosis.pipeline.Step.refit`), else ""."""
    refit = getattr(step, "refit", "")
    if not refit.startswith("not converged"):
        return ""
    return (f"The refit stopped before it converged ({refit.removeprefix('not converged: ')}): "
            "its parameters and the fits below are where the budget ran out, not shown to be "
            "at the training optimum (raise the budget: `panto diagnose --max-evaluations N`).")


def step_units(diagnosis: Any, step: Any, units: Mapping[str, str]) -> dict[str, str]:
    """The units of an accepted `step`'s parameters (:func:`effect_parameter_units`), an
    ``extra_mode`` gain's from the output it was ranked on and its drive signal."""
    output, drive = _extra_mode_signals(diagnosis, step.effect)
    return effect_parameter_units(step.parameters, units, output=output, drive=drive)


def _extra_mode_signals(diagnosis: Any, effect: str) -> tuple[str | None, str | None]:
    """(target output, drive) of the accepted candidate of `effect`: the ranking entry of its
    round with the accepted trial's variant; (None, None) when not found."""
    for round_ in diagnosis.rounds:
        variants = {x["variant"] for x in round_.get("tried", ())
                    if x["effect"] == effect and x["accepted"]}
        for output, ranking in round_.get("ranking", {}).items():
            for candidate in ranking.get("candidates", ()):
                if candidate["effect"].split("@")[0] == effect and candidate["variant"] in variants:
                    setting = candidate.get("setting") or {}
                    return setting.get("output", output), setting.get("drive")
    return None, None


def markdown_report(diagnosis: Any, step_unit_maps: list[Mapping[str, str]]) -> str:
    """``report.md``: the verdict, the validation fits before and after, each accepted
    effect's parameters with value, standard deviation and unit, and each rejected candidate
    with its reason (:func:`rejection`)."""
    from panto.templating import format_number

    lines = [f"# Sim-to-real gap diagnosis: {diagnosis.structure}", "",
             f"Verdict: {diagnosis.verdict}" + (f" ({' then '.join(diagnosis.effects)})"
                                                 if diagnosis.effects else ""), "",
             diagnosis.summary, "", "| output | fit before [%] | fit after [%] |", "|---|---|---|"]
    lines += [f"| {o} | {format_number(diagnosis.fit_before[o])} | "
              f"{format_number(diagnosis.fit_after[o])} |" for o in diagnosis.output_names]
    for step, unit_map in zip(diagnosis.steps, step_unit_maps):
        lines += ["", f"## {step.effect}", "", step.description, ""]
        if step.evidence:
            lines += [_evidence_text(step), ""]
        if warning := _not_converged(step):
            lines += [warning, ""]
        if step.parameters:
            lines += ["| parameter | value | ± (1 σ) | unit |", "|---|---|---|---|"]
            lines += [f"| {n} | {format_number(v, 5)} | {format_number(_spread(step, n), 3)} | "
                      f"{unit_map.get(n, UNKNOWN)} |" for n, v in step.parameters.items()]
    rejected = [(i + 1, x) for i, round_ in enumerate(diagnosis.rounds)
                for x in round_.get("tried", ()) if not x.get("accepted")]
    if rejected:
        lines += ["", "## Candidates rejected", ""]
        lines += [f"- round {i}: {x['effect']} ({x.get('variant', '')}): {rejection(x)}"
                  for i, x in rejected]
    return "\n".join(lines) + "\n"


def _percent(share: Any) -> float | None:
    """A share (0-1) in percent; None when not finite."""
    return 100.0 * float(share) if share is not None and math.isfinite(share) else None


def _head(diagnosis: Any) -> list[dict]:
    from panto import templating as t

    verdict = {"effect": "effect(s) found", "none": "none: the gap is within the noise",
               "unexplained": "unexplained: a significant gap no candidate closes"}[diagnosis.verdict]
    found = f" — {' then '.join(diagnosis.effects)}" if diagnosis.effects else ""
    blocks = [t.paragraph(f"Verdict: {verdict}{found}", "verdict"),
              t.paragraph(diagnosis.summary)]
    suggestion = diagnosis.next_experiment()
    if suggestion:
        blocks.append(t.paragraph(f"Next experiment ({suggestion['effect']}, "
                                  f"{suggestion['status']}): {suggestion['command']} — "
                                  f"{suggestion['why']}."))
    blocks.append(t.paragraph(f"Wall time {diagnosis.wall_time:.1f} s.", "note"))
    return blocks


__all__ = ["write_report", "step_units", "markdown_report", "rejection", "gap_sentence"]
