"""The motor-command conditioning chain: limiter bound, position limits, soft blend, reference
filter, streaming == vectorised, and the following-error bound against a simulated loop."""
import math

import numpy as np
import pytest

from panto.rig.conditioning import (ConditioningOptions, DynamicBlend, MotorConditioner, MotorLimits,
                              ReferenceFilter, following_error_bound, minimum_loop_bandwidth)

T = 0.004  # 250 Hz stream


def random_worst_case(rng, n):
    """Demands built to provoke the limiter: jumps, noise, far out-of-range values, holds."""
    kind = rng.integers(0, 4)
    if kind == 0:
        return rng.uniform(-1.0, 1.0, n)
    if kind == 1:
        return np.repeat(rng.uniform(-0.5, 0.8, n // 20 + 1), 20)[:n]
    if kind == 2:
        return np.cumsum(rng.normal(0.0, 0.02, n))
    return 0.15 + 0.2 * np.sign(np.sin(np.arange(n) * rng.uniform(0.01, 1.0)))


def test_limiter_bound_and_position_limits_never_exceeded():
    rng = np.random.default_rng(2024)
    for trial in range(60):
        low = rng.uniform(-0.1, 0.1)
        limits = MotorLimits(position_min=low, position_max=low + rng.uniform(0.05, 0.4),
                             max_step=rng.uniform(0.001, 0.01))
        options = ConditioningOptions(reference_filter=bool(trial % 2),
                                      blend_time_constant=rng.choice([0.0, 0.05, 0.5]))
        start = rng.uniform(-0.5, 0.5)  # may lie outside the limits: clipped in
        chain = MotorConditioner(options, limits, initial_position=start)
        n = 800
        offset, dynamic = rng.uniform(-0.3, 0.5, n), random_worst_case(rng, n)
        switch = (rng.uniform(size=n) > 0.3).astype(float)
        command = chain.apply(offset, dynamic, switch).command
        previous = np.concatenate([[chain.initial_position], command[:-1]])
        assert np.all(np.abs(command - previous) <= limits.max_step * (1 + 1e-12))
        assert np.all((command >= limits.position_min) & (command <= limits.position_max))


def test_limiter_is_transparent_for_slow_demands_and_caps_speed_at_1_25_m_per_s():
    limits = MotorLimits(position_min=0.0, position_max=0.3)
    options = ConditioningOptions(blend_time_constant=0.0)
    t = np.arange(2000) * T
    slow = 0.15 + 0.05 * np.sin(2 * np.pi * 1.0 * t)  # 0.31 m/s peak: never limited
    chain = MotorConditioner(options, limits, initial_position=0.15)
    result = chain.apply(np.zeros_like(t), slow)
    assert np.array_equal(result.command, slow) and not result.limited.any()
    jump = np.where(t < 1.0, 0.05, 0.25)  # a 200 mm step
    chain = MotorConditioner(options, limits, initial_position=0.05)
    command = chain.apply(np.zeros_like(t), jump).command
    speed = np.diff(command) / T
    assert math.isclose(speed.max(), 1.25, rel_tol=1e-9)  # 5 mm per 4 ms
    assert command[-1] == 0.25 and np.count_nonzero(speed > 1.0) == 40  # 200 mm / 5 mm
    unlimited = MotorConditioner(ConditioningOptions(blend_time_constant=0.0, limiter=False),
                                 limits, initial_position=0.05).apply(np.zeros_like(t), jump)
    assert np.max(np.diff(unlimited.command)) == pytest.approx(0.2)


def test_streaming_equals_vectorised():
    rng = np.random.default_rng(7)
    limits = MotorLimits(position_min=0.0, position_max=0.3)
    options = ConditioningOptions(reference_filter=True, filter_cutoff=15.0,
                                  blend_time_constant=0.2)
    n = 3000
    offset = np.full(n, 0.15)
    dynamic = np.repeat(rng.normal(0.0, 0.05, n // 25), 25)
    switch = (np.sin(np.arange(n) / 300.0) > -0.5).astype(float)
    chain = MotorConditioner(options, limits, initial_position=0.1)
    vector = chain.apply(offset, dynamic, switch)
    chain.reset()
    stream = [chain.step(o, d, s) for o, d, s in zip(offset, dynamic, switch)]
    assert np.array_equal([s.command for s in stream], vector.command)
    assert np.array_equal([s.limited for s in stream], vector.limited)
    assert vector.limited.any() and not vector.limited.all()


def test_blend_gain_is_the_first_order_step_response():
    tau = 0.3
    blend = DynamicBlend(tau, 250.0)
    gains = np.array([blend.step(1.0) for _ in range(1000)])
    k = np.arange(1, 1001)
    assert np.allclose(gains, 1.0 - np.exp(-k * T / tau), rtol=0, atol=1e-12)


def test_blend_removes_the_jump_of_a_setting_change():
    """Sine at 2 Hz, switched to 5 Hz with a phase jump while the switch is 0: no jump."""
    amplitude, tau = 0.02, 0.1
    t = np.arange(5000) * T
    change = 10.0
    dynamic = np.where(t < change, amplitude * np.sin(2 * np.pi * 2.0 * t),
                       amplitude * np.sin(2 * np.pi * 5.0 * t + 2.0))
    switch = np.where((t > change - 1.0) & (t < change + 0.5), 0.0, 1.0)
    limits = MotorLimits(position_min=-1.0, position_max=1.0)
    options = ConditioningOptions(blend_time_constant=tau, limiter=False)
    blended = MotorConditioner(options, limits, initial_position=0.0).apply(0.0, dynamic,
                                                                           switch)
    alpha = 1.0 - math.exp(-T / tau)
    # |g_k d_k - g_{k-1} d_{k-1}| <= alpha |d| + |d_k - d_{k-1}| on the continuous pieces
    bound = alpha * amplitude + amplitude * 2 * np.pi * 5.0 * T
    after_fade_in = t > 5 * tau
    assert np.max(np.abs(np.diff(blended.command))[after_fade_in[1:]]) <= bound
    raw = MotorConditioner(options, limits, initial_position=0.0).apply(
        0.0, dynamic, np.ones_like(t))
    assert np.max(np.abs(np.diff(raw.command))) > 2 * bound  # the jump the blend removes
    assert np.allclose(blended.command[t > change + 2.0], raw.command[t > change + 2.0],
                       atol=amplitude * math.exp(-1.4 / tau))


def test_reference_filter_is_a_unity_gain_butterworth():
    fs, cutoff = 250.0, 10.0
    filt = ReferenceFilter(cutoff, fs)
    step = [filt.step(1.0) for _ in range(500)]
    assert step[-1] == pytest.approx(1.0, abs=1e-9)
    t = np.arange(5000) / fs
    out = ReferenceFilter(cutoff, fs).apply(np.sin(2 * np.pi * cutoff * t))
    tail = t > 5.0  # after the transient: fit a sin + b cos
    basis = np.column_stack([np.sin(2 * np.pi * cutoff * t), np.cos(2 * np.pi * cutoff * t)])
    coef, *_ = np.linalg.lstsq(basis[tail], out[tail], rcond=None)
    assert np.hypot(*coef) == pytest.approx(1 / math.sqrt(2), abs=1e-6)  # -3 dB at cut-off
    stream = ReferenceFilter(cutoff, fs)
    noise = np.random.default_rng(1).normal(size=2000)
    assert np.array_equal([stream.step(x) for x in noise], ReferenceFilter(cutoff, fs).apply(noise))


def simulate_first_order_loop(command, bandwidth, delay_periods, substeps=40):
    """Drive with 1.5-period setpoint delay, linear interpolation and a first-order loop,
    integrated exactly on a fine grid; returns the error against the undelayed setpoint."""
    dt = T / substeps
    n = command.size
    fine_t = np.arange(n * substeps) * dt
    setpoint = np.interp(fine_t, np.arange(n) * T, command)  # what the master streamed
    reference = np.interp(fine_t - delay_periods * T, np.arange(n) * T, command)
    decay = math.exp(-bandwidth * dt)
    x = np.empty_like(reference)
    x[0] = command[0]
    for k in range(1, x.size):  # exact for a reference linear over dt
        r0, r1 = reference[k - 1], reference[k]
        slope = (r1 - r0) / dt
        x[k] = (r1 - slope / bandwidth) + (x[k - 1] - r0 + slope / bandwidth) * decay
    return setpoint - x


def test_following_error_bound_holds_and_is_tight_for_a_first_order_loop():
    bandwidth = minimum_loop_bandwidth()  # the bandwidth at which the bound is exactly 30 mm
    assert following_error_bound(bandwidth=bandwidth) == pytest.approx(0.030, rel=1e-12)
    bound = following_error_bound(bandwidth=60.0)
    numeric = following_error_bound(closed_loop=([60.0], [1.0, 60.0]))
    assert numeric == pytest.approx(bound, rel=1e-4)  # integral of |1 - h| = 1/omega
    rng = np.random.default_rng(5)
    limits = MotorLimits(position_min=-1.0, position_max=1.0)
    chain = MotorConditioner(ConditioningOptions(blend_time_constant=0.0), limits,
                             initial_position=0.0)
    demand = np.concatenate([np.repeat(rng.uniform(-0.4, 0.4, 8), 60), np.full(120, 0.0)])
    command = chain.apply(0.0, demand).command
    error = simulate_first_order_loop(command, 60.0, 1.5)
    assert np.max(np.abs(error)) <= bound
    assert np.max(np.abs(error)) > 0.95 * bound  # long limited ramps nearly reach it
    assert np.max(np.abs(error)) < 0.030  # so the 30 mm fault cannot trip


def test_following_error_bound_of_second_order_loops():
    """For G = wn^2 / (s^2 + 2 zeta wn s + wn^2), the signed integral of 1 - h is 2 zeta / wn
    (final-value theorem on (1 - G)/s); without overshoot (zeta >= 1) |1 - h| = 1 - h, so the
    bound is exactly v (d + 2 zeta / wn); with overshoot it is strictly larger."""
    wn, speed, delay = 80.0, 0.005 / T, 1.5 * T
    for zeta in (1.0, 1.5):
        bound = following_error_bound(closed_loop=([wn ** 2], [1.0, 2 * zeta * wn, wn ** 2]))
        assert bound == pytest.approx(speed * (delay + 2 * zeta / wn), rel=1e-4)
    under = following_error_bound(closed_loop=([wn ** 2], [1.0, 2 * 0.2 * wn, wn ** 2]))
    assert under > 1.2 * speed * (delay + 2 * 0.2 / wn)
    with pytest.raises(ValueError, match="stable"):
        following_error_bound(closed_loop=([1.0], [1.0, -1.0]))
