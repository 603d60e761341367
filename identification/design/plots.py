"""Plots of the design-of-experiments results, as the thesis' figures 5.1 and 5.3-5.5.

* :func:`plot_line_designs`: the line example (Fig. 5.1) with two and three measurement points.
* :func:`plot_inputs_and_outputs`: force (dashed) and position (solid) for the two-sine,
  offline and online inputs (Figs. 5.3-5.5), with the limits.
* :func:`plot_covariance_comparison`: Cramer-Rao variance of each parameter per input (log scale)
  and, if given, the grey-box variances of m, c, k (Table 5.1).
* :func:`plot_online_estimates`: the RLS estimate during the online design against the truth.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from panto.identification.design.thesis_example import ThesisExample
from panto.identification.design.fisher import LineDesign, design_line_experiment


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_line_designs(path: str | Path, designs: list[LineDesign] | None = None) -> Path:
    """The line :math:`y = k x + d` with D-optimal measurement points (Fig. 5.1)."""
    plt = _pyplot()
    designs = designs or [design_line_experiment(2), design_line_experiment(3),
                          design_line_experiment(3, zero_covariance=True)]
    figure, axes = plt.subplots(1, len(designs), figsize=(4 * len(designs), 3.4), squeeze=False)
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
    plt = _pyplot()
    names = list(example.evaluations)
    figure, axes = plt.subplots(len(names), 1, figsize=(9, 2.6 * len(names)), sharex=True)
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
    plt = _pyplot()
    names = list(example.evaluations)
    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 3.8))
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
    plt = _pyplot()
    history = example.online.theta_history
    time = np.arange(len(history)) * example.settings["sample_period"]
    figure, axes = plt.subplots(2, 2, figsize=(9, 5), sharex=True)
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


def _save(figure, path: str | Path) -> Path:
    import matplotlib.pyplot as plt
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
