"""The demo's one-picture overview, drawn from the data the steps saved (not from their PNGs).

Six panels, each a matplotlib subfigure drawing the numbers the demo's steps wrote into its
folder: the identified model against the rig (``identification/fit_validation.csv``), the
NSGA-II Pareto front (``summary.json``), the diagnosis before and after
(``diagnosis/validation_series.csv``), the predicted parameter standard deviations of the designed
run against an APRBS (``doe/doe_summary.json``), the video track against the lasers after the LED
synchronisation (the merged dataset) and the contact force along the analysed section of the
EN 50318 line (``cosim/*.csv``; the settling span before the section is left out, so the
start-up transient does not set the scale). Every axis carries its unit, legends sit above the
data. Written as ``overview.svg`` and ``overview.pdf`` (vector) and ``overview.png`` (the
README's). A panel whose data a failed step did not write says so in place.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

#: Display unit and factor from SI per pantograph output.
OUTPUT_UNITS = {"F_c": ("N", 1.0), "y_cb": ("mm", 1e3), "xi": ("mm", 1e3)}
#: Points per drawn line at most (min/max per bucket keeps the envelope); keeps the SVG small.
MAX_POINTS = 1500
#: Resolution of ``overview.png`` [dots per inch].
PNG_DPI = 100


def write_overview(out: str | Path, summary: Mapping[str, Any] | None = None,
                   name: str = "overview") -> Path | None:
    """Draw the overview of the demo folder `out` into ``name.svg``, ``.pdf`` and ``.png``.

    Parameters
    ----------
    out : str or pathlib.Path
        The demo's output folder.
    summary : mapping, optional
        The demo's summary (default: ``out/summary.json``).
    name : str
        File stem of the pictures.

    Returns
    -------
    pathlib.Path or None
        The PNG, or None when no panel has data.
    """
    out = Path(out)
    if summary is None:
        path = out / "summary.json"
        summary = json.loads(path.read_text()) if path.is_file() else {}
    figure = draw_overview(out, summary)
    if figure is None:
        return None
    lay_out_once(figure, PNG_DPI)
    for suffix in (".svg", ".pdf"):
        figure.savefig(out / f"{name}{suffix}")
    target = out / f"{name}.png"
    figure.savefig(target, dpi=PNG_DPI)
    return target


def lay_out_once(figure: Any, dpi: float) -> None:
    """Run `figure`'s layout engine once, at `dpi` [dots per inch], then switch it off.

    Each save of a figure with a layout engine lays it out again and draws it twice (once
    unrendered for the layout); laid out once here, the three saves (SVG, PDF, PNG) draw once
    each. The PNG at `dpi` gets the layout its own save would have computed.

    Parameters
    ----------
    figure : matplotlib.figure.Figure
        The drawn figure, its layout engine (if any) not yet run.
    dpi : float
        Resolution the layout is computed at [dots per inch].
    """
    from matplotlib import rc_context

    figure.set_dpi(dpi)
    engine = figure.get_layout_engine()
    if engine is not None:
        engine.execute(figure)
    with rc_context({"figure.autolayout": False, "figure.constrained_layout.use": False}):
        figure.set_layout_engine(None)  # None, not "none": no placeholder engine to draw for


def draw_overview(out: Path, summary: Mapping[str, Any]) -> Any:
    """The overview as a :class:`matplotlib.figure.Figure` (None when no panel has data)."""
    from matplotlib.figure import Figure

    drawable = available_panels(out, summary)
    if not drawable:
        return None
    rows = -(-len(drawable) // 2)
    figure = Figure(figsize=(16, 5 * rows), layout="constrained")
    cells = figure.subfigures(rows, 2, squeeze=False).ravel()
    for cell in cells[len(drawable):]:
        cell.set_visible(False)
    for cell, (title, draw) in zip(cells, drawable):
        cell.suptitle(title, fontsize=12, fontweight="bold")
        try:
            draw(cell, out, summary)
        except Exception as error:  # noqa: BLE001 - one bad panel must not lose the others
            for axis in list(cell.axes):
                axis.remove()
            cell.text(0.5, 0.5, f"cannot draw: {type(error).__name__}: {error}",
                      ha="center", va="center", wrap=True)
    return figure


def available_panels(out: Path, summary: Mapping[str, Any]) -> list[tuple[str, Callable]]:
    """The (title, drawing function) of the panels whose data exist in `out` and `summary`."""
    return [(title, draw) for title, draw, has in PANELS if _safe(has, out, summary)]


def _safe(test: Callable[[Path, Mapping[str, Any]], bool], out: Path,
          summary: Mapping[str, Any]) -> bool:
    try:
        return bool(test(out, summary))
    except (KeyError, TypeError, OSError, ValueError):
        return False


def thin(x: np.ndarray, y: np.ndarray, points: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """At most about `points` samples of a line: each bucket's minimum and maximum, in order."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) <= points:
        return x, y
    edges = np.linspace(0, len(x), points // 2 + 1).astype(int)
    keep = []
    for start, stop in zip(edges[:-1], edges[1:]):
        part = y[start:stop]
        if not np.isfinite(part).any():
            keep.append(start)
            continue
        pair = sorted({start + int(np.nanargmin(part)), start + int(np.nanargmax(part))})
        keep += pair
    keep = np.asarray(keep)
    return x[keep], y[keep]


def _legend_above(axis: Any, columns: int = 3) -> None:
    """The axis' legend above its frame, off the data."""
    axis.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=columns, frameon=False,
                fontsize=9, borderaxespad=0.2)


def _unit(name: str, header_unit: str | None = None) -> tuple[str, float]:
    if name in OUTPUT_UNITS:
        return OUTPUT_UNITS[name]
    return header_unit or "-", 1.0


def _read_table(path: Path) -> dict[str, tuple[np.ndarray, str | None]]:
    """A CSV table as ``{name: (values, unit or None)}`` (``name [unit]`` headers)."""
    import pandas as pd

    frame = pd.read_csv(path)
    table = {}
    for column in frame.columns:
        name, _, unit = column.partition(" [")
        table[name] = (frame[column].to_numpy(float), unit.rstrip("]") or None)
    return table


def _series_panel(cell: Any, table: Mapping[str, tuple[np.ndarray, str | None]],
                  styles: list[tuple[str, str, dict]]) -> None:
    """One axis per output over time: a line per (suffix, label, style) of `styles`."""
    time = table["time"][0]
    outputs = [n[: -len("_measured")] for n in table if n.endswith("_measured")]
    axes = cell.subplots(len(outputs), 1, sharex=True, squeeze=False)[:, 0]
    clipped = False
    for axis, output in zip(axes, outputs):
        unit, factor = _unit(output, table[f"{output}_measured"][1])
        for suffix, label, style in styles:
            if f"{output}_{suffix}" in table:
                axis.plot(*thin(time, factor * table[f"{output}_{suffix}"][0]), label=label,
                          **style)
        axis.set_ylabel(f"{output} [{unit}]")
        axis.grid(alpha=0.3)
        clipped = clip_to_bulk(axis, [factor * table[f"{output}_{suffix}"][0] for suffix, _, _
                                      in styles if f"{output}_{suffix}" in table]) or clipped
    axes[-1].set_xlabel("time [s]" + (" (y axes: 0.5-99.5 % of the samples; the start-up "
                                      "transient runs off the scale)" if clipped else ""))
    _legend_above(axes[0])


def clip_to_bulk(axis: Any, lines: list[np.ndarray], share: float = 0.5,
                 margin: float = 0.1) -> bool:
    """Limit `axis`' y range to the `share`-th to (100 - `share`)-th percentile of all samples
    of `lines`, widened by `margin` of the span; returns whether any sample lies outside."""
    values = np.concatenate([np.asarray(v, float) for v in lines])
    values = values[np.isfinite(values)]
    if values.size == 0:
        return False
    low, high = np.percentile(values, [share, 100.0 - share])
    pad = margin * (high - low) or 1.0
    axis.set_ylim(low - pad, high + pad)
    return bool((values < low - pad).any() or (values > high + pad).any())


def _fit_file(out: Path) -> Path:
    for label in ("validation", "training"):
        if (out / "identification" / f"fit_{label}.csv").is_file():
            return out / "identification" / f"fit_{label}.csv"
    raise FileNotFoundError("identification/fit_*.csv")


def draw_fit(cell: Any, out: Path, summary: Mapping[str, Any]) -> None:
    """Measured and identified (free run) outputs of the validation run."""
    path = _fit_file(out)
    run = path.stem.removeprefix("fit_")
    _series_panel(cell, _read_table(path), [
        ("measured", f"measured ({run} run)", {"color": "0.55", "lw": 0.8}),
        ("simulated", "identified physical model", {"color": "k", "lw": 0.9})])


def draw_pareto(cell: Any, out: Path, summary: Mapping[str, Any], floor: float = -100.0) -> None:
    """The front of the two fits; points below `floor` [%] drawn at the floor as triangles."""
    pareto = summary["identification"]["pareto"]
    names = pareto.get("objective_names") or list(pareto["knee_fit"])
    points = np.asarray(pareto["objectives"], float)
    axis = cell.subplots()
    low = max(floor, float(np.nanmin(points)) - 5.0)
    clipped = np.maximum(points, low)
    beyond = (points < low).any(axis=1)
    axis.scatter(clipped[~beyond, 0], clipped[~beyond, 1], color="tab:blue",
                 label="non-dominated (NSGA-II)")
    if beyond.any():
        axis.scatter(clipped[beyond, 0], clipped[beyond, 1], marker="v", color="tab:blue",
                     facecolor="none", label=f"below {low:.0f} %, drawn at the edge")
    for key, label, marker in (("knee_fit", "knee", "s"), ("polished_fit", "knee polished by LM",
                                                           "*")):
        point = [max(low, pareto[key][n]) for n in names]
        edge = any(pareto[key][n] < low for n in names)
        axis.scatter(*point, marker=marker, s=110, color="tab:red" if marker == "*" else "k",
                     label=label + (" (drawn at the edge)" if edge else ""), zorder=3)
    axis.set_xlabel(f"fit {names[0]} [%]")
    axis.set_ylabel(f"fit {names[1]} [%]")
    axis.grid(alpha=0.3)
    _legend_above(axis, 2)


def draw_diagnosis(cell: Any, out: Path, summary: Mapping[str, Any]) -> None:
    """The validation run: measured, nominal and with the found effects."""
    effects = " then ".join(summary["diagnosis"].get("effects") or ()) or "no effect found"
    _series_panel(cell, _read_table(out / "diagnosis" / "validation_series.csv"), [
        ("measured", "measured", {"color": "0.55", "lw": 0.8}),
        ("before", "nominal (before)", {"color": "tab:blue", "lw": 0.8}),
        ("after", f"with {effects} (after)", {"color": "tab:red", "lw": 0.8})])


def draw_doe(cell: Any, out: Path, summary: Mapping[str, Any]) -> None:
    """Relative standard deviation per parameter, APRBS against the designed run (log axis)."""
    rows = summary["doe"]["table"]
    names = [r["parameter"] for r in rows]
    scale = np.array([abs(r["value"]) or np.nan for r in rows], float)
    axis = cell.subplots()
    position = np.arange(len(rows))
    for offset, key, label, color in ((-0.2, "std_conventional", "APRBS of equal length",
                                       "0.6"),
                                      (0.2, "std_designed", "designed run (D-optimal)",
                                       "tab:green")):
        values = 100 * np.array([r[key] for r in rows], float) / scale
        axis.bar(position + offset, values, width=0.4, color=color, label=label)
    axis.set_yscale("log")
    axis.set_xticks(position, names, rotation=45, ha="right")
    axis.set_ylabel("predicted std / value [%]")
    axis.set_xlabel("parameter")
    axis.grid(alpha=0.3, axis="y")
    _legend_above(axis, 2)


def draw_video(cell: Any, out: Path, summary: Mapping[str, Any]) -> None:
    """The tracked cross bar against the lasers' mean over the filmed window."""
    label, run = next(iter(summary["video"]["runs"].items()))
    table = _read_table(out / run["merged_dataset"])
    time, video = table["time"][0], table["video_cross_bar_y"][0]
    laser = np.nanmean(np.vstack([table["laser_1"][0], table["laser_2"][0]]), axis=0)
    window = np.isfinite(video)
    axis = cell.subplots()
    axis.plot(*thin(time[window], 1e3 * laser[window]), color="0.55", lw=0.9,
              label="lasers (500 Hz)")
    axis.plot(*thin(time[window], 1e3 * video[window]), color="tab:purple", lw=0.9,
              label=f"video marker, LED-synchronised (confidence {run['sync_confidence']:.2f})")
    axis.set_xlabel(f"time in the {label} run [s]")
    axis.set_ylabel("cross bar height [mm]")
    axis.grid(alpha=0.3)
    _legend_above(axis, 1)


def draw_contact_force(cell: Any, out: Path, summary: Mapping[str, Any]) -> None:
    """Contact force along the analysed section (the settling span before it is left out)."""
    path = _cosim_file(out, summary)
    table = _read_table(path)
    meta = json.loads(path.with_name(path.name + ".json").read_text())
    start, stop = meta.get("section_m") or meta["settings"]["section_m"]
    position = table["position"][0]
    section = (position >= start) & (position <= stop)
    axis = cell.subplots()
    axis.plot(*thin(position[section], table["contact_force"][0][section]), color="0.55",
              lw=0.7, label="contact force")
    if "contact_force_20Hz" in table:
        axis.plot(*thin(position[section], table["contact_force_20Hz"][0][section]),
                  color="k", lw=1.0, label="0-20 Hz (EN 50318)")
    mean = float(meta.get("statistics", {}).get("mean", np.nan))
    axis.axhline(mean, color="tab:red", lw=1.0, ls="--", label=f"mean {mean:.1f} N")
    for support in meta.get("support_positions_m", []):
        if start <= support <= stop:
            axis.axvline(support, color="tab:blue", lw=0.6, alpha=0.5)
    cosim = summary["cosim"]
    axis.set_xlabel(f"position along the line [m] (analysed section {start:g}-{stop:g} m; "
                    "lines: supports)")
    axis.set_ylabel("contact force [N]")
    axis.set_title(f"identified pantograph, {cosim['speed_kmh']:g} km/h", fontsize=10, loc="right")
    axis.grid(alpha=0.3)
    _legend_above(axis, 3)


def _cosim_file(out: Path, summary: Mapping[str, Any]) -> Path:
    cosim = summary["cosim"]
    path = out / "cosim" / f"{cosim['line']}_{cosim['speed_kmh']:g}kmh.csv"
    if not path.is_file():
        raise FileNotFoundError(path)
    return path


#: (title, drawing function, whether its data exist), in reading order.
PANELS: tuple[tuple[str, Callable, Callable], ...] = (
    ("Identified physical model vs the rig", draw_fit, lambda o, s: _fit_file(o)),
    ("NSGA-II Pareto front of the two fits", draw_pareto,
     lambda o, s: s["identification"]["pareto"]["objectives"]),
    ("Diagnosis: validation run before and after the found effects", draw_diagnosis,
     lambda o, s: s["diagnosis"] and (o / "diagnosis" / "validation_series.csv").is_file()),
    ("Next rig run: predicted parameter uncertainty", draw_doe, lambda o, s: s["doe"]["table"]),
    ("Video markers synchronised through the LED", draw_video,
     lambda o, s: (o / next(iter(s["video"]["runs"].values()))["merged_dataset"]).is_file()),
    ("Contact force along the EN 50318 line", draw_contact_force,
     lambda o, s: _cosim_file(o, s)),
)
