"""A global start for the refit of an unmodelled mode (``extra_mode``, output side).

The augmentation adds ``g (H_{f,zeta} - 1) w`` to its target output
(:func:`~panto.identification.diagnosis.augmentations.mode_response`): linear in the gain ``g``,
but a lightly damped resonance in the frequency ``f`` [Hz]. The training cost as a function of
``f`` then has a narrow valley about the mode (relative width about ``zeta``: 3 % for the
``zeta = 0.03`` of a steel or rubber support) and ripples elsewhere, so a gradient refit from the
ranking's grid frequency (its points ~36 % apart) can stop in a ripple. :func:`located_mode`
scans ``f`` over the refit's bounds and ``zeta`` over :data:`MODE_DAMPINGS` with the rest of the
model held at the start, the gain solved by linear least squares at every point (one free run of
the model, then a filter per grid point: variable projection, Golub & Pereyra 1973), and starts
the refit from the grid's best point (a global method on the grid; the refit then moves all
parameters from there).
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from panto.identification.diagnosis.augmentations import AugmentedStructure, mode_response
from panto.identification.estimation.base import IdentificationData, IdentificationError

#: Frequencies of the scan, log-spaced over the refit's frequency bounds (a ratio of 9: 1.8 %
#: apart, finer than the valley of a ``zeta = 0.03`` mode).
MODE_FREQUENCIES = 121
#: Dampings [-] of the scan (those inside the refit's bounds).
MODE_DAMPINGS = (0.005, 0.01, 0.02, 0.03, 0.05, 0.1, 0.2, 0.5)
GAIN, FREQUENCY, DAMPING = "extra_mode:gain", "extra_mode:frequency", "extra_mode:damping"


def located_mode(structure: AugmentedStructure, start: Mapping[str, float],
                 train: IdentificationData) -> dict[str, float]:
    """`start` with the mode's gain, frequency [Hz] and damping [-] from the grid scan (module
    notes) when a grid point has a lower training cost on the target output than `start` itself;
    other effects, modes inside the dynamics and targets absent from `train` return `start`."""
    start = dict(start)
    if structure.effect != "extra_mode" or structure.mode != "wrapper":
        return start
    output = str(structure.setting["output"])
    if output not in train.output_names or output not in structure.output_names:
        return start
    bounds = structure.bounds()
    try:
        y = np.asarray(structure.simulate({**start, GAIN: 0.0}, train), float)
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return start
    measured = train.outputs[:, train.output_names.index(output)]
    residual = np.where(np.isfinite(measured), measured - y[:, structure.output_names.index(output)],
                        0.0)
    drive = structure.mode_drive(train, y)
    drive = drive - drive[0]
    dt = train.sample_period

    def solved(frequency: float, damping: float, gain: float | None = None
               ) -> tuple[float, float]:
        x = np.where(np.isfinite(measured), mode_response(drive, frequency, damping, dt), 0.0)
        xx = float(x @ x)
        if gain is None:
            gain = float(np.clip(x @ residual / xx, *bounds[GAIN])) if xx > 0 else 0.0
        cost = float(np.sum((residual - gain * x) ** 2))
        return (cost if math.isfinite(cost) else math.inf), gain

    best_cost, _ = solved(start[FREQUENCY], start[DAMPING], start[GAIN])
    low, high = bounds[FREQUENCY]
    dampings = [z for z in MODE_DAMPINGS if bounds[DAMPING][0] <= z <= bounds[DAMPING][1]]
    for frequency in np.geomspace(low, high, MODE_FREQUENCIES):
        for damping in dampings:
            cost, gain = solved(float(frequency), damping)
            if cost < best_cost:
                best_cost = cost
                start.update({GAIN: gain, FREQUENCY: float(frequency), DAMPING: damping})
    return start


__all__ = ["located_mode", "MODE_FREQUENCIES", "MODE_DAMPINGS"]
