"""The compiled stick-slip kernel (:mod:`panto.identification.diagnosis.stick_slip`): the same
states as the NumPy loop on random stable mechanisms in the sticking, sliding and mixed regimes,
with a zero gain, with NaN and inf in the drive; the fallback without a compiler; and Coulomb's
law itself on a single mass (at rest below the friction level, accelerating with
``(F - level) / m`` above, stopping in ``m v0 / level`` and staying stopped)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from panto.identification.diagnosis import stick_slip


def _discretise(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation ``(Phi, Gamma)`` by the augmented exponential."""
    n, m = b.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n], block[:n, n:] = a, b
    exponential = expm(block * h)
    return exponential[:n, :n], exponential[:n, n:]


def _mechanism(seed: int, samples: int = 2000):
    """Two masses on springs and dampers, a piecewise-constant random force on the first (the
    input the friction is counted in) and one on the second: ``(phi, drive, x0, column)``."""
    rng = np.random.default_rng(seed)
    m1, m2 = rng.uniform(0.5, 2.0, 2)
    k1, k2 = rng.uniform(50.0, 400.0, 2)
    c1, c2 = rng.uniform(0.5, 5.0, 2)
    stiffness = np.array([[-(k1 + k2), k2], [k2, -k2]])
    damping = np.array([[-(c1 + c2), c2], [c2, -c2]])
    mass = np.diag([1 / m1, 1 / m2])
    a = np.block([[np.zeros((2, 2)), np.eye(2)], [mass @ stiffness, mass @ damping]])
    b = np.vstack([np.zeros((2, 2)), mass])
    phi, gamma = _discretise(a, b, 0.01)
    forces = np.repeat(rng.uniform(-10.0, 10.0, (samples // 25 + 1, 2)), 25, axis=0)[:samples]
    x0 = rng.normal(0.0, 0.01, 4)
    return phi, forces @ gamma.T, x0, gamma[:, 0]


def _both(phi, drive, x0, column, joint, level, monkeypatch):
    """The states by the compiled kernel and by the NumPy loop."""
    if stick_slip.load_kernel() is None:
        pytest.skip("no C compiler: the compiled kernel cannot be built")
    with monkeypatch.context() as patch:
        patch.setattr(stick_slip, "USE_COMPILED", True)
        assert stick_slip.active_backend() == "compiled"
        compiled = stick_slip.run_stick_slip(phi, drive, x0, column, joint, level)
        patch.setattr(stick_slip, "USE_COMPILED", False)
        assert stick_slip.active_backend() == "numpy"
        reference = stick_slip.run_stick_slip(phi, drive, x0, column, joint, level)
    return compiled, reference


def _stuck_steps(states: np.ndarray, joint: int, scale: float) -> int:
    """Steps after which the joint's velocity is zero (to rounding of the velocity `scale`):
    the joint stuck."""
    return int(np.sum(np.abs(states[1:, joint]) <= 1e-12 * scale))


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("regime, level, stuck_range", [
    ("sticking", 1e4, (1.0, 1.0)), ("sliding", 1e-3, (0.0, 0.02)), ("mixed", 4.0, (0.1, 0.9))])
def test_compiled_kernel_equals_the_numpy_loop(seed, regime, level, stuck_range, monkeypatch):
    phi, drive, x0, column = _mechanism(seed)
    compiled, reference = _both(phi, drive, x0, column, 2, level, monkeypatch)
    scale = np.max(np.abs(reference), axis=0)
    np.testing.assert_allclose(compiled, reference, rtol=1e-12, atol=1e-12 * scale.max())
    free = stick_slip.run_stick_slip(phi, drive, x0, column, 2, 0.0)  # no friction
    velocity = np.max(np.abs(free[:, 2]))
    fraction = _stuck_steps(reference, 2, velocity) / (len(reference) - 1)
    assert stuck_range[0] <= fraction <= stuck_range[1], (regime, fraction)
    assert _stuck_steps(compiled, 2, velocity) == _stuck_steps(reference, 2, velocity)


def test_zero_gain_applies_no_friction(monkeypatch):
    phi, drive, x0, column = _mechanism(4, samples=500)
    column = column.copy()
    column[2] = 0.0
    compiled, reference = _both(phi, drive, x0, column, 2, 5.0, monkeypatch)
    free = np.empty_like(reference)
    free[0] = x0
    for k, row in enumerate(drive):
        free[k + 1] = phi @ free[k] + row
    scale = np.max(np.abs(free))
    np.testing.assert_allclose(reference, free, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(compiled, free, rtol=0, atol=1e-13 * scale)


def test_nan_and_inf_in_the_drive_behave_as_in_the_numpy_loop(monkeypatch):
    phi, drive, x0, column = _mechanism(5, samples=300)
    level, joint = 4.0, 2
    drive = drive.copy()
    drive[100, joint] = np.nan  # f* is NaN: Python's min(level, max(-level, nan)) is -level
    drive[200, 0] = np.inf
    compiled, reference = _both(phi, drive, x0, column, joint, level, monkeypatch)
    for states in (compiled, reference):
        expected = phi @ states[100] + drive[100] - level * column
        others = [i for i in range(4) if i != joint]
        np.testing.assert_allclose(states[101, others], expected[others], rtol=1e-12)
        assert np.isnan(states[101, joint]) and np.all(np.isnan(states[102:]))
        assert np.all(np.isfinite(states[:101]))
    np.testing.assert_array_equal(np.isnan(compiled), np.isnan(reference))
    np.testing.assert_allclose(compiled, reference, rtol=1e-12, equal_nan=True)
    # inf alone (no NaN before it): f* is -inf / gain, clipped to the level
    drive[100, joint] = 0.0
    compiled, reference = _both(phi, drive, x0, column, joint, level, monkeypatch)
    np.testing.assert_array_equal(np.isnan(compiled), np.isnan(reference))
    np.testing.assert_array_equal(np.isinf(compiled), np.isinf(reference))
    assert np.isinf(reference[201, 0]) and np.all(np.isfinite(reference[:201]))
    finite = np.isfinite(reference)
    np.testing.assert_allclose(compiled[finite], reference[finite], rtol=1e-12,
                               atol=1e-12 * np.max(np.abs(reference[:201])))


def _single_mass(mass: float, h: float, force: float, samples: int):
    """A free mass (states q, v) under a constant force, exactly discretised (``Phi`` and
    ``Gamma`` in closed form; with binary fractions every product is exact)."""
    phi, gamma = np.array([[1.0, h], [0.0, 1.0]]), np.array([h ** 2 / (2 * mass), h / mass])
    return phi, np.tile(gamma * force, (samples, 1)), gamma


@pytest.mark.parametrize("compiled", [True, False])
def test_coulomb_law_on_a_single_mass(compiled, monkeypatch):
    if compiled and stick_slip.load_kernel() is None:
        pytest.skip("no C compiler: the compiled kernel cannot be built")
    monkeypatch.setattr(stick_slip, "USE_COMPILED", compiled)
    mass, h, level, samples = 2.0, 1 / 16, 5.0, 64
    time = h * np.arange(samples + 1)
    # below the level: the mass stays exactly at rest
    phi, drive, column = _single_mass(mass, h, 3.0, samples)
    at_rest = stick_slip.run_stick_slip(phi, drive, np.zeros(2), column, 1, level)
    assert np.all(at_rest == 0.0)
    # above: it accelerates with (F - level) / m
    phi, drive, column = _single_mass(mass, h, 8.0, samples)
    sliding = stick_slip.run_stick_slip(phi, drive, np.zeros(2), column, 1, level)
    acceleration = (8.0 - level) / mass
    np.testing.assert_allclose(sliding[:, 1], acceleration * time, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(sliding[:, 0], acceleration * time ** 2 / 2, rtol=1e-13, atol=1e-15)
    # no force, moving at v0 = 1 m/s: decelerates with level / m, stops at m v0 / level (on a
    # sample: level 4 N) after m v0^2 / (2 level) and stays stopped
    level = 4.0
    phi, drive, column = _single_mass(mass, h, 0.0, samples)
    stopping = stick_slip.run_stick_slip(phi, drive, np.array([0.0, 1.0]), column, 1, level)
    expected = np.maximum(1.0 - level / mass * time, 0.0)
    np.testing.assert_allclose(stopping[:, 1], expected, rtol=0, atol=1e-14)
    stop = mass * 1.0 / level
    assert np.all(stopping[time >= stop, 1] == 0.0) and np.all(stopping[time < stop, 1] > 0.0)
    np.testing.assert_allclose(stopping[time >= stop, 0], mass * 1.0 ** 2 / (2 * level),
                               rtol=1e-14)


def test_fallback_without_a_compiler(tmp_path, monkeypatch):
    phi, drive, x0, column = _mechanism(6, samples=400)
    monkeypatch.setattr(stick_slip, "USE_COMPILED", False)
    reference = stick_slip.run_stick_slip(phi, drive, x0, column, 2, 4.0)
    monkeypatch.setattr(stick_slip, "USE_COMPILED", True)
    monkeypatch.setattr(stick_slip, "_compiler", lambda: None)
    monkeypatch.setenv("PANTO_KERNEL_CACHE", str(tmp_path))
    stick_slip.load_kernel.cache_clear()
    try:
        assert stick_slip.load_kernel() is None and stick_slip.active_backend() == "numpy"
        np.testing.assert_array_equal(stick_slip.run_stick_slip(phi, drive, x0, column, 2, 4.0),
                                      reference)
        assert not any(tmp_path.iterdir())
    finally:
        stick_slip.load_kernel.cache_clear()


def test_switch_variable_selects_the_numpy_loop(monkeypatch):
    monkeypatch.setenv(stick_slip.SWITCH_VARIABLE, "0")
    assert stick_slip.active_backend() == "numpy"


def test_mismatched_shapes_are_refused():
    with pytest.raises(ValueError, match="joint 5"):
        stick_slip.run_stick_slip(np.eye(2), np.zeros((3, 2)), np.zeros(2), np.ones(2), 5, 1.0)
