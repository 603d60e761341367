"""A narrow actuator dead zone away from the input's median (``refit.located_zone``).

A zone of width ``b`` acts like a relay where the input crosses its centre: the training cost has
a basin about the true centre only about ``b`` wide. The plant is the two-mass oscillator of
``benchmarks/effect_plants.py`` (written apart from the identification package: its own RK4
loop, the zone applied to the slider height at every sub-step) with a 0.1 mm or 15 um zone about
the relaxed height 2 m; the slider ramps between 1.995 and 2.015 m, so its median lies ~5 mm
above. A trial zone a few times wider than the true one costs more than none: the grid's widths
must reach below it (the 15 um case fails with the widths of 0.3-10 % of the travel).
"""
from __future__ import annotations

import numpy as np
import pytest

from panto.identification.diagnosis.augmentations import AugmentedStructure
from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.diagnosis.refit import located_zone
from panto.identification.estimation.base import IdentificationData
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.structures.oscillators import OscillatorStructure

from test_unilateral_contact import _TRUTH, _effect_plants

PERIOD = 0.01
CENTRE = 2.0


@pytest.fixture(scope="module", params=[1e-4, 1.5e-5], ids=["100um", "15um"])
def zone_run(request) -> tuple[IdentificationData, float]:
    """Noise-free ``F_c`` and ``y_cb`` of the plant with the dead zone (0.5 % and 0.075 % of the
    travel wide) and that width [m]; slider ramps of different slopes between 1.995 and
    2.015 m, pressure held."""
    width = request.param
    plant = _effect_plants().EffectPlant(_TRUTH, "dead_zone", {"w": width, "centre": CENTRE})
    t = np.arange(1500) * PERIOD
    corners = np.array([2.005, 2.015, 1.995, 2.012, 1.998, 2.015, 1.995, 2.01, 2.005])
    eta = np.interp(t, np.linspace(0.0, t[-1], len(corners)), corners)
    p = np.full(len(t), 4.5)
    run = plant.simulate(t, eta, p, step=1e-3)
    return IdentificationData(t, np.column_stack([eta, p]),
                              np.column_stack([run["F_c"], run["x1"]]), ("eta", "p"),
                              ("F_c", "y_cb")), width


def _zone(data: IdentificationData, centre: float, width: float) -> AugmentedStructure:
    nominal = OscillatorStructure(2, outputs=data.output_names)
    spread = float(np.max(np.abs(data.input("eta") - centre)))
    roles = SignalRoles(position="y_cb", force="F_c", actuators=("eta", "p"))
    return AugmentedStructure(nominal, "dead_zone", roles,
                              {"width": width, "centre": centre, "spread": spread,
                               "coefficient": width, "scale": 1.0})


def test_the_grid_finds_a_narrow_zone_the_median_start_misses(zone_run):
    """From the median (5 mm off) with the ranking's wide start width, the output-error fit of
    the zone's width and centre cannot reach the zone; from :func:`located_zone`'s start it
    recovers both (width within 5 %, centre within a tenth of the width) and the fit of the
    plant's own run."""
    zone_run, true_width = zone_run
    eta = zone_run.input("eta")
    median = float(np.median(eta))
    assert median - CENTRE > 20 * true_width
    structure = _zone(zone_run, median, 0.05 * float(np.max(np.abs(eta - median))))
    names = structure.effect_parameters
    truth = {k: v for k, v in _TRUTH.items() if k in structure.parameter_names}
    start = {**structure.nominal(), **truth}
    plain = fit_least_squares(structure, zone_run, free=names, initial=start, max_evaluations=300)
    located = located_zone(structure, start, zone_run)
    # the grid's zone overlaps the true one (the basin the fit then descends)
    assert abs(located[names[1]] - CENTRE) < true_width, located  # inside the zone
    fitted = fit_least_squares(structure, zone_run, free=names, initial=located,
                               max_evaluations=300)
    width, centre = fitted.parameters[names[0]], fitted.parameters[names[1]]
    assert width == pytest.approx(true_width, rel=0.05) and abs(centre - CENTRE) < 0.1 * true_width
    assert fitted.fit["F_c"] > 99.0, fitted.fit
    assert plain.fit["F_c"] < fitted.fit["F_c"] - 5.0, (plain.fit, plain.parameters)


def test_other_effects_and_a_fixed_centre_keep_their_start(zone_run):
    zone_run, true_width = zone_run
    structure = _zone(zone_run, CENTRE, true_width)
    fixed = AugmentedStructure(structure.base, "dead_zone", structure.roles,
                               {"width": true_width, "centre": CENTRE, "coefficient": true_width})
    start = fixed.nominal()
    assert located_zone(fixed, start, zone_run) == start
