"""The main job's HTML report: a one-page summary at the top, then one section per step.

:func:`write_report` reads the summary :func:`panto.demo.run_demo` writes (``summary.json``) and
the plots in the output folder, and writes ``report.html`` beside them, rendered from the
templates of :mod:`panto.templating` (the look the identification and diagnosis reports share).
The images are embedded (base64), so the single file can be mailed or attached; the plots also
stay as files. The overview (:mod:`panto.overview`) is embedded as SVG, a vector figure. A
failed step shows its message and the start of its traceback instead of its results; a section
that cannot be drawn says why, and the rest of the report stays.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from panto import templating as t
from panto.identification.estimation.reporting import parameter_blocks

Blocks = list[dict[str, Any]]
Rows = list[tuple[str, str]]


def write_report(summary: Mapping[str, Any], out: str | Path, *, embed: bool = True) -> Path:
    """Write ``out/report.html`` from the demo's summary; returns its path.

    Parameters
    ----------
    summary : mapping
        What :func:`panto.demo.run_demo` returns (and writes to ``summary.json``).
    out : str or pathlib.Path
        The demo's output folder (the plots and the data behind the overview are read there).
    embed : bool
        Embed the images as base64 (default); False links the files instead.
    """
    out = Path(out)
    figure = lambda path, caption="": t.figure(out / path, caption, embed=embed,  # noqa: E731
                                               relative_to=out)
    overview = _guarded(_overview_blocks, out, summary, figure)
    wall = summary.get("wall_time_s")
    run_line = (f"{'Quick' if summary.get('quick') else 'Full'} run, "
                + (f"{wall:.0f} s on this machine." if isinstance(wall, (int, float)) else
                   "wall time not recorded."))
    sections = []
    for title, key, body in SECTIONS:
        missing = _missing(summary, key)
        blocks = missing or _guarded(body, summary[key], figure)
        sections.append({"title": title, "blocks": blocks, "failed": bool(missing)})
    failures = [{"title": s["title"], "message": s.get("message", ""),
                 "traceback": s.get("traceback", "")}
                for s in summary.get("steps", []) if s.get("status") == "failed"]
    page = t.render("demo_report.html.j2",
                    title="Pantograph: from the rig to the line (panto demo)",
                    written=time.strftime("%Y-%m-%d %H:%M"), run_line=run_line,
                    summary=_guarded(summary_blocks, summary), overview=overview,
                    steps=_guarded(_steps_blocks, summary), sections=sections,
                    failures=failures)
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def _guarded(section: Callable[..., Blocks], *args: Any) -> Blocks:
    """A section's blocks, or one line saying why it could not be drawn."""
    try:
        return section(*args)
    except Exception as error:  # noqa: BLE001 - a malformed entry must not lose the report
        return [t.paragraph(f"({section.__name__.strip('_')}: cannot show "
                            f"{type(error).__name__}: {error})", "failed")]


def _overview_blocks(out: Path, summary: Mapping[str, Any],
                     figure: Callable[..., dict]) -> Blocks:
    from panto.overview import available_panels, write_overview

    written = write_overview(out, summary)
    if written is None:
        return []
    count = len(available_panels(out, summary))
    words = dict(enumerate(("no", "one", "two", "three", "four", "five", "six")))
    vector = written.with_suffix(".svg")
    shown = vector if vector.is_file() and vector.stat().st_size < 4e6 else written
    return [figure(shown.name, f"overview: {words.get(count, count)} of the plots below, drawn "
                   f"from the steps' data (vector: {vector.name}, "
                   f"{written.with_suffix('.pdf').name})")]


def _status(summary: Mapping[str, Any], name: str) -> dict:
    return next((s for s in summary.get("steps", []) if s["name"] == name), {})


def _missing(summary: Mapping[str, Any], name: str) -> Blocks:
    if name in summary:
        return []
    step = _status(summary, name)
    return [t.paragraph(f"Step {name} {step.get('status', 'not run')}: "
                        f"{step.get('message', '')}", "failed")]


def _fits(fits: Mapping[str, Any] | None) -> str:
    return ", ".join(f"{k} {t.format_number(v, 3)} %" for k, v in (fits or {}).items()) or "–"


def _value_std(value: Any, std: Any, unit: str = "") -> str:
    """``value ± std unit`` (``value unit`` without a finite std)."""
    text = t.format_number(value, 3)
    if isinstance(std, (int, float)) and math.isfinite(std):
        text += f" ± {t.format_number(std, 2)}"
    return f"{text} {unit}".strip()


# --- the one-page summary ---------------------------------------------------------------------

def summary_blocks(summary: Mapping[str, Any]) -> Blocks:
    """The summary page: one row per step's headline, the structures and the EN 50318 table."""
    rows: Rows = []
    for key, section_rows in (("fmus", _fmu_rows), ("rig", _rig_rows), ("video", _video_rows),
                              ("identification", _identification_rows),
                              ("diagnosis", _diagnosis_rows), ("doe", _doe_rows),
                              ("cosim", _cosim_rows)):
        if summary.get(key):
            rows += _rows(section_rows, summary[key])
    failed = summary.get("failed_steps") or []
    rows.append(("Steps failed", ", ".join(failed) if failed else "none"))
    blocks = [t.table(("what", "result"), rows)]
    ident, cosim = summary.get("identification"), summary.get("cosim")
    if ident:
        blocks += [t.heading("Model structures (fit on training, then on the withheld "
                             "validation run)"), markdown_table(ident["comparison_markdown"])]
    if cosim:
        blocks += [t.heading(f"EN 50318 at {cosim['speed_kmh']:g} km/h: the line model's check "
                             "and the identified pantograph beside it"), cosim_table(cosim)]
    return blocks


def _rows(builder: Callable[[Mapping[str, Any]], Rows], part: Mapping[str, Any]) -> Rows:
    try:
        return builder(part)
    except Exception as error:  # noqa: BLE001 - one malformed entry, one row says so
        return [(builder.__name__.strip("_").replace("_rows", ""),
                 t.cell(f"cannot show {type(error).__name__}: {error}", "failed"))]


def markdown_table(text: str) -> dict[str, Any]:
    """A Markdown pipe table (as ``ComparisonTable.to_markdown`` writes) as a table block."""
    lines = [line.strip().strip("|") for line in text.strip().splitlines()
             if line.strip().startswith("|") and not set(line.strip()) <= set("|-: ")]
    rows = [[c.strip() for c in line.split("|")] for line in lines] or [[""]]
    return t.table(rows[0], rows[1:])


def _fmu_rows(fmus: Mapping[str, Any]) -> Rows:
    valid = sum(bool(f["valid"]) for f in fmus["fmus"])
    return [("FMUs built and validated (fmpy)", f"{valid} of {fmus['count']} valid")]


def _rig_rows(rig: Mapping[str, Any]) -> Rows:
    nominal = rig["nominal_model_fit_percent"].get("validation", {}).get("Pantograph", {})
    return [("Rig campaign (virtual test bed, imperfections on)", "; ".join(
                f"{k}: {v['profile']} {v['duration_s']:g} s" for k, v in rig["runs"].items())),
            ("Nominal model on the validation run (500 Hz)", _fits(nominal))]


def _video_rows(video: Mapping[str, Any]) -> Rows:
    rms = [v["video_vs_laser"]["rms_mm"] for v in video["runs"].values()]
    return [("Video synchronisation (LED)",
             (f"lowest confidence {video['min_sync_confidence']:.3f}; video vs laser "
              f"cross bar RMS {', '.join(t.format_number(r, 3) for r in rms)} mm"))]


def _identification_rows(ident: Mapping[str, Any]) -> Rows:
    physical = ident["physical"]
    ranking = ident["comparison"]["ranking_validation"]
    marked = [e["name"] for e in physical.get("estimates") or []
              if e.get("fixed") or e.get("at_bound") or e.get("verdict") != "identifiable"]
    return [("Physical model identified (physical-linear, LM): training",
             _fits(physical["fit_training"])),
            ("… validation (identified / nominal at 50 Hz)",
             (f"{_fits(physical['fit_validation'])} / "
              f"{_fits(physical['nominal_fit_validation'])}")),
            ("… parameters not pinned by the run (fixed, at a bound or weakly identifiable)",
             ", ".join(marked) or "none"),
            ("Best structure on validation", ranking[0] if ranking else "–")]


def _diagnosis_rows(diagnosis: Mapping[str, Any]) -> Rows:
    closed = ", ".join(f"{k} {100 * v:.0f} %" for k, v in diagnosis["gap_closed"].items()
                       if v is not None)
    effects = " then ".join(diagnosis["effects"] or ())
    return [("Sim-to-real diagnosis", f"{diagnosis['verdict']}"
             + (f" ({effects})" if effects else "") + "; validation fit "
             + ", ".join(f"{o} {t.format_number(diagnosis['fit_before'][o], 3)} → "
                         f"{t.format_number(diagnosis['fit_after'][o], 3)} %"
                         for o in diagnosis["fit_before"])
             + (f"; residual energy removed: {closed}" if closed else ""))]


def _doe_rows(doe: Mapping[str, Any]) -> Rows:
    return [("Next rig run (D-optimal design)",
             (f"{doe['duration_s']:g} s; parameter std of an APRBS / designed: median "
              f"{doe['median_std_ratio']:.2f}× (det ratio per parameter "
              f"{doe['det_ratio_per_parameter']:.2f})"))]


def _cosim_rows(cosim: Mapping[str, Any]) -> Rows:
    statistics = cosim["statistics"]
    checked = [r for r in statistics if r.get("target")]
    passed = [_inside(r["reference_pantograph"], r["target"]) for r in checked
              if r.get("reference_pantograph") is not None]
    check = (f"{sum(passed)} of {len(checked)} statistics inside the ranges: the line model "
             + ("passes" if sum(passed) == len(checked) else "does not pass")
             if passed else "not run (quick demo)")
    values = {r["statistic"]: r["value"] for r in statistics}
    return [(f"EN 50318 line check at {cosim['speed_kmh']:g} km/h (reference pantograph)", check),
            ("Identified pantograph on that line",
             f"mean contact force {t.format_number(values.get('mean'), 4)} N, standard "
             f"deviation {t.format_number(values.get('std'), 3)} N, contact loss "
             f"{t.format_number(values.get('loss_pct'), 2)} % (table below)")]


def _inside(value: float, target: Any) -> bool:
    """Whether `value` lies in the range ``target = (low, high)`` (rounding tolerance)."""
    return target[0] - 1e-9 <= value <= target[1] + 1e-9


def _position(value: Any, target: Any) -> str:
    """Where a statistic of a pantograph the ranges are not made for sits: no verdict."""
    if value is None or not target:
        return "–"
    low, high = target
    return "below the range" if value < low else "above the range" if value > high \
        else "within the range"


def cosim_table(cosim: Mapping[str, Any]) -> dict[str, Any]:
    """EN 50318: the range, the reference pantograph's check (pass/fail: what the standard
    tests) and the identified pantograph's statistics beside it (where they sit, no verdict)."""
    rows = []
    for row in cosim["statistics"]:
        target, reference = row.get("target"), row.get("reference_pantograph")
        if reference is None:
            check = t.cell("not run", "na")
        elif not target:
            check = "–"
        else:
            ok = _inside(reference, target)
            check = t.cell("pass" if ok else "fail", "ok" if ok else "failed")
        rows.append([row["label"], f"{target[0]:g} … {target[1]:g}" if target else "–",
                     t.format_number(reference, 4), check, t.format_number(row["value"], 4),
                     _position(row["value"], target)])
    return t.table(("statistic", "EN 50318:2002 range (reference pantograph)",
                    "reference pantograph: value", "line check", "identified pantograph: value",
                    "compared with the range"), rows)


def _steps_blocks(summary: Mapping[str, Any]) -> Blocks:
    rows = [(s["title"], t.cell(s["status"], s["status"]), f"{s['seconds']:.1f}",
             s.get("message", "")) for s in summary.get("steps", [])]
    return [t.table(("step", "status", "time [s]", "message"), rows)]


# --- the sections --------------------------------------------------------------------------------

def _rig_section(rig: Mapping[str, Any], figure: Callable[..., dict]) -> Blocks:
    rows = [(k, v["profile"], f"{v['duration_s']:g}", v["folder"], f"{v['wall_s']:.1f}")
            for k, v in rig["runs"].items()]
    return [t.table(("run", "profile", "duration [s]", "folder", "wall [s]"), rows),
            t.paragraph("Measured (grey) against the nominal nonlinear and linearised FMUs driven "
                        "by the measured inputs: the gap before any fitting."),
            *[figure(plot, f"{label} run") for label, plot in rig["plots"].items()]]


def _video_section(video: Mapping[str, Any], figure: Callable[..., dict]) -> Blocks:
    camera = video["camera"]
    rows = [(k, v["frames"], " × ".join(map(str, v["resolution"])),
             f"{v['sync_confidence']:.3f}", f"{v['peak_ratio']:.2f}", v["shift_samples"],
             t.format_number(v["video_vs_laser"]["rms_mm"], 3), v["merged_dataset"])
            for k, v in video["runs"].items()]
    return [t.paragraph(f"The synthetic camera films {camera['window_s']:g} s of each run at "
                        f"{camera['scale']:g} × the 1920 × 1080 resolution (rendering full HD "
                        "costs about 37 s per 20 s of video here); the markers are tracked, the "
                        "LED's PRBS is correlated with the 500 Hz data, and the merged dataset "
                        "is written beside the run."),
            t.table(("run", "frames", "pixels", "confidence", "peak ratio", "shift [samples]",
                     "video − laser RMS [mm]", "merged dataset"), rows),
            *[figure(run["sync_plot"], f"{label}: LED correlation")
              for label, run in video["runs"].items()]]


def estimates_blocks(physical: Mapping[str, Any]) -> Blocks:
    """The physical model's parameters: value, unit, ± (1 σ), a 95 % interval that respects
    the sign, and a mark on those at a bound, fixed or not identifiable; what was fixed, why."""
    estimates = physical.get("estimates") or []
    if not estimates:  # a summary written before the per-parameter records
        return [t.table(("parameter", "identified", "± (1 σ)"), [
            (name, t.format_number(value, 5), t.format_number(physical["std"].get(name), 3))
            for name, value in physical["parameters"].items()])]
    blocks = parameter_blocks(list(estimates), physical.get("verdict_rule"))
    fixed = physical.get("fixed_at_prior") or {}
    if fixed:
        blocks.insert(1, t.paragraph("Fixed at their prior (not identifiable from this run), "
                                     "the rest refitted: " + ", ".join(fixed) + "."))
    return blocks


def _identification_section(ident: Mapping[str, Any], figure: Callable[..., dict]) -> Blocks:
    physical = ident["physical"]
    blocks = [markdown_table(ident["comparison_markdown"]),
              figure(ident["plots"]["comparison"], "fits per structure"),
              t.heading(f"Physical model (parameter file {physical['parameter_file']})"),
              *estimates_blocks(physical),
              figure(ident["plots"]["fit"], "identified physical model")]
    pareto = ident.get("pareto") or {}
    if "plot" in pareto:
        blocks += [t.paragraph(f"NSGA-II (small population): {pareto['front_size']} "
                               f"non-dominated solutions; knee {_fits(pareto['knee_fit'])}, "
                               f"polished by LM {_fits(pareto['polished_fit'])}."),
                   figure(pareto["plot"], "Pareto front (thesis Fig. 4.7)")]
    sensitivity = ident.get("sensitivity") or {}
    if sensitivity:
        modes = ", ".join(f"{f:.2f}" for f in sensitivity["natural_frequencies_hz"])
        blocks += [t.paragraph(f"Modes {modes} Hz; most influential parameters "
                               f"{', '.join(sensitivity['ranking'][:4])}."),
                   figure(sensitivity["plot"], "eigenvalue sensitivity (thesis Fig. 4.9)")]
    return blocks


def _effect_text(step: Mapping[str, Any]) -> str:
    fitted = ", ".join(f"{k} {_value_std(v, step['std'].get(k))}"
                       for k, v in step["parameters"].items()) or "(a switch)"
    torque = step.get("hinge_torque_Nm")
    if torque:
        fitted += f" (a hinge friction torque of {_value_std(torque[0], torque[1], 'N m')})"
    return fitted


def _diagnosis_section(diagnosis: Mapping[str, Any], figure: Callable[..., dict]) -> Blocks:
    closed = diagnosis["gap_closed"]
    blocks = [t.paragraph(diagnosis["summary"]),
              t.table(("output", "validation fit before [%]", "after [%]",
                       "residual energy removed [%]"),
                      [(o, t.format_number(diagnosis["fit_before"][o], 3),
                        t.format_number(diagnosis["fit_after"][o], 3),
                        "–" if closed.get(o) is None else f"{100 * closed[o]:.0f}")
                       for o in diagnosis["fit_before"]])]
    steps = diagnosis.get("steps") or []
    if steps:
        blocks += [t.paragraph("Found effects, in the order accepted (each refitted with the "
                               "nominal's parameters on the training run, judged on the withheld "
                               "validation run):"),
                   t.table(("effect", "fitted (± 1 σ)", "validation fit after [%]"), [
                       (s["effect"], _effect_text(s), _fits(s["fit_after"])) for s in steps])]
    truth = diagnosis.get("rig_truth") or []
    if truth:
        blocks += [t.paragraph("What the virtual rig hid (its truth record; the diagnosis never "
                               "sees it):"),
                   t.table(("imperfection", "value", "library effect", "named"), [
                       (r["imperfection"], "on" if isinstance(r["value"], bool)
                        else t.format_number(r["value"], 4), r["effect"] or "(none)",
                        "yes" if r["named"] else "no") for r in truth])]
    blocks += [{"kind": "link", "before": "Full diagnosis report: ", "href": diagnosis["report"],
                "text": diagnosis["report"], "after": ""},
               figure(diagnosis["plot"], "validation run: before and after")]
    return blocks


def _doe_section(doe: Mapping[str, Any], figure: Callable[..., dict]) -> Blocks:
    units = doe.get("units") or {}
    rows = [(r["parameter"], t.format_number(r["value"], 4), units.get(r["parameter"], "–"),
             t.format_number(r["std_designed"], 3), t.format_number(r["std_conventional"], 3),
             f"{r['ratio_conventional_to_designed']:.2f}") for r in doe["table"]]
    return [t.paragraph(f"{doe['criterion']}-optimal motor position and pressure demand for the "
                        f"physical model's parameters ({doe['parameters_from']} values), "
                        f"{doe['duration_s']:g} s, as a rig profile: "
                        f"{doe['files'].get('profile', '')}."),
            t.table(("parameter", "value", "unit", "std designed", "std APRBS",
                     "ratio APRBS / designed"), rows),
            t.paragraph("Standard deviations predicted from the Fisher information, in the "
                        "parameter's unit.", "note"),
            *[figure(plot) for plot in doe["plots"]]]


def _cosim_section(cosim: Mapping[str, Any], figure: Callable[..., dict]) -> Blocks:
    reference = any(r.get("reference_pantograph") is not None for r in cosim["statistics"])
    return [t.paragraph(f"{cosim['line']} line at {cosim['speed_kmh']:g} km/h, the Pantograph "
                        f"FMU with the {cosim['parameters_from']} parameters, bellow pressure "
                        f"{cosim['pressure_bar']:.2f} bar (static contact force "
                        f"{cosim['static_force_N']:g} N at 2 m, as the reference pantograph's "
                        f"uplift). {cosim['message']}."),
            t.paragraph("What the ranges are: EN 50318 validates a simulation of the catenary "
                        "by running the standard's reference pantograph on the reference line; "
                        "its ranges are the check of the line model, not acceptance limits for "
                        "another pantograph. The reference pantograph's column is that check "
                        "(pass/fail); the identified pantograph's statistics stand beside it to "
                        "show where this pantograph differs, without a verdict."
                        + ("" if reference else " The reference pantograph was "
                           "not run here (the quick demo leaves it out).")),
            cosim_table(cosim), *[figure(plot) for plot in cosim["plots"]]]


#: The report's sections after the summary: heading, the summary's key, the body builder.
SECTIONS = (("1-2. FMUs and the rig campaign: trajectories", "rig", _rig_section),
            ("2. Camera video: tracking and synchronisation", "video", _video_section),
            ("3. Identification: fit table, Pareto front, eigenvalues", "identification",
             _identification_section),
            ("4. Sim-to-real diagnosis", "diagnosis", _diagnosis_section),
            ("5. The next rig run (design of experiments)", "doe", _doe_section),
            ("6. The identified pantograph on the line: contact force", "cosim", _cosim_section))
