"""Plots of the design-of-experiments results, as the thesis' figures 5.1 and 5.3-5.5.

* :func:`plot_line_designs`: the line example (Fig. 5.1) with two and three measurement points.
* :func:`plot_inputs_and_outputs`: force (dashed) and position (solid) for the two-sine,
  offline and online inputs (Figs. 5.3-5.5), with the limits.
* :func:`plot_covariance_comparison`: Cramer-Rao variance of each parameter per input (log scale)
  and, if given, the grey-box variances of m, c, k (Table 5.1).
* :func:`plot_online_estimates`: the RLS estimate during the online design against the truth.
* :func:`plot_design`: a rig design's inputs against the conventional APRBS and the predicted
  standard deviation per parameter (thesis section 5.5).

The figures are :class:`matplotlib.figure.Figure` objects (no pyplot, no backend chosen), so the
functions are safe in notebooks, scripts and servers.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from panto.identification.design.thesis_example import ThesisExample
from panto.identification.design.fisher import LineDesign, design_line_experiment
from panto.identification.design.pantograph import PantographDesign


def plot_line_designs(path: str | Path, designs: list[LineDesign] | None = None) -> Path:
    """The line :math:`y = k x + d` with D-optimal measurement points (Fig. 5.1)."""
    from matplotlib.figure import Figure

    designs = designs or [design_line_experiment(2), design_line_experiment(3),
                          design_line_experiment(3, zero_covariance=True)]
    figure = Figure(figsize=(4 * len(designs), 3.4))
    axes = figure.subplots(1, len(designs), squeeze=False)
    x = np.linspace(-1, 1, 50)
    for axis, design in zip(axes[0], designs):
        axis.plot(x, 0.5 * x + 0.2, color="0.4", label="y = k x + d")
        axis.plot(design.points, 0.5 * design.points + 0.2, "o", color="red", label="measurements")
        values, counts = np.unique(np.round(design.points, 6), return_counts=True)
        for value, count in zip(values, counts):
            if count > 1:
                axis.annotate(f"x{count}", (value, 0.5 * value + 0.2), textcoords="offset points",
                              xytext=(-14, 6), fontsize=8, color="red")
        covariance = design.covariance[0, 1]
        title = f"{design.points.size} points" + (", zero covariance" if design.zero_covariance
                                                  else "")
        axis.set_title(f"{title}\nx = {np.round(design.points, 3)}, cov(k, d) = {covariance:.3g}",
                       fontsize=9)
        axis.set_xlim(-1.1, 1.1)
        axis.set_xlabel("x")
        axis.grid(alpha=0.3)
    axes[0][0].set_ylabel("y")
    axes[0][0].legend(fontsize=8)
    return _save(figure, path)


def plot_inputs_and_outputs(example: ThesisExample, path: str | Path) -> Path:
    """Force (dashed) and position (solid) for each input (thesis Figs. 5.3-5.5)."""
    from matplotlib.figure import Figure

    names = list(example.evaluations)
    figure = Figure(figsize=(9, 2.6 * len(names)))
    axes = figure.subplots(len(names), 1, sharex=True)
    period = example.settings["sample_period"]
    for axis, name in zip(np.atleast_1d(axes), names):
        evaluation = example.evaluations[name]
        time = np.arange(evaluation.inputs.size) * period
        axis.step(time, evaluation.inputs, "--", where="post", color="black", lw=1,
                  label="force F [N]")
        limit = example.settings["amplitude_limit"]
        axis.axhline(limit, color="red", lw=0.6)
        axis.axhline(-limit, color="red", lw=0.6)
        axis.set_ylabel("F [N]")
        twin = axis.twinx()
        twin.plot(time, 1e3 * evaluation.outputs, color="0.5", lw=1.2, label="position y")
        twin.set_ylabel("y [mm]")
        axis.set_title(f"{name}: trace of Cramer-Rao covariance "
                       f"{np.trace(evaluation.cramer_rao):.3g}", fontsize=9)
    np.atleast_1d(axes)[-1].set_xlabel("time [s]")
    return _save(figure, path)


def plot_covariance_comparison(example: ThesisExample, path: str | Path) -> Path:
    """Variances per parameter and input: Cramer-Rao of theta, grey-box of m, c, k."""
    from matplotlib.figure import Figure

    names = list(example.evaluations)
    figure = Figure(figsize=(11, 3.8))
    left, right = figure.subplots(1, 2)
    width = 0.8 / len(names)
    for i, name in enumerate(names):
        evaluation = example.evaluations[name]
        left.bar(np.arange(4) + i * width, np.diag(evaluation.cramer_rao), width, label=name)
        right.bar(np.arange(3) + i * width, evaluation.grey_box.variances, width, label=name)
    left.set_xticks(np.arange(4) + 0.4 - width / 2, ["a1", "a2", "b1", "b2"])
    right.set_xticks(np.arange(3) + 0.4 - width / 2, ["m", "c", "k"])
    left.set_title("Cramer-Rao variance of theta (true parameters)", fontsize=9)
    right.set_title("grey-box variance of m, c, k (one noisy run)", fontsize=9)
    for axis in (left, right):
        axis.set_yscale("log")
        axis.grid(alpha=0.3, which="both")
        axis.legend(fontsize=8)
    return _save(figure, path)


def plot_online_estimates(example: ThesisExample, path: str | Path) -> Path:
    """RLS estimate of each parameter during the online design, against the true value."""
    from matplotlib.figure import Figure

    history = example.online.theta_history
    time = np.arange(len(history)) * example.settings["sample_period"]
    figure = Figure(figsize=(9, 5))
    axes = figure.subplots(2, 2, sharex=True)
    for j, (axis, name) in enumerate(zip(axes.ravel(), ["a1", "a2", "b1", "b2"])):
        axis.plot(time, history[:, j], label="RLS estimate")
        axis.axhline(example.theta_true[j], color="black", ls="--", lw=0.8, label="true")
        axis.set_ylabel(name)
        axis.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for axis in axes[1]:
        axis.set_xlabel("time [s]")
    return _save(figure, path)


def plot_thesis_example(example: ThesisExample, folder: str | Path) -> list[Path]:
    """All plots of the dynamic example into `folder`."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return [plot_inputs_and_outputs(example, folder / "doe_inputs_outputs.png"),
            plot_covariance_comparison(example, folder / "doe_covariance.png"),
            plot_online_estimates(example, folder / "doe_online_estimates.png")]


def plot_design(design: PantographDesign, folder: str | Path) -> dict[str, Path]:
    """``doe_inputs.png`` (both inputs, designed and conventional, predicted outputs) and
    ``doe_std.png`` (predicted relative std per parameter, designed vs conventional)."""
    from matplotlib.figure import Figure

    folder = Path(folder)
    t = design.time
    fig = Figure(figsize=(10, 8))
    axes = fig.subplots(2 + len(design.output_names), 1, sharex=True)
    axes[0].plot(t, 1e3 * design.conventional_motor_position, lw=0.8, label="APRBS (conditioned)")
    axes[0].plot(t, 1e3 * design.motor_position, lw=0.8, label="designed")
    axes[0].set_ylabel("motor [mm]")
    axes[1].plot(t, design.conventional_pressure_demand, lw=0.8, label="APRBS demand")
    axes[1].plot(t, design.pressure_demand, lw=0.8, label="designed demand")
    axes[1].plot(t, design.pressure, lw=0.8, label="designed, measured (lag)")
    axes[1].set_ylabel("pressure [bar]")
    for axis, j in zip(axes[2:], range(len(design.output_names))):
        axis.plot(t, design.conventional_outputs[:, j], lw=0.8, label="APRBS")
        axis.plot(t, design.outputs[:, j], lw=0.8, label="designed")
        axis.set_ylabel(design.output_names[j])
    for axis in axes:
        axis.legend(loc="upper right", fontsize=7)
        axis.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{design.structure}: {design.criterion}-optimal inputs vs APRBS")
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    inputs = folder / "doe_inputs.png"
    fig.savefig(inputs, dpi=120)
    scale = np.array([abs(design.parameters[n]) or 1.0 for n in design.parameter_names])
    fig = Figure(figsize=(8, 4))
    axis = fig.subplots()
    x = np.arange(len(scale))
    axis.bar(x - 0.2, 100 * design.conventional_std / scale, 0.4, label="APRBS")
    axis.bar(x + 0.2, 100 * design.std / scale, 0.4, label="designed")
    axis.set_xticks(x, design.parameter_names, rotation=45)
    axis.set_yscale("log")
    axis.set_ylabel("predicted std [% of value]")
    axis.legend()
    axis.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    std = folder / "doe_std.png"
    fig.savefig(std, dpi=120)
    return {"inputs_plot": inputs, "std_plot": std}

def _save(figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    figure.savefig(path, dpi=110)
    return path
