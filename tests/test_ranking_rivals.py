"""Rival explanations refitted together (identification/diagnosis/ranking.py ``RIVALS``): a mass
on the force sensor bends the force's response at high frequency as an extra mode does, with one
parameter instead of three; whenever the ranked head holds an extra mode, the sensor mass is
refitted too, whatever its rank (seen held-out two-mass/sensor_inertia/2076: ranked sixth of
five refits behind an extra mode, never refitted). The per-output scores stand in for the FROLS
ranking, as in test_diagnosis_linear_shortfall.py."""
from __future__ import annotations

import numpy as np

from fixtures.ranking_stubs import Score, stub_ranking

from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.diagnosis.ranking import rank_candidates
from panto.identification.diagnosis.refit import Model
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure

ROLES = SignalRoles(position="eta", force="F_c", actuators=("eta", "p"), sensor_position=None,
                    head_position="xi")


def _ranked(monkeypatch, scores, max_refits, every=()):
    """The ranking of a two-mass nominal with the per-output `scores` in place of FROLS'."""
    stub_ranking(monkeypatch, scores)
    rng = np.random.default_rng(0)
    t = np.arange(400) / 50.0
    eta, p = 0.002 * rng.normal(size=t.size), 4.0 + 0.1 * rng.normal(size=t.size)
    structure = OscillatorStructure(2, outputs=("F_c",))
    data = IdentificationData(t, np.column_stack([eta, p]), np.zeros((t.size, 1)), ("eta", "p"),
                              ("F_c",))
    data = IdentificationData(t, data.inputs, structure.simulate(structure.nominal(), data)
                              + rng.normal(size=(t.size, 1)), ("eta", "p"), ("F_c",))
    model = Model(structure, structure.nominal(), ("F_0", "p_gain"))
    candidates = ["extra_mode", "sensor_inertia", "input_delay", "actuator_lag"]
    return rank_candidates(model, data, ROLES, candidates, max_refits, every)


def test_a_sensor_mass_ranked_below_the_refits_follows_an_extra_mode(monkeypatch):
    """Two refits: the mode and the delay ranked, the sensor mass (third, and below the ERR
    floor) appended after them; the ranked head itself unchanged."""
    scores = [Score("extra_mode", "mode", 0.3), Score("input_delay@eta", "delay", 0.2),
              Score("actuator_lag@eta", "lag", 0.1), Score("sensor_inertia", "xi''", 0.001)]
    result = _ranked(monkeypatch, scores, 2)
    assert [c["effect"] for c in result["top"]] == ["extra_mode", "input_delay", "sensor_inertia"]
    assert result["rivals"] == ["sensor_inertia"] and result["appended"] == 0


def test_no_sensor_mass_is_appended_without_an_extra_mode_in_the_head(monkeypatch):
    """The mode ranked third of two refits: nothing appended; the mode and the mass both in the
    head: nothing appended twice."""
    scores = [Score("input_delay@eta", "delay", 0.3), Score("actuator_lag@eta", "lag", 0.2),
              Score("extra_mode", "mode", 0.1), Score("sensor_inertia", "xi''", 0.05)]
    result = _ranked(monkeypatch, scores, 2)
    assert [c["effect"] for c in result["top"]] == ["input_delay", "actuator_lag"]
    assert result["rivals"] == []
    result = _ranked(monkeypatch, scores, 4)
    assert [c["effect"] for c in result["top"]] == ["input_delay", "actuator_lag", "extra_mode",
                                                    "sensor_inertia"]
    assert result["rivals"] == []


def test_a_sensor_mass_above_the_floor_but_beyond_the_refits_follows_as_well(monkeypatch):
    """The mass ranked fourth of two refits with an ERR above the floor: appended once; with
    the candidates adding dynamics appended anyway (``every``), it comes with them, counted
    among them, not twice."""
    scores = [Score("extra_mode", "mode", 0.3), Score("input_delay@eta", "delay", 0.2),
              Score("actuator_lag@eta", "lag", 0.1), Score("sensor_inertia", "xi''", 0.05)]
    result = _ranked(monkeypatch, scores, 2)
    assert [c["effect"] for c in result["top"]] == ["extra_mode", "input_delay", "sensor_inertia"]
    assert result["rivals"] == ["sensor_inertia"]
    result = _ranked(monkeypatch, scores, 2, every=("extra_mode", "sensor_inertia"))
    assert [c["effect"] for c in result["top"]] == ["extra_mode", "input_delay", "sensor_inertia"]
    assert result["rivals"] == [] and result["appended"] == 1
