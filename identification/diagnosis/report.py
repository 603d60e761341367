"""The diagnosis as files a person opens: ``report.html`` (self-contained, plots embedded as PNG)
and ``report.json`` (:meth:`~panto.identification.diagnosis.pipeline.Diagnosis.to_dict`), plus the PNGs beside
them.

The HTML answers the three questions in order: where the gap lies (validation fit, the residual
spectra, error model, segments and correlations of the nominal model), which effect causes it
(the FROLS ranking per round and every refitted candidate with its tests), how far it shrinks
(fit before/after per output, band and segment energy before/after, effect parameters).
"""
from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from panto.identification.diagnosis.residual_plots import plot_bands, plot_output_analysis, plot_series


def _number(value: Any, digits: int = 4) -> str:
    if isinstance(value, (int, float, np.floating)) and not isinstance(value, bool):
        return "-" if not math.isfinite(float(value)) else f"{float(value):.{digits}g}"
    return html.escape(str(value))


def _table(header: list[str], rows: list[list[Any]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{_number(c)}</td>" for c in row) + "</tr>"
                   for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _image(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img src="data:image/png;base64,{data}" alt="{html.escape(path.name)}">'


def write_report(diagnosis: Any, folder: str | Path) -> dict[str, Path]:
    """Write ``report.json``, the PNG plots and ``report.html`` into `folder`; returns the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    json_path = folder / "report.json"
    json_path.write_text(json.dumps(diagnosis.to_dict(), indent=2))
    images = [plot_series(diagnosis, folder / "validation.png")]
    bands = plot_bands(diagnosis, folder / "bands.png")
    where_images = []
    for analysis in diagnosis.analysis_before:
        where_images += [Path(p) for p in plot_output_analysis(
            analysis, folder / f"nominal_{analysis.output_name}")]
    parts = [_head(diagnosis), "<h2>1. Where the gap lies (nominal model, validation run)</h2>",
             f"<p>{html.escape(diagnosis.where.get('text', ''))}</p>",
             "<p>Gap " + ("significant: " + html.escape("; ".join(diagnosis.gap["reasons"]))
                          if diagnosis.gap["significant"] else "within the noise") + "</p>",
             _image(images[0])] + [_image(p) for p in where_images]
    parts += ["<h2>2. Which effect: ranking on the training residual and refits</h2>"]
    for index, round_ in enumerate(diagnosis.rounds):
        parts.append(f"<h3>Round {index + 1}</h3>")
        for output, ranking in round_["ranking"].items():
            rows = [[c["effect"], c["variant"], c["err"], c["significant"]]
                    for c in ranking["candidates"][:6]]
            parts.append(f"<p>FROLS on {html.escape(output)}</p>" +
                         _table(["effect", "variant", "ERR", "significant"], rows))
        rows = [[t["effect"], t["description"], t["delta_bic"], t["significance"],
                 t["improvement"], t["fold_spread"], "accepted" if t["accepted"] else
                 "; ".join(t["failed"])] for t in round_["tried"]]
        parts.append(_table(["effect", "augmentation", "dBIC", "|theta|/sigma",
                             "validation +points", "fold spread", "decision"], rows))
    parts.append("<h2>3. How far the gap shrinks (validation run)</h2>")
    parts.append(_table(["output", "fit before [%]", "fit after [%]", "share of residual energy removed"],
                        [[o, diagnosis.fit_before[o], diagnosis.fit_after[o],
                          diagnosis.gap_closed()[o]] for o in diagnosis.output_names]))
    for step in diagnosis.steps:
        rows = [[n, v, step.std.get(n, math.nan)] for n, v in step.parameters.items()]
        parts.append(f"<h3>{html.escape(step.effect)}</h3><p>{html.escape(step.description)}</p>"
                     + _table(["parameter", "value", "std"], rows)
                     + _table(["output", "fit before", "fit after", "energy removed"],
                              [[o, step.fit_before[o], step.fit_after[o], step.energy_removed[o]]
                               for o in step.fit_before]))
    if bands is not None:
        parts.append(_image(bands))
    if diagnosis.steps:
        parts.append("<p>Remaining gap: " + (html.escape("; ".join(diagnosis.remaining_gap["reasons"]))
                                             if diagnosis.remaining_gap["significant"]
                                             else "within the noise") + "</p>")
    html_path = folder / "report.html"
    html_path.write_text("<!DOCTYPE html><html><head><meta charset='utf-8'><title>Diagnosis</title>"
                         "<style>body{font-family:sans-serif;max-width:1000px;margin:auto}"
                         "table{border-collapse:collapse;margin:6px 0}td,th{border:1px solid #bbb;"
                         "padding:2px 6px;font-size:13px}img{max-width:100%}</style></head><body>"
                         + "\n".join(parts) + "</body></html>")
    return {"json": json_path, "html": html_path, "images": images + where_images +
            ([bands] if bands else [])}


def _head(diagnosis: Any) -> str:
    verdict = {"effect": "effect(s) found", "none": "none: the gap is within the noise",
               "unexplained": "unexplained: a significant gap no candidate closes"}[diagnosis.verdict]
    return (f"<h1>Sim-to-real gap diagnosis: {html.escape(diagnosis.structure)}</h1>"
            f"<p><b>Verdict: {html.escape(verdict)}</b>"
            + (f" &mdash; {html.escape(' then '.join(diagnosis.effects))}" if diagnosis.effects else "")
            + f"</p><p>{html.escape(diagnosis.summary)}</p>"
            + _next_experiment(diagnosis)
            + f"<p>Wall time {diagnosis.wall_time:.1f} s.</p>")


def _next_experiment(diagnosis: Any) -> str:
    suggestion = diagnosis.next_experiment()
    if not suggestion:
        return ""
    return (f"<p>Next experiment ({html.escape(suggestion['effect'])}, "
            f"{html.escape(suggestion['status'])}): <code>{html.escape(suggestion['command'])}"
            f"</code> &mdash; {html.escape(suggestion['why'])}.</p>")


__all__ = ["write_report"]
