"""The thesis' rig excitation (Fig. 3.4): the contact-wire motion under a passive pantograph.

Thesis section 3.3: "an additional input sequence was created from a numerical simulation of the
catenary system of a train drive at 300 km/h that captures the distance between support wire
poles (assumed to be 60 m). The sequence is therefore 0.72 s long and periodic" (Fig. 3.4:
contact-wire deflection, passive pantograph). :func:`make_rig_sequence` produces it:

1. co-simulate the ``thesis-60m`` line at 300 km/h with a passive pantograph - by default the
   thesis' own physical pantograph (``physical``, constant bellow pressure 4 bar, no control);
2. take the contact-wire height under the pantograph while it crosses each of the line's
   analysed (central) spans, as a function of the position within the span, and average them
   (the spans are identical, so what differs between them is the start transient and the end
   reflections, which averaging reduces);
3. make it exactly periodic: remove the linear drift :math:`(w(L) - w(0))\\,s/L` that makes the
   end differ from the start (reported in the metadata), subtract the mean (a zero-mean
   displacement, as the rig adds it to its own offset);
4. resample it on the time grid :math:`t_k = k / f_s`, :math:`k = 0 .. N-1` with
   :math:`N = f_s T` (500 Hz, 360 samples: one period without repeating the first sample),
   after a zero-phase anti-aliasing low-pass at 100 Hz applied to three periods in a row (so
   the filtered period is periodic too).

The CSV has the columns ``time [s]`` and ``contact_wire_displacement [m]``
(:meth:`panto.fmu_src.response.TimeResponse.to_csv`), which the rig's signal generator replays
(``panto.rig.signals.Replay``); the JSON beside it (``<file>.csv.json``) holds the units, the period,
the line, speed and pantograph and how the sequence was made.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .master import CosimOptions, cosimulate
from .pantographs import PantographSetup, pantograph_setup
from .plots import plot_rig_sequence
from .statistics import lowpass_filter

#: Name of the value column the rig's signal generator reads.
COLUMN = "contact_wire_displacement"
#: Anti-aliasing cut-off before resampling (Hz).
ANTI_ALIAS_HZ = 100.0


def periodic_sequence(position: np.ndarray, wire_height: np.ndarray, spans: list[tuple[float,
                      float]]) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """Average the wire height over several spans and close it into one zero-mean period.

    Parameters
    ----------
    position, wire_height : numpy.ndarray
        The contact point x (m, increasing) and the wire height there (m).
    spans : list of (float, float)
        Start and end x of each span to use (all of the same length L).

    Returns
    -------
    s : numpy.ndarray
        Position within the span (m), uniform, ``s[0] = 0``, ``s[-1] < L``.
    displacement : numpy.ndarray
        Zero-mean, periodic displacement (m) at `s`.
    info : dict
        ``drift_m`` removed, ``span_spread_m`` (rms difference between the spans).
    """
    length = spans[0][1] - spans[0][0]
    if any(abs((b - a) - length) > 1e-9 * length for a, b in spans):
        raise ValueError(f"the spans must have equal lengths, got {spans}")
    samples = int(np.count_nonzero((position >= spans[0][0]) & (position < spans[0][1])))
    s = length * np.arange(samples + 1) / samples
    curves = np.array([np.interp(a + s, position, wire_height) for a, _ in spans])
    mean_curve = curves.mean(axis=0)
    spread = float(np.sqrt(np.mean((curves - mean_curve) ** 2))) if len(spans) > 1 else 0.0
    drift = float(mean_curve[-1] - mean_curve[0])
    closed = mean_curve - drift * s / length
    closed = closed[:-1] - np.mean(closed[:-1])  # one period, the end sample = the first
    return s[:-1], closed, {"drift_m": drift, "span_spread_m": spread}


def resample_periodic(displacement: np.ndarray, period: float, rate_hz: float) -> np.ndarray:
    """Anti-alias (zero phase, on three periods in a row) and resample one period at `rate_hz`."""
    count = int(round(period * rate_hz))
    if abs(count - period * rate_hz) > 1e-6:
        raise ValueError(f"the period {period} s is not a whole number of samples at "
                         f"{rate_hz} Hz")
    fine_rate = displacement.size / period
    tiled = np.tile(displacement, 3)
    if fine_rate > 2.5 * ANTI_ALIAS_HZ:
        tiled = lowpass_filter(tiled, fine_rate, cutoff_hz=ANTI_ALIAS_HZ)
    fine_time = np.arange(tiled.size) / fine_rate
    coarse_time = period + np.arange(count) / rate_hz  # the middle period
    values = np.interp(coarse_time, fine_time, tiled)
    return values - values.mean()


#: Default run of :func:`make_rig_sequence`: a 0.2 ms catenary time step.
RIG_SEQUENCE_OPTIONS = CosimOptions(time_step=2e-4)


def make_rig_sequence(path: str | Path, *, line: str = "thesis-60m", speed_kmh: float = 300.0,
                      pantograph: PantographSetup | str | None = None,
                      sample_rate_hz: float = 500.0, options: CosimOptions | None = None,
                      progress: Callable[[str], None] | None = None, **settings: Any) -> Path:
    """Co-simulate and write the periodic rig sequence (module notes) to the CSV `path`.

    `line` may be a name, a line file or a line definition. The run's `options` default to
    :data:`RIG_SEQUENCE_OPTIONS`; keyword `settings` replace its fields (e.g. ``time_step``,
    ``element_length``, ``fmu_cache``), as in :func:`.master.cosimulate`.

    Returns
    -------
    pathlib.Path
        The CSV written (its metadata in ``<path>.json``: see
        :func:`panto.fmu_src.dataformat.metadata_path_for`).
    """
    from panto.fmu_src.response import TimeResponse

    setup = pantograph_setup("physical") if pantograph is None else (
        pantograph_setup(pantograph) if isinstance(pantograph, str) else pantograph)
    options = replace(options or RIG_SEQUENCE_OPTIONS, **settings)
    result = cosimulate(line, setup, speed_kmh=speed_kmh, options=options, progress=progress)
    definition = _line_definition(line)
    first, last = definition.analysed_spans
    spans = [((k - 1) * definition.span_length, k * definition.span_length)
             for k in range(first, last + 1)]
    s, displacement, info = periodic_sequence(result.position, result.wire_height, spans)
    period = definition.span_length / (speed_kmh / 3.6)
    values = resample_periodic(displacement, period, sample_rate_hz)
    time = np.arange(values.size) / sample_rate_hz
    metadata = _metadata(definition, speed_kmh, setup, period, sample_rate_hz, spans, info,
                         values, result)
    response = TimeResponse(time, {COLUMN: values}, units={COLUMN: "m"}, metadata=metadata)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    response.to_csv(path)
    plot_rig_sequence(path.with_suffix(".png"), time, values, period)
    return path


def _line_definition(line: Any) -> Any:
    from .lines import load_line

    return load_line(line) if isinstance(line, (str, Path)) else line


def _metadata(line: Any, speed_kmh: float, setup: PantographSetup, period: float,
              rate: float, spans: list[tuple[float, float]], info: dict[str, float],
              values: np.ndarray, result: Any) -> dict[str, Any]:
    return {
        "units": {"time": "s", COLUMN: "m"}, "period": period, "sample_rate_hz": rate,
        "samples": int(values.size), "line": line.name, "speed_kmh": speed_kmh,
        "pantograph": setup.name, "pantograph_description": setup.description,
        "description": "contact-wire displacement under a passive pantograph, one period "
                       "(span length / speed), zero mean; thesis section 3.3, Fig. 3.4",
        "provenance": (f"co-simulation (catenary_cosim) of line {line.name} at {speed_kmh:g} "
                       f"km/h with pantograph {setup.name}; spans {spans} (m) averaged, drift "
                       f"{1000 * info['drift_m']:.2f} mm removed, mean removed, zero-phase "
                       f"low-pass {ANTI_ALIAS_HZ:g} Hz, resampled at {rate:g} Hz"),
        "drift_removed_m": info["drift_m"], "span_spread_rms_m": info["span_spread_m"],
        "peak_to_peak_m": float(np.ptp(values)),
        "cosimulation": {"time_step_s": result.settings["time_step_s"],
                         "statistics": result.statistics().to_dict()},
        "one_period_without_repeating_first_sample": True,
    }


__all__ = ["make_rig_sequence", "RIG_SEQUENCE_OPTIONS", "periodic_sequence", "resample_periodic", "COLUMN"]
