"""The drive's position latency: measured on the virtual test bed, and taken into account by the
identification (band-limited fractional delay, ``pantograph_data(position_latency=...)`` and the
physical structures' ``eta_delay``)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.data.datasets import delay_signal, pantograph_data
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.structures.physical import PhysicalLinear, PhysicalNonlinear


@pytest.mark.parametrize("delay", [0.3, 2.5, -1.7, 4.0])
def test_delay_signal_is_an_exact_shift_of_a_band_limited_signal(delay):
    k = np.arange(3000.0)
    frequencies, phases = (0.02, 0.13, 0.31), (0.3, 1.1, 2.0)

    def signal(t):
        return sum(np.sin(2 * np.pi * f * t + p) for f, p in zip(frequencies, phases))

    shifted = delay_signal(signal(k), delay)
    inner = slice(100, -100)  # away from the held ends
    assert np.max(np.abs(shifted[inner] - signal(k - delay)[inner])) < 1e-3
    assert np.allclose(delay_signal(np.full(50, 3.5), delay), 3.5)  # constants pass exactly


def test_delay_signal_is_continuous_in_the_delay():
    x = np.random.default_rng(0).standard_normal(400)
    for whole in (0, 1, -2):
        below, above = delay_signal(x, whole - 1e-9), delay_signal(x, whole + 1e-9)
        assert np.max(np.abs(below - above)) < 1e-6
        assert np.allclose(delay_signal(x, whole)[10:-10], np.roll(x, whole)[10:-10])


@pytest.fixture(scope="module")
def ideal_run(tmp_path_factory):
    """10 s of the training APRBS on the ideal virtual test bed (no noise)."""
    from panto.build_fmu.project import project_fmu
    from panto.rig.imperfections import RigImperfections
    from panto.rig.profiles import load_profile
    from panto.rig.virtual import run_virtual_profile

    profile = load_profile(Path(__file__).parents[1] / "rig" / "profiles" / "aprbs_training.json")
    profile = dataclasses.replace(profile, duration=10.0)
    folder = tmp_path_factory.mktemp("latency") / "run"
    run_virtual_profile(profile, fmu_path=project_fmu("Pantograph"), folder=folder,
                        imperfections=RigImperfections.none(), seed=1)
    return folder


def test_the_drive_reports_the_slider_two_and_a_half_samples_late(ideal_run):
    """motor_position[k] is the slider at sample k - 2 (even k) or k - 3 (odd k): the position
    sampled at a SYNC reaches the master one 250 Hz cycle later and is held two samples."""
    from panto.rig.dataset import read_dataset

    run = read_dataset(ideal_run, required=())
    truth = read_dataset(ideal_run / "truth.csv", required=())
    rows = np.searchsorted(truth.time, run.time - 1e-9)
    assert np.allclose(truth.time[rows], run.time)
    slider = np.asarray(truth["slider_position"])
    reported = np.asarray(run["motor_position"])
    k = np.arange(len(reported))
    late = np.where(k % 2 == 0, 2, 3)
    usable = rows - late >= 0
    error = reported[usable] - slider[rows[usable] - late[usable]]
    assert np.max(np.abs(error)) < 1e-6  # the CAN frame's 0.1 um resolution
    assert np.max(np.abs(reported[usable] - slider[rows[usable]])) > 1e-4  # not on time


def test_pantograph_data_advances_the_position_by_the_latency(ideal_run):
    """At 50 Hz the advanced position agrees with the true slider height far better."""
    from panto.rig.dataset import read_dataset

    truth = read_dataset(ideal_run / "truth.csv", required=())
    errors = {}
    for latency in (0.0, 0.005):
        data = pantograph_data(ideal_run, position_latency=latency)
        true_eta = np.interp(data.time, truth.time, truth["eta"])
        errors[latency] = np.std((data.input("eta") - true_eta)[5:-5])
        assert data.metadata["position_latency"] == latency
    # what remains is the 20 Hz low-pass of the data, which the unfiltered truth lacks
    assert errors[0.005] < 0.25 * errors[0.0]
    with pytest.raises(IdentificationError, match="position_latency"):
        pantograph_data(ideal_run, position_latency=-0.001)


def test_the_rig_setup_latency_is_the_default(ideal_run):
    from panto.rig.dataset import read_dataset

    run = read_dataset(ideal_run, required=())
    extra = {**run.metadata.extra, "rig_setup": {**run.metadata.extra["rig_setup"],
                                                 "position_latency": 0.005}}
    tagged = dataclasses.replace(run, metadata=dataclasses.replace(run.metadata, extra=extra))
    assert np.allclose(pantograph_data(tagged).inputs,
                       pantograph_data(run, position_latency=0.005).inputs)


def _inputs(duration: float) -> IdentificationData:
    time = np.arange(0.0, duration, 0.02)
    eta = 2.0 + 0.02 * (np.sin(2 * np.pi * 0.7 * time) + 0.5 * np.sin(2 * np.pi * 3.1 * time))
    p = 4.0 + 0.5 * np.sin(2 * np.pi * 0.23 * time + 0.4)
    return IdentificationData(time, np.column_stack([eta, p]), np.zeros((len(time), 2)),
                              ("eta", "p"), ("F_c", "y_cb"), source="synthetic inputs")


@pytest.mark.parametrize("kind", [PhysicalLinear, PhysicalNonlinear])
def test_eta_delay_feeds_the_model_the_advanced_measurement(kind):
    """Two samples of eta_delay equal simulating on eta shifted by two samples by hand."""
    data = _inputs(6.0)
    shifted_eta = np.concatenate([data.input("eta")[2:], np.repeat(data.input("eta")[-1], 2)])
    shifted = dataclasses.replace(data, inputs=np.column_stack([shifted_eta, data.input("p")]))
    options = {"operating_point": "first"} if kind is PhysicalLinear else {}
    with_delay = kind(eta_delay=0.04, **options).simulate({}, data)
    by_hand = kind(**options).simulate({}, shifted)
    assert np.max(np.abs(with_delay - by_hand), axis=0) == pytest.approx([0, 0], abs=1e-9)
    assert kind(fixed={"eta_delay": 0.04}, **options).nominal()["eta_delay"] == 0.04


def test_a_free_eta_delay_is_recovered_with_the_parameters():
    """A 13 ms latency (0.65 of a sample) from noisy synthetic data, with m_c and k_p."""
    rng = np.random.default_rng(2)
    data = _inputs(30.0)
    truth = {"eta_delay": 0.013, "m_c": 6.5, "k_p": 250.0}
    clean = PhysicalLinear().simulate(truth, data)
    noisy = dataclasses.replace(
        data, outputs=clean + np.array([1.0, 5e-4]) * rng.standard_normal(clean.shape))
    result = fit_least_squares(PhysicalLinear(), noisy, free=tuple(truth),
                               initial={"m_c": 5.0, "k_p": 300.0})
    assert result.success, result.message
    for name, value in truth.items():
        low, high = result.details["intervals_95"][name]
        assert low <= value <= high, (name, value, low, high)
    assert result.std["eta_delay"] < 0.001


def test_bad_eta_delay_is_refused():
    with pytest.raises(IdentificationError, match="eta_delay"):
        PhysicalLinear(eta_delay=1.0)
    assert "eta_delay" not in PhysicalLinear().default_free()
    assert "eta_delay" in PhysicalLinear().parameter_names
