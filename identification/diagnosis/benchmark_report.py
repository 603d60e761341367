"""Files of the diagnosis benchmark (:mod:`panto.identification.diagnosis.benchmark`): JSON for scripts,
markdown for people, and a confusion-matrix PNG."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping

from panto.identification.diagnosis.benchmark import BenchmarkResult, describe_scores


def write_benchmark(result: BenchmarkResult, json_path: str | Path,
                    markdown_path: str | Path | None = None,
                    png_path: str | Path | None = None) -> dict[str, Path]:
    """Write the JSON (and the markdown and PNG beside it unless given); return the paths."""
    json_path = Path(json_path)
    json_path.parent.mkdir(parents=True, exist_ok=True)
    markdown_path = Path(markdown_path) if markdown_path else json_path.with_suffix(".md")
    png_path = Path(png_path) if png_path else json_path.with_name(json_path.stem + "_confusion.png")
    json_path.write_text(json.dumps(result.to_dict(), indent=2))
    plot_confusion(result.confusion, png_path)
    markdown_path.write_text(format_markdown(result, png_path.name))
    return {"json": json_path, "markdown": markdown_path, "png": png_path}


def _labels(confusion: Mapping[str, Mapping[str, int]]) -> tuple[list[str], list[str]]:
    from panto.identification.diagnosis.benchmark import LIBRARY_DRAW, OUTSIDE_DRAW

    order = list(LIBRARY_DRAW) + ["none"] + list(OUTSIDE_DRAW)
    rows = [r for r in order if r in confusion] + sorted(set(confusion) - set(order))
    predicted = {p for row in confusion.values() for p in row}
    columns = [c for c in order if c in predicted] + sorted(
        predicted - set(order) - {"unexplained", "error"}) + \
        [c for c in ("unexplained", "error") if c in predicted]
    return rows, columns


def plot_confusion(confusion: Mapping[str, Mapping[str, int]], path: str | Path) -> Path:
    """The confusion matrix as a PNG (rows: hidden effect, columns: the diagnosis' answer)."""
    import numpy as np
    from matplotlib.figure import Figure

    rows, columns = _labels(confusion)
    counts = np.array([[confusion[r].get(c, 0) for c in columns] for r in rows], float)
    figure = Figure(figsize=(max(4.0, 1.5 + 0.8 * len(columns)), max(3.0, 1.5 + 0.5 * len(rows))))
    axes = figure.subplots()
    axes.imshow(counts, cmap="Blues")
    for i in range(len(rows)):
        for j in range(len(columns)):
            if counts[i, j]:
                axes.text(j, i, f"{int(counts[i, j])}", ha="center", va="center",
                          color="white" if counts[i, j] > counts.max() / 2 else "black")
    axes.set_xticks(range(len(columns)), columns, rotation=45, ha="right")
    axes.set_yticks(range(len(rows)), rows)
    axes.set_xlabel("diagnosis (first effect or verdict)")
    axes.set_ylabel("hidden effect")
    axes.set_title("Diagnosis benchmark: confusion matrix")
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    figure.savefig(path, dpi=110)
    return Path(path)


def _pct(value: Any) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{100 * value:.0f} %"


def format_markdown(result: BenchmarkResult, png_name: str) -> str:
    """The report: settings, scores against the goals, confusion matrix, the cases."""
    s, settings = result.scores, result.settings
    lines = ["# Sim-to-real diagnosis: blind benchmark on the virtual test bed", "",
             f"`panto diagnose-benchmark --cases {settings.get('cases')} --seed "
             f"{settings.get('seed')} --duration {settings.get('duration_s')}`: nominal "
             f"`{settings.get('structure')}`, training and a different validation run (another "
             "APRBS realisation) per case, diagnosed blind (truth metadata stripped). Wall time "
             f"{s.get('wall_time_s', math.nan):.0f} s.", "",
             "| score | value | cases | goal |", "|---|---|---|---|",
             "| top-1 on library effects costing the model >= "
             f"{settings.get('strong_fit_points')} fit points | {_pct(s['top1_accuracy'])} | "
             f"{s['strong_cases']} | >= 90 % |",
             f"| top-1 on all library cases | {_pct(s['top1_accuracy_all_library'])} | "
             f"{s['library_cases']} | |",
             f"| false alarms on `none` (an effect named) | {_pct(s['false_alarm_rate'])} | "
             f"{s['none_cases']} | <= 5 % |",
             f"| `none` answered `unexplained` | {_pct(s['none_unexplained_rate'])} | "
             f"{s['none_cases']} | |",
             f"| `unexplained` on out-of-library effects | {_pct(s['unexplained_rate_outside'])}"
             f" | {s['outside_cases']} | >= 80 % |",
             f"| gap closed on validation (median, correctly named strong cases) | "
             f"{_pct(s['gap_closed_median'])} | | >= 80 % |", "",
             describe_scores(s) + ".", "", f"![confusion matrix]({png_name})", "",
             "## Confusion matrix (rows: hidden effect; columns: answer)", ""]
    rows, columns = _labels(result.confusion)
    lines += ["| hidden \\ answer | " + " | ".join(columns) + " |",
              "|---" * (len(columns) + 1) + "|"]
    lines += [f"| {r} | " + " | ".join(str(result.confusion[r].get(c, "")) for c in columns) + " |"
              for r in rows]
    lines += ["", "## Cases", "",
              "| # | hidden | magnitude | cost to the model [fit pts] | signal [fit pts] | verdict "
              "| effects | fit clean / before -> after | gap closed | time [s] |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for o in result.outcomes:
        fits = ", ".join(f"{k} {o.fit_clean.get(k, math.nan):.1f} / {o.fit_before[k]:.1f}->"
                         f"{o.fit_after[k]:.1f}" for k in o.fit_before)
        lines.append(f"| {o.case.index + 1} | {o.case.label} | {o.case.magnitude:.3g} | "
                     f"{o.cost:.1f} | {o.signal_cost:.1f} | {o.verdict} | {', '.join(o.effects)} "
                     f"| {fits} | "
                     f"{_pct(o.gap_closed)} | {o.wall_time:.0f} |")
    return "\n".join(lines) + "\n"


__all__ = ["write_benchmark", "plot_confusion", "format_markdown"]
