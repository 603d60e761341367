"""Excitation signals, profiles and the LED sequence: each signal's defining properties.

Statistical checks use tolerances derived from the sample size (quantiles of the exact sampling
distributions at a 1e-4 level), spectral checks the exact periodicity of the multisine.
"""
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps
from scipy import stats

from panto.fmu_src.response import TimeResponse
from panto.rig.profiles import (ProfileError, ProfileStream, load_profile, profile_from_dict,
                          profile_to_dict, render_profile, save_profile)
from panto.rig.signals import (SIGNAL_TYPES, Aprbs, Chirp, Multisine, Ramps, RealiseContext, Replay,
                         Steps, signal_from_dict)
from panto.rig.sync_led import LedOptions, LedStream, generate_led_bits, run_lengths

FS = 500.0
PROFILES = Path(__file__).resolve().parents[1] / "rig" / "profiles"


def rng(seed=0):
    return np.random.default_rng(seed)


def times(duration, fs=FS):
    return np.arange(int(round(duration * fs))) / fs


# --- APRBS -------------------------------------------------------------------------------------

def aprbs_levels_and_holds(values):
    """Levels and hold lengths [samples] of the complete runs (the last one may be cut)."""
    levels, lengths = run_lengths(values)
    return levels[:-1], lengths[:-1]


def test_aprbs_hold_times_within_bounds_and_spanning_them():
    signal = Aprbs(std=0.01, hold_min=0.1, hold_max=0.5, clip=False)
    values = signal.sample(times(1500.0), rng(1))
    _, holds = aprbs_levels_and_holds(values)
    assert holds.size > 4000
    assert holds.min() >= 0.1 * FS and holds.max() <= 0.5 * FS
    # uniform over 201 whole-sample holds: P(an end never drawn in >4000 draws) < 1e-8
    assert holds.min() == 50 and holds.max() == 250


def test_aprbs_levels_are_zero_mean_normal_with_given_std():
    sigma = 0.02
    values = Aprbs(std=sigma, hold_min=0.004, hold_max=0.02, clip=False).sample(
        times(200.0), rng(2))
    levels, _ = aprbs_levels_and_holds(values)
    n = levels.size
    assert n > 5000
    assert abs(levels.mean()) < 4.0 * sigma / math.sqrt(n)
    statistic = (n - 1) * levels.var(ddof=1) / sigma ** 2  # chi-square with n - 1 dof
    assert stats.chi2.ppf(1e-4, n - 1) < statistic < stats.chi2.ppf(1 - 1e-4, n - 1)
    assert stats.kstest(levels / sigma, "norm").pvalue > 1e-4


def test_aprbs_clips_to_channel_room():
    context = RealiseContext(duration=100.0, sample_rate=FS, bounds=(-0.01, 0.005))
    values = Aprbs(std=0.02, hold_min=0.1, hold_max=0.2).realise(rng(3), context)(times(100.0))
    assert values.min() == -0.01 and values.max() == 0.005  # the clip acts on both sides


# --- chirp ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("method, f0, f1", [("linear", 1.0, 20.0), ("logarithmic", 0.5, 40.0)])
def test_chirp_instantaneous_frequency_follows_its_law(method, f0, f1):
    fs, length = 4000.0, 20.0
    chirp = Chirp(f_start=f0, f_stop=f1, duration=length, amplitude=0.003, method=method)
    t = times(length, fs)
    x = chirp.sample(t, rng(), sample_rate=fs)
    phase = np.unwrap(np.angle(sps.hilbert(x)))  # analytic signal of A sin(phi): phase phi - pi/2
    if method == "linear":  # the laws, integrated by hand: phi = 2 pi int f dt
        law = 2.0 * np.pi * (f0 * t + (f1 - f0) * t ** 2 / (2.0 * length))
    else:
        k = math.log(f1 / f0) / length
        law = 2.0 * np.pi * f0 * (np.exp(k * t) - 1.0) / k
    inner = (t > 2.0) & (t < length - 2.0)  # away from the Hilbert transform's end effects
    assert np.max(np.abs(phase - law + np.pi / 2)[inner]) < 0.1  # rad, over > 150 cycles
    window = int(fs)  # instantaneous frequency averaged over 1 s windows
    measured = (phase[window:] - phase[:-window]) / (2.0 * np.pi)
    expected = (law[window:] - law[:-window]) / (2.0 * np.pi)
    assert np.max(np.abs(measured - expected)[inner[:-window] & inner[window:]]) < 0.02  # Hz
    assert np.max(np.abs(x)) <= 0.003 and x[0] == 0.0
    assert np.all(chirp.sample(times(length + 1.0, fs), rng(), sample_rate=fs)[t.size:] == 0.0)


def test_chirp_zero_crossings_agree_with_linear_law():
    chirp = Chirp(f_start=2.0, f_stop=10.0, duration=8.0, amplitude=1.0)
    fs = 20000.0
    t = times(8.0, fs)
    x = chirp.sample(t, rng(), sample_rate=fs)
    up = np.flatnonzero((x[:-1] < 0.0) & (x[1:] >= 0.0))
    crossing = t[up] - x[up] / (x[up + 1] - x[up]) / fs  # linear interpolation
    mid, freq = 0.5 * (crossing[1:] + crossing[:-1]), 1.0 / np.diff(crossing)
    assert np.allclose(freq, 2.0 + 1.0 * mid, rtol=2e-3)


# --- multisine ----------------------------------------------------------------------------------

def test_multisine_excites_only_odd_lines_with_detection_lines_and_rms():
    period, periods = 2.0, 3
    signal = Multisine(period=period, f_max=60.0, detection_group=3, rms=0.004)
    x = signal.sample(times(period * periods), rng(5))
    spectrum = np.abs(np.fft.rfft(x)) / x.size
    floor = 1e-10 * spectrum.max()
    bins = np.arange(spectrum.size)
    on_grid = bins % periods == 0
    assert np.all(spectrum[~on_grid] < floor)  # exactly periodic: nothing between the lines
    harmonic = bins // periods
    excited = set(harmonic[on_grid & (spectrum > floor)].tolist())
    assert all(k % 2 == 1 for k in excited)  # no even line, no DC
    odd = list(range(1, int(60.0 * period) + 1, 2))
    for g in range(len(odd) // 3):  # one detection line in every group of three odd lines
        assert len(excited & set(odd[3 * g: 3 * g + 3])) == 2
    amplitudes = spectrum[[periods * k for k in sorted(excited)]]
    assert np.ptp(amplitudes) < 1e-9 * amplitudes.max()  # flat amplitude spectrum
    assert math.isclose(np.sqrt(np.mean(x ** 2)), 0.004, rel_tol=1e-12)


def test_multisine_peak_scaling_and_random_phases():
    signal = Multisine(period=1.0, f_max=30.0, peak=0.01, detection_group=0)
    a = signal.sample(times(2.0), rng(1))
    b = signal.sample(times(2.0), rng(2))
    assert math.isclose(np.max(np.abs(a)), 0.01, rel_tol=1e-12)
    assert not np.allclose(a, b)


def test_multisine_refuses_a_window_without_whole_periods():
    with pytest.raises(ValueError, match="whole number of periods"):
        Multisine(period=3.0, f_max=10.0, rms=0.001).sample(times(10.0), rng())


# --- ramps, steps, replay -------------------------------------------------------------------------

def test_ramps_slope_height_and_end():
    ramps = Ramps(repetitions=2, height=0.04, gradient=0.01, hold_time=1.0)
    x = ramps.sample(times(25.0), rng())
    slope = np.diff(x) * FS
    moving = np.abs(slope) > 1e-9
    assert np.allclose(np.abs(slope[moving]), 0.01, rtol=1e-9)
    assert math.isclose(x.max(), 0.04) and x.min() == 0.0
    cycle = 2 * (0.04 / 0.01 + 1.0)
    assert np.all(x[times(25.0) >= 2 * cycle] == 0.0)


def test_steps_staircase_levels():
    x = Steps(count=3, height=0.5, hold_time=1.0).sample(times(8.0), rng())
    levels, lengths = run_lengths(x)
    assert levels.tolist() == [0.5, 1.0, 1.5, 1.0, 0.5, 0.0]
    assert lengths[:-1].tolist() == [500] * 5


def write_sequence(folder, unit="m", name="seq.csv", n=360, dt=0.002, seed=4):
    values = np.random.default_rng(seed).normal(size=n) * 0.01
    path = TimeResponse(np.arange(n) * dt, {"contact_wire_displacement": values},
                        units={"contact_wire_displacement": unit}).to_csv(folder / name)
    return path, values


def test_replay_reproduces_file_and_repeats_periodically(tmp_path):
    path, values = write_sequence(tmp_path)
    replay = Replay(path=str(path), column="contact_wire_displacement")
    t = times(3 * 0.72)
    x = replay.sample(t, rng())
    assert np.allclose(x.reshape(3, 360), values, rtol=0, atol=1e-12)  # three periods
    # between samples: linear interpolation, also across the wrap-around
    mid = replay.sample(np.array([0.001, 0.719]), rng())
    assert np.allclose(mid, [(values[0] + values[1]) / 2, (values[-1] + values[0]) / 2])


def test_replay_converts_and_checks_units(tmp_path):
    path, values = write_sequence(tmp_path, unit="mm")
    x = Replay(path=str(path), column="contact_wire_displacement").sample(times(0.72), rng())
    assert np.allclose(x, values * 1e-3, rtol=1e-15)
    with pytest.raises(ValueError, match="conflicting units"):
        Replay(path=str(path), column="contact_wire_displacement", unit="m").sample(
            times(0.1), rng())
    pressure = RealiseContext(duration=0.1, sample_rate=FS, unit="bar")
    with pytest.raises(ValueError, match="cannot be converted"):
        Replay(path=str(path), column="contact_wire_displacement").realise(rng(), pressure)


def test_replay_without_repetition_holds_the_last_value(tmp_path):
    path, values = write_sequence(tmp_path)
    x = Replay(path=str(path), column="contact_wire_displacement", periodic=False).sample(
        times(1.0), rng())
    assert np.allclose(x[:360], values, rtol=0, atol=1e-12) and np.all(x[360:] == values[-1])


# --- registry and reproducibility ----------------------------------------------------------

def test_every_registered_kind_round_trips_through_its_dict(tmp_path):
    path, _ = write_sequence(tmp_path)
    examples = [Aprbs(std=0.01, hold_min=0.1, hold_max=0.2), Chirp(f_start=1, f_stop=2,
                duration=1, amplitude=0.1), Multisine(period=1.0, f_max=5.0, rms=0.1),
                Ramps(repetitions=1, height=1, gradient=1), Steps(count=2, height=1,
                hold_time=1), Replay(path=str(path), column="contact_wire_displacement"),
                signal_from_dict({"kind": "sine", "frequency": 1, "amplitude": 1}),
                signal_from_dict({"kind": "constant", "value": 2})]
    assert {s.kind for s in examples} == set(SIGNAL_TYPES)
    for signal in examples:
        assert signal_from_dict(json.loads(json.dumps(signal.to_dict()))) == signal


def full_profile_dict(tmp_path):
    path, _ = write_sequence(tmp_path)
    return {"name": "all", "duration": 20.0, "seed": 42,
            "limits": {"motor_min": 0.0, "motor_max": 0.3, "safe_pressure": 3.0},
            "conditioning": {"reference_filter": True},
            "motor": {"offset": 0.15, "signals": [
                {"kind": "aprbs", "std": 0.01, "hold_min": 0.1, "hold_max": 1.0},
                {"kind": "sine", "frequency": 1.5, "amplitude": 0.005, "start": 2.0, "stop": 9.0},
                {"kind": "chirp", "f_start": 0.5, "f_stop": 8, "duration": 5, "amplitude": 0.004,
                 "method": "logarithmic", "start": 10.0},
                {"kind": "multisine", "period": 2.0, "f_max": 10.0, "rms": 0.002},
                {"kind": "replay", "path": path.name, "column": "contact_wire_displacement",
                 "remove_mean": True},
                {"kind": "steps", "count": 2, "height": 0.002, "hold_time": 1.5, "start": 1.0}]},
            "pressure": {"offset": 4.0, "signals": [
                {"kind": "aprbs", "std": 0.5, "hold_min": 0.5, "hold_max": 2.0},
                {"kind": "ramps", "repetitions": 1, "height": 1.0, "gradient": 0.5}]}}


def test_stream_equals_render_and_seed_controls_randomness(tmp_path):
    data = full_profile_dict(tmp_path)
    profile = profile_from_dict(data, base_dir=tmp_path)
    rendered = render_profile(profile)
    streamed = list(ProfileStream(profile, chunk=333))
    assert len(streamed) == rendered.time.size == 10000
    for name in ("time", "motor_offset", "motor_dynamic", "pressure_demand", "led"):
        assert np.array_equal([getattr(s, name) for s in streamed], getattr(rendered, name))
    again = render_profile(profile_from_dict(data, base_dir=tmp_path))
    assert np.array_equal(again.motor_dynamic, rendered.motor_dynamic)
    assert np.array_equal(again.led, rendered.led)
    other = render_profile(replace(profile, seed=43))
    assert not np.allclose(other.motor_dynamic, rendered.motor_dynamic)
    assert not np.array_equal(other.led, rendered.led)


def test_profile_save_load_round_trip(tmp_path):
    profile = profile_from_dict(full_profile_dict(tmp_path), base_dir=tmp_path)
    path = save_profile(profile, tmp_path / "p.json")
    loaded = load_profile(path)
    assert loaded == profile and profile_to_dict(loaded) == profile_to_dict(profile)
    with pytest.raises(FileExistsError):
        save_profile(profile, path)


@pytest.mark.parametrize("path", sorted(p for p in PROFILES.glob("*.json")
                                         if not p.name.endswith(".csv.json")),
                         ids=lambda p: p.stem)
def test_example_profiles_load_and_stay_within_limits(path):
    profile = load_profile(path)
    run = render_profile(profile)
    assert np.all((run.motor_demand >= profile.limits.motor_min)
                  & (run.motor_demand <= profile.limits.motor_max))
    assert np.all((run.pressure_demand >= profile.limits.pressure_min)
                  & (run.pressure_demand <= profile.limits.pressure_max))


@pytest.mark.parametrize("change, expected", [
    (lambda d: d["motor"]["signals"].append({"kind": "wobble"}),
     r"motor\.signals\[6\].*kind = 'wobble': unknown signal kind"),
    (lambda d: d["pressure"]["signals"][0].update(hold_min=-0.5),
     r"pressure\.signals\[0\].*hold_min = -0\.5"),
    (lambda d: d["motor"]["signals"][1].update(amplitude=0.2),
     r"motor\.signals\[1\] \(sine.*outside the limits \[0\.0, 0\.3\] m"),
    (lambda d: d["motor"]["signals"][3].update(period=3.0),
     r"motor\.signals\[3\] \(multisine\).*whole number of periods"),
    (lambda d: d["motor"]["signals"][4].update(path="missing.csv"),
     r"motor\.signals\[4\] \(replay\).*not found"),
    (lambda d: d["limits"].pop("safe_pressure"), r"limits.*'safe_pressure'.*missing"),
    (lambda d: d["limits"].update(safe_pressure=9.0), r"safe_pressure = 9\.0"),
    (lambda d: d["motor"].update(offset=0.5), r"motor\.offset = 0\.5"),
    (lambda d: d.update(duration=20.0001), r"duration = 20\.0001"),
    (lambda d: d["led"] if d.update(led={"blink": 1}) else None, r"led.*unknown field.*blink"),
], ids=["kind", "hold", "amplitude", "periods", "file", "required", "safe", "offset",
        "duration", "field"])
def test_load_profile_names_file_field_and_value(tmp_path, change, expected):
    data = full_profile_dict(tmp_path)
    change(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ProfileError, match=expected) as caught:
        load_profile(path)
    assert str(path) in str(caught.value)


# --- LED -----------------------------------------------------------------------------------------

def test_led_hold_times_within_5_to_30_ms_at_500_hz():
    bits = generate_led_bits(200_000, rng(8))
    values, lengths = run_lengths(bits)
    inner = lengths[1:-1] / FS
    assert np.all(inner >= 0.005) and np.all(inner <= 0.030)
    assert set(np.unique(lengths[1:-1])) == set(range(3, 16))  # 6 ms .. 30 ms, all occur
    assert np.all(values[1:] != values[:-1]) and set(values.tolist()) == {0, 1}


def test_led_stream_equals_vectorised_and_seeds_differ():
    stream = LedStream(rng(9))
    assert np.array_equal([stream.next() for _ in range(20_000)],
                          generate_led_bits(20_000, rng(9)))
    assert not np.array_equal(generate_led_bits(5000, rng(9)), generate_led_bits(5000, rng(10)))
    assert not generate_led_bits(100, rng(9), LedOptions(enabled=False)).any()
