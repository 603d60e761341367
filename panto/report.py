"""The main job's HTML report: a one-page summary at the top, then one section per step.

:func:`write_report` reads the summary :func:`panto.demo.run_demo` writes (``summary.json``) and
the plots in the output folder, and writes ``report.html`` beside them. The images are embedded
(base64), so the single file can be mailed or attached; the plots also stay as PNG files. A
failed step shows its message and the start of its traceback instead of its results.
"""
from __future__ import annotations

import base64
import html
import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;
text-align:right}th{background:#eee}td:first-child,th:first-child{text-align:left}
.ok{color:#060}.failed,.outside{color:#b00;font-weight:bold}.skipped{color:#a60}
img{max-width:100%;border:1px solid #ddd;margin:.4em 0}pre{background:#f6f6f6;padding:.5em;
overflow-x:auto}.summary{background:#f4f8fc;border:1px solid #9bc;padding:.2em 1em 1em}
"""


def write_report(summary: Mapping[str, Any], out: str | Path, *, embed: bool = True) -> Path:
    """Write ``out/report.html`` from the demo's summary; returns its path.

    Parameters
    ----------
    summary : mapping
        What :func:`panto.demo.run_demo` returns (and writes to ``summary.json``).
    out : str or pathlib.Path
        The demo's output folder (the plots are read from there).
    embed : bool
        Embed the images as base64 (default); False links the PNG files instead.
    """
    from panto.overview import write_overview

    out = Path(out)
    overview = write_overview(out)
    parts = [(f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>panto demo</title>"
             f"<style>{_STYLE}</style></head><body>"),
             "<h1>Pantograph: from the rig to the line (panto demo)</h1>",
             (f"<p>{'Quick' if summary.get('quick') else 'Full'} run, "
             f"{time.strftime('%Y-%m-%d %H:%M')}, {summary.get('wall_time_s', math.nan):.0f} s "
             "on this machine.</p>"),
             _guarded(_summary_page, summary),
             _image(out, overview.name, embed, "overview: six of the plots below")
             if overview else "", _guarded(_steps_table, summary)]
    for title, key, body in _SECTIONS:
        parts.append(_guarded(_section, summary, out, embed, title, key, body))
    parts.append(_guarded(_failures_section, summary, out, embed))
    parts.append("</body></html>")
    path = out / "report.html"
    path.write_text("\n".join(parts), encoding="utf-8")
    return path


def _guarded(section: Any, *args: Any) -> str:
    """A section, or a line saying why it could not be drawn (the rest of the report stays)."""
    try:
        return section(*args)
    except Exception as error:  # noqa: BLE001 - a malformed entry must not lose the report
        name = args[-1].__name__ if section is _section else section.__name__
        return (f"<p class='failed'>({_e(name.strip('_'))}: cannot show "
                f"{type(error).__name__}: {_e(error)})</p>")


def _section(summary: Mapping[str, Any], out: Path, embed: bool, title: str, key: str,
             body: Any) -> str:
    """One step's section: its heading, then its body, or why the step has no results."""
    missing = _missing(summary, key)
    parts = [missing] if missing else body(summary[key], out, embed)
    return "\n".join([f"<h2>{title}</h2>", *parts])


# --- building blocks ----------------------------------------------------------------------------

def _e(value: Any) -> str:
    return html.escape(str(value))


def _number(value: Any, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    if isinstance(value, (int, float)):
        return f"{value:.{digits}f}"
    return _e(value)


def _parameter(value: float, std: float | None) -> str:
    return f"{value:.3g} ± {std:.2g}" if std is not None and math.isfinite(std) \
        else f"{value:.3g}"


def table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """An HTML table; cells already holding HTML (``<span``) are kept, others escaped."""
    def cell(value: Any) -> str:
        text = str(value)
        return text if text.startswith("<span") else _e(text)

    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def markdown_table(text: str) -> str:
    """A Markdown pipe table (as ``ComparisonTable.to_markdown`` writes) as HTML."""
    lines = [line.strip().strip("|") for line in text.strip().splitlines()
             if line.strip().startswith("|") and not set(line.strip()) <= set("|-: ")]
    if not lines:
        return ""
    rows = [[cell.strip() for cell in line.split("|")] for line in lines]
    return table(rows[0], rows[1:])


def _image(out: Path, relative: str | None, embed: bool, caption: str = "") -> str:
    if not relative or not (out / relative).is_file():
        return f"<p><em>(no plot {_e(relative or caption)})</em></p>"
    if embed:
        data = base64.b64encode((out / relative).read_bytes()).decode("ascii")
        source = f"data:image/png;base64,{data}"
    else:
        source = _e(relative)
    label = f"<br><small>{_e(caption or relative)}</small>"
    return f"<figure><img src='{source}' alt='{_e(relative)}'>{label}</figure>"


def _status(summary: Mapping[str, Any], name: str) -> dict:
    return next((s for s in summary.get("steps", []) if s["name"] == name), {})


def _missing(summary: Mapping[str, Any], name: str) -> str | None:
    step = _status(summary, name)
    if name in summary:
        return None
    return (f"<p class='failed'>Step {_e(name)} {_e(step.get('status', 'not run'))}: "
            f"{_e(step.get('message', ''))}</p>")


def _fits(fits: Mapping[str, Any] | None) -> str:
    return ", ".join(f"{k} {_number(v)} %" for k, v in (fits or {}).items()) or "–"


# --- the one-page summary ---------------------------------------------------------------------

def _summary_page(summary: Mapping[str, Any]) -> str:
    rows = []
    for key, section_rows in (("fmus", _fmu_rows), ("rig", _rig_rows), ("video", _video_rows),
                              ("identification", _identification_rows),
                              ("diagnosis", _diagnosis_rows), ("doe", _doe_rows),
                              ("cosim", _cosim_rows)):
        if summary.get(key):
            rows += section_rows(summary[key])
    failed = summary.get("failed_steps") or []
    rows.append(("Steps failed", ", ".join(failed) if failed else "none"))
    parts = ["<div class='summary'><h2>Summary</h2>", table(("what", "result"), rows)]
    ident, cosim = summary.get("identification"), summary.get("cosim")
    if ident:
        parts += [("<h3>Model structures (fit on training, then on the withheld validation "
                  "run)</h3>"), markdown_table(ident["comparison_markdown"])]
    if cosim:
        parts += [(f"<h3>EN 50318 statistics at {cosim['speed_kmh']:g} km/h, identified "
                  "pantograph</h3>"), _cosim_table(cosim)]
    parts.append("</div>")
    return "\n".join(parts)


Rows = list[tuple[str, str]]


def _fmu_rows(fmus: Mapping[str, Any]) -> Rows:
    valid = sum(f["valid"] for f in fmus["fmus"])
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
              f"cross bar RMS {', '.join(_number(r, 2) for r in rms)} mm"))]


def _identification_rows(ident: Mapping[str, Any]) -> Rows:
    physical = ident["physical"]
    ranking = ident["comparison"]["ranking_validation"]
    return [("Physical model identified (physical-linear, LM): training",
             _fits(physical["fit_training"])),
            ("… validation (identified / nominal at 50 Hz)",
             (f"{_fits(physical['fit_validation'])} / "
              f"{_fits(physical['nominal_fit_validation'])}")),
            ("Best structure on validation", ranking[0] if ranking else "–")]


def _diagnosis_rows(diagnosis: Mapping[str, Any]) -> Rows:
    closed = ", ".join(f"{k} {100 * v:.0f} %" for k, v in diagnosis["gap_closed"].items()
                       if v is not None)
    return [("Sim-to-real diagnosis", f"{diagnosis['verdict']} "
             f"{diagnosis['effects'] or ''}; validation fit "
             + ", ".join(f"{o} {_number(diagnosis['fit_before'][o])} → "
                         f"{_number(diagnosis['fit_after'][o])} %"
                         for o in diagnosis["fit_before"])
             + (f"; residual energy removed: {closed}" if closed else ""))]


def _doe_rows(doe: Mapping[str, Any]) -> Rows:
    return [("Next rig run (D-optimal design)",
             (f"{doe['duration_s']:g} s; parameter std of an APRBS / designed: median "
              f"{doe['median_std_ratio']:.2f}× (det ratio per parameter "
              f"{doe['det_ratio_per_parameter']:.2f})"))]


def _cosim_rows(cosim: Mapping[str, Any]) -> Rows:
    return [(f"EN 50318 line at {cosim['speed_kmh']:g} km/h",
             f"identified pantograph: {cosim['inside']} of {len(cosim['statistics'])} "
             "statistics inside the acceptance ranges"
             + (f"; EN 50318 reference pantograph (line check): "
                f"{cosim['reference_inside']} of {len(cosim['statistics'])}"
                if cosim.get("reference_inside") is not None else "")
             + " (table below)")]


def _cosim_table(cosim: Mapping[str, Any]) -> str:
    rows = []
    reference = any(row.get("reference_pantograph") is not None for row in cosim["statistics"])
    for row in cosim["statistics"]:
        target = row["target"]
        verdict = ("<span class='ok'>inside</span>" if row["inside"]
                   else "<span class='outside'>outside</span>") if target else "–"
        cells = [row["label"], _number(row["value"]), verdict,
                 f"{target[0]:g} … {target[1]:g}" if target else "–"]
        if reference:
            cells.append(_number(row.get("reference_pantograph")))
        rows.append(cells)
    header = ["statistic", "identified pantograph", "", "EN 50318:2002 range"]
    return table(header + (["reference pantograph (line check)"] if reference else []), rows)


def _steps_table(summary: Mapping[str, Any]) -> str:
    rows = [(s["title"], f"<span class='{s['status']}'>{_e(s['status'])}</span>",
             f"{s['seconds']:.1f}", s.get("message", "")) for s in summary.get("steps", [])]
    return "<h2>Steps</h2>" + table(("step", "status", "time [s]", "message"), rows)


# --- the sections --------------------------------------------------------------------------------

def _rig_section(rig: Mapping[str, Any], out: Path, embed: bool) -> list[str]:
    parts = []
    rows = [(k, v["profile"], f"{v['duration_s']:g}", v["folder"], f"{v['wall_s']:.1f}")
            for k, v in rig["runs"].items()]
    parts.append(table(("run", "profile", "duration [s]", "folder", "wall [s]"), rows))
    parts.append("<p>Measured (grey) against the nominal nonlinear and linearised FMUs driven by "
                 "the measured inputs: the gap before any fitting.</p>")
    for label, plot in rig["plots"].items():
        parts.append(_image(out, plot, embed, f"{label} run"))
    return parts


def _video_section(video: Mapping[str, Any], out: Path, embed: bool) -> list[str]:
    parts = []
    camera = video["camera"]
    parts.append(f"<p>The synthetic camera films {camera['window_s']:g} s of each run at "
                 f"{camera['scale']:g}× the 1920×1080 resolution (rendering full HD costs about "
                 "37 s per 20 s of video here); the markers are tracked, the LED's PRBS is "
                 "correlated with the 500 Hz data, and the merged dataset is written beside the "
                 "run.</p>")
    rows = [(k, v["frames"], "×".join(map(str, v["resolution"])), f"{v['sync_confidence']:.3f}",
             f"{v['peak_ratio']:.2f}", v["shift_samples"],
             _number(v["video_vs_laser"]["rms_mm"], 2), v["merged_dataset"])
            for k, v in video["runs"].items()]
    parts.append(table(("run", "frames", "pixels", "confidence", "peak ratio", "shift [samples]",
                        "video − laser RMS [mm]", "merged dataset"), rows))
    for label, run in video["runs"].items():
        parts.append(_image(out, run["sync_plot"], embed, f"{label}: LED correlation"))
    return parts


def _estimates_table(physical: Mapping[str, Any]) -> list[str]:
    """Value, unit, ±, 95 % interval and verdict per fitted parameter; what was fixed and why."""
    estimates = physical.get("estimates") or []
    if not estimates:  # a summary written before the per-parameter records
        rows = [(name, f"{value:.5g}", _number(physical["std"].get(name), 3))
                for name, value in physical["parameters"].items()]
        return [table(("parameter", "identified", "std"), rows)]
    def interval(e: Mapping[str, Any]) -> str:
        low, high = e["interval_95"]
        return "–" if low is None or high is None else f"[{low:.4g}, {high:.4g}]"
    rows = [(e["name"], f"{e['value']:.5g}", e["unit"],
             f"{e['std']:.3g}" if e["std"] is not None else "–", interval(e),
             e["verdict"] if e["status"] == "estimated" else f"{e['verdict']}; {e['status']}")
            for e in estimates]
    parts = [table(("parameter", "value", "unit", "± (1 σ)", "95 % interval", "verdict"), rows)]
    fixed = physical.get("fixed_at_prior") or {}
    if fixed:
        parts.append("<p>Fixed at their prior (not identifiable from this run), the rest "
                     "refitted: " + _e("; ".join(f"{n}: {why}" for n, why in fixed.items()))
                     + "</p>")
    if physical.get("verdict_rule"):
        parts.append(f"<p><small>Verdicts: {_e(physical['verdict_rule'])}.</small></p>")
    return parts


def _identification_section(ident: Mapping[str, Any], out: Path, embed: bool) -> list[str]:
    parts = []
    physical = ident["physical"]
    parts.append(markdown_table(ident["comparison_markdown"]))
    parts.append(_image(out, ident["plots"]["comparison"], embed, "fits per structure"))
    parts.append(f"<h3>Physical model (parameter file {_e(physical['parameter_file'])})</h3>")
    parts += _estimates_table(physical)
    parts.append(_image(out, ident["plots"]["fit"], embed, "identified physical model"))
    pareto = ident.get("pareto") or {}
    if "plot" in pareto:
        parts.append(f"<p>NSGA-II (small population): {pareto['front_size']} non-dominated "
                     f"solutions; knee {_fits(pareto['knee_fit'])}, polished by LM "
                     f"{_fits(pareto['polished_fit'])}.</p>")
        parts.append(_image(out, pareto["plot"], embed, "Pareto front (thesis Fig. 4.7)"))
    sensitivity = ident.get("sensitivity") or {}
    if sensitivity:
        modes = ", ".join(f"{f:.2f}" for f in sensitivity["natural_frequencies_hz"])
        parts.append(f"<p>Modes {modes} Hz; most influential parameters "
                     f"{_e(sensitivity['ranking'][:4])}.</p>")
        parts.append(_image(out, sensitivity["plot"], embed,
                            "eigenvalue sensitivity (thesis Fig. 4.9)"))
    return parts


def _diagnosis_section(diagnosis: Mapping[str, Any], out: Path, embed: bool) -> list[str]:
    parts = []
    parts.append(f"<p>{_e(diagnosis['summary'])}</p>")
    rows = [(o, _number(diagnosis["fit_before"][o]), _number(diagnosis["fit_after"][o]),
             _number(None if diagnosis["gap_closed"].get(o) is None
                     else 100 * diagnosis["gap_closed"][o], 0))
            for o in diagnosis["fit_before"]]
    parts.append(table(("output", "validation fit before [%]", "after [%]",
                        "residual energy removed [%]"), rows))
    steps = diagnosis.get("steps") or []
    if steps:
        parts.append("<p>Found effects, in the order accepted (each refitted with the nominal's "
                     "parameters on the training run, judged on the withheld validation run):</p>")
        parts.append(table(("effect", "fitted", "validation fit after [%]"), [
            (s["effect"], (", ".join(f"{k} {_parameter(v, s['std'].get(k))}"
                                     for k, v in s["parameters"].items()) or "(a switch)")
             + (f" (a hinge friction torque of {_parameter(*s['hinge_torque_Nm'])} N m)"
                if s.get("hinge_torque_Nm") else ""),
             ", ".join(f"{o} {_number(v)}" for o, v in s["fit_after"].items()))
            for s in steps]))
    truth = diagnosis.get("rig_truth") or []
    if truth:
        parts.append("<p>What the virtual rig hid (its truth record; the diagnosis never sees "
                     "it):</p>")
        parts.append(table(("imperfection", "value", "library effect", "named"), [
            (r["imperfection"], "on" if isinstance(r["value"], bool) else f"{r['value']:g}",
             r["effect"] or "(none)",
             "yes" if r["named"] else "no") for r in truth]))
    parts.append(f"<p>Full diagnosis report: <a href='{_e(diagnosis['report'])}'>"
                 f"{_e(diagnosis['report'])}</a></p>")
    parts.append(_image(out, diagnosis["plot"], embed, "validation run: before and after"))
    return parts


def _doe_section(doe: Mapping[str, Any], out: Path, embed: bool) -> list[str]:
    parts = []
    parts.append(f"<p>{doe['criterion']}-optimal motor position and pressure demand for the "
                 f"physical model's parameters ({_e(doe['parameters_from'])} values), "
                 f"{doe['duration_s']:g} s, as a rig profile: "
                 f"<code>{_e(doe['files'].get('profile', ''))}</code>.</p>")
    rows = [(r["parameter"], f"{r['value']:.4g}", f"{r['std_designed']:.3g}",
             f"{r['std_conventional']:.3g}", f"{r['ratio_conventional_to_designed']:.2f}")
            for r in doe["table"]]
    parts.append(table(("parameter", "value", "std designed", "std APRBS", "ratio"), rows))
    for plot in doe["plots"]:
        parts.append(_image(out, plot, embed))
    return parts


def _cosim_section(cosim: Mapping[str, Any], out: Path, embed: bool) -> list[str]:
    parts = []
    parts.append(f"<p>{_e(cosim['line'])} line at {cosim['speed_kmh']:g} km/h, the Pantograph "
                 f"FMU with the {_e(cosim['parameters_from'])} parameters, bellow pressure "
                 f"{cosim['pressure_bar']:.2f} bar (static contact force "
                 f"{cosim['static_force_N']:g} N at 2 m, as the reference pantograph's uplift). "
                 "The acceptance ranges are those of the EN 50318 reference pantograph: they "
                 "check the line model, and show where this pantograph differs. "
                 f"{_e(cosim['message'])}.</p>")
    parts.append(_cosim_table(cosim))
    for plot in cosim["plots"]:
        parts.append(_image(out, plot, embed))
    return parts


def _failures_section(summary: Mapping[str, Any], out: Path, embed: bool) -> str:
    failed = [s for s in summary.get("steps", []) if s["status"] == "failed"]
    if not failed:
        return ""
    parts = ["<h2>Failures</h2>"]
    for step in failed:
        parts.append(f"<h3 class='failed'>{_e(step['title'])}</h3><p>{_e(step['message'])}</p>"
                     f"<pre>{_e(step.get('traceback', ''))}</pre>")
    return "\n".join(parts)


#: The report's sections after the summary: heading, the summary's key, the body builder.
_SECTIONS = (("1-2. FMUs and the rig campaign: trajectories", "rig", _rig_section),
             ("2. Camera video: tracking and synchronisation", "video", _video_section),
             ("3. Identification: fit table, Pareto front, eigenvalues", "identification",
              _identification_section),
             ("4. Sim-to-real diagnosis", "diagnosis", _diagnosis_section),
             ("5. The next rig run (design of experiments)", "doe", _doe_section),
             ("6. The identified pantograph on the line: contact force", "cosim", _cosim_section))
