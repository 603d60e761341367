"""Plots of the data preparation, PNG files drawn on bare matplotlib figures.

* :func:`plot_aliasing_check`: the two spectrograms and the two spectra of an aliasing check
  (:func:`panto.identification.data.preprocessing.check_aliasing`, thesis Fig. 4.1).

The figures are :class:`matplotlib.figure.Figure` objects (no pyplot, no backend chosen), so the
functions are safe in notebooks, scripts and servers.
"""
from __future__ import annotations

import numpy as np

from panto.identification.data.preprocessing import AliasingCheck


def plot_aliasing_check(check: AliasingCheck, out_png: str) -> str:
    """Two spectrograms and the two spectra (thesis Fig. 4.1), suspect bands shaded."""
    from matplotlib.figure import Figure

    figure = Figure(figsize=(15, 4.5))
    axes = figure.subplots(1, 3)
    for axis, (f, t, power), rate in zip(axes[:2], check.spectrograms, check.rates):
        keep = f <= check.max_frequency
        image = axis.pcolormesh(t, f[keep], 10 * np.log10(power[keep] + 1e-300),
                                shading="auto", cmap="viridis")
        axis.set(title=f"{check.channel} at {rate:g} Hz", xlabel="time [s]",
                 ylabel="frequency [Hz]")
        figure.colorbar(image, ax=axis, label="PSD [dB]")
    axis = axes[2]
    for f, p, rate in zip(check.frequencies, check.spectra, check.rates):
        axis.semilogy(f, p, label=f"{rate:g} Hz", linewidth=0.8)
    for low, high, _ in check.where:
        axis.axvspan(low, high, color="red", alpha=0.2)
    verdict = "aliasing suspected" if check.aliasing_suspected else "spectra agree"
    axis.set(title=f"spectra: {verdict}", xlabel="frequency [Hz]", ylabel="PSD",
             xlim=(0, check.max_frequency))
    axis.legend()
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    figure.savefig(out_png, dpi=110)
    return str(out_png)


__all__ = ["plot_aliasing_check"]
