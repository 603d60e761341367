"""Output sensitivities of the pantograph structures for experiment design (thesis section 5.5).

The thesis designs inputs for "one of the system structures described in Chapter 2 ...
transferred into a discrete-time transfer function". :class:`LinearisedPantograph` does that for
``"physical-linear"`` (the physical model linearised about its equilibrium,
:class:`panto.identification.structures.physical.PhysicalLinear`), ``"two-mass"`` and ``"three-mass"``
(:class:`panto.identification.structures.oscillators.OscillatorStructure`): about the operating point
:math:`u_0 = (\\eta_0, p_0)` the structure is

.. math:: x_{k+1} = \\Phi x_k + \\Gamma_0 \\Delta u_k + \\Gamma_1 (\\Delta u_{k+1} - \\Delta u_k),
          \\qquad y_k = y_0(\\theta) + C x_k + D \\Delta u_k

(exact first-order-hold discretisation, :func:`panto.identification.structures.linearisation.discretise`, the
convention of the FMUs and of ``PhysicalLinear``), started at rest (:math:`x_0 = 0`,
:math:`\\Delta u_0 = 0`). With :math:`z_k = x_k - \\Gamma_1 \\Delta u_k` it is the ordinary system
:math:`(\\Phi, \\Phi\\Gamma_1 + \\Gamma_0 - \\Gamma_1, C, C\\Gamma_1 + D)`, so the output is the
convolution :math:`y_k = y_0 + \\sum_j g_j \\Delta u_{k-j}` with the Markov parameters
:math:`g_0 = C\\Gamma_1 + D`, :math:`g_j = C \\Phi^{j-1} (\\Phi\\Gamma_1 + \\Gamma_0 - \\Gamma_1)`.

The output sensitivities (eq. 5.6 needs :math:`\\psi = \\partial y / \\partial \\theta`) are then

.. math:: \\psi_{k,i} = \\frac{\\partial y_0}{\\partial \\theta_i}
          + \\sum_j \\frac{\\partial g_j}{\\partial \\theta_i} \\Delta u_{k-j},

with :math:`\\partial g_j / \\partial \\theta_i` and :math:`\\partial y_0 / \\partial \\theta_i`
by central differences of the structure's own linearisation (relative step), computed once.
A whole GA population is scored by one FFT convolution (:meth:`LinearisedPantograph.sensitivities`).

The bellow's slow response (thesis section 5.5: "much more limiting is the slow dynamic response
of the pneumatic actuator") is part of the input path: the design variable is the pressure
*demand* :math:`p^*`, and the model sees the measured pressure, a first-order lag with delay
(:class:`PressureLag`, fitted to the rig's PI loop and valve by :func:`pressure_lag_from_rig`).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import fft

from panto.identification.estimation.base import IdentificationError
from panto.identification.structures.linearisation import discretise

STRUCTURES = ("physical-linear", "two-mass", "three-mass")
OUTPUT_NAMES = ("y_cb", "xi", "F_c")
INPUT_NAMES = ("eta", "p")


@dataclass(frozen=True)
class PressureLag:
    """Pressure demand to measured pressure: :math:`\\tau \\dot p = p^*(t - t_d) - p`.

    Sampled with a zero-order hold at period :math:`T`:
    :math:`p_{k+1} = a p_k + (1 - a) p^*_{k - n_d}`, :math:`a = e^{-T/\\tau}`,
    :math:`n_d = \\operatorname{round}(t_d / T)`.

    Parameters
    ----------
    time_constant : float
        :math:`\\tau` [s] (> 0).
    delay : float
        :math:`t_d` [s] (>= 0).
    """

    time_constant: float = 0.4
    delay: float = 0.02

    def __post_init__(self) -> None:
        if not (math.isfinite(self.time_constant) and self.time_constant > 0):
            raise ValueError(f"PressureLag.time_constant = {self.time_constant!r}: must be > 0 s")
        if not (math.isfinite(self.delay) and self.delay >= 0):
            raise ValueError(f"PressureLag.delay = {self.delay!r}: must be >= 0 s")

    def impulse_response(self, period: float, length: int) -> np.ndarray:
        """Discrete impulse response :math:`h_j` (``length`` samples) of demand -> pressure."""
        a = math.exp(-period / self.time_constant)
        first = int(round(self.delay / period)) + 1
        h = np.zeros(length)
        if first < length:
            h[first:] = (1.0 - a) * a ** np.arange(length - first)
        return h

    def apply(self, demand: np.ndarray, period: float, start: float) -> np.ndarray:
        """Measured pressure for demands ``(..., N)`` [bar], from rest at `start` [bar]."""
        demand = np.asarray(demand, float)
        h = self.impulse_response(period, demand.shape[-1])
        return start + convolve(h, demand - start)


def convolve(kernel: np.ndarray, signal: np.ndarray) -> np.ndarray:
    """Causal convolution along the last axis, truncated to the signal length (FFT)."""
    n = signal.shape[-1]
    size = fft.next_fast_len(2 * n)
    return fft.irfft(fft.rfft(kernel, size) * fft.rfft(signal, size), size)[..., :n]


def pressure_lag_from_rig(*, pressure: float = 4.0, step: float = 0.3,
                          valve=None, controller=None) -> PressureLag:
    """The measured-pressure response of the rig's pressure loop to a demand step, as a lag.

    Simulates :class:`panto.rig.pressure.PressureController` on :class:`panto.rig.pneumatics.ValvePlant`
    (the virtual test bed's loop, 2 ms) for a demand step `pressure` -> `pressure` + `step` and
    returns the valve's transport delay and the time constant at which 63.2 % of the step is
    reached after it.
    """
    from panto.rig.pneumatics import ValveParameters, ValvePlant
    from panto.rig.pressure import PressureController, PressureControllerOptions

    valve = valve or ValveParameters()
    options = controller or PressureControllerOptions()
    plant = ValvePlant(valve, initial_pressure=pressure)
    loop = PressureController(options, initial_voltage=float(valve.voltage_for(pressure)))
    dt, measured, history = options.sample_time, pressure, []
    for _ in range(int(round(5.0 / dt))):
        measured = plant.step(loop.step(pressure + step, measured), dt)
        history.append(measured)
    reached = np.flatnonzero(np.asarray(history) >= pressure + (1 - math.exp(-1)) * step)
    if reached.size == 0:
        raise ValueError(f"the pressure loop does not reach 63 % of a {step} bar step in 5 s")
    return PressureLag(max((reached[0] + 1) * dt - valve.delay, dt), valve.delay)


def _structure(name: str, outputs: Sequence[str], fixed: Mapping[str, float]):
    if name == "physical-linear":
        from panto.identification.structures.physical import PhysicalLinear

        return PhysicalLinear(outputs=outputs, fixed=fixed, operating_point="first")
    if name in ("two-mass", "three-mass"):
        from panto.identification.structures.oscillators import OscillatorStructure

        if fixed:
            raise IdentificationError(f"{name}: fixed values are given as parameters")
        return OscillatorStructure(2 if name == "two-mass" else 3, outputs=outputs)
    raise IdentificationError(f"structure {name!r}: choose from {STRUCTURES}")


class LinearisedPantograph:
    """A pantograph structure, discrete-time about its operating point, with sensitivities.

    Parameters
    ----------
    structure : {"physical-linear", "two-mass", "three-mass"}
    parameters : mapping, optional
        Values of structure parameters (default: the structure's nominal values); for
        ``physical-linear`` other model parameters (geometry) are held as ``fixed``.
    free : sequence of str, optional
        Parameters to design for (default: the structure's ``default_free()``).
    outputs : sequence of str
        Measured outputs, of ``("y_cb", "xi", "F_c")``.
    operating_point : (float, float)
        :math:`(\\eta_0, p_0)` [m, bar]: the inputs at rest before and at the first sample.
    sample_period : float
        :math:`T` [s] (0.02 s: the identification's 50 Hz, thesis 4.2).
    length : int
        Samples :math:`N` per experiment (impulse responses are computed this long).
    pressure_lag : PressureLag or None
        Demand -> measured pressure; None: the pressure input is the measured pressure.
    relative_step : float
        Central-difference step relative to each parameter (absolute for zero values).

    Notes
    -----
    Inputs to :meth:`simulate` and :meth:`sensitivities` are *absolute* ``(eta, p*)`` samples,
    shape ``(..., N, 2)``; their first sample should equal the operating point (rest start).
    """

    def __init__(self, structure: str = "physical-linear", parameters: Mapping[str, float] | None = None,
                 free: Sequence[str] | None = None, *, outputs: Sequence[str] = ("F_c", "y_cb"),
                 operating_point: tuple[float, float] = (2.0, 4.0), sample_period: float = 0.02,
                 length: int = 3000, pressure_lag: PressureLag | None = PressureLag(),
                 relative_step: float = 1e-5, fixed: Mapping[str, float] | None = None) -> None:
        self.structure = _structure(structure, tuple(OUTPUT_NAMES), dict(fixed or {}))
        self.structure_name = structure
        self.output_names = tuple(outputs)
        bad = [o for o in self.output_names if o not in OUTPUT_NAMES]
        if bad or not self.output_names:
            raise IdentificationError(f"outputs {list(outputs)}: choose from {OUTPUT_NAMES}")
        values = self.structure.nominal() | {k: float(v) for k, v in (parameters or {}).items()}
        unknown = sorted(set(values) - set(self.structure.parameter_names))
        if unknown:
            raise IdentificationError(f"{structure}: unknown parameter(s) {unknown}; known: "
                                      f"{list(self.structure.parameter_names)}")
        self.parameters = values
        self.parameter_names = tuple(free) if free is not None else tuple(self.structure.default_free())
        unknown = [n for n in self.parameter_names if n not in values]
        if unknown or not self.parameter_names:
            raise IdentificationError(f"{structure}: free parameter(s) {unknown or '(none)'} not "
                                      f"in {list(self.structure.parameter_names)}")
        if length < 2 or not sample_period > 0:
            raise IdentificationError(f"length = {length} and sample_period = {sample_period}: "
                                      "need >= 2 samples and a period > 0")
        self.operating_point = (float(operating_point[0]), float(operating_point[1]))
        self.sample_period, self.length = float(sample_period), int(length)
        self.pressure_lag = pressure_lag
        self.theta = np.array([values[n] for n in self.parameter_names])
        self._build(relative_step)

    @staticmethod
    def structure_for(name: str):
        """The identification structure behind `name` (for its parameter names and defaults)."""
        return _structure(name, tuple(OUTPUT_NAMES), {})

    # --- the discrete-time model ----------------------------------------------------------

    def continuous(self, values: Mapping[str, float]) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, y0)`` about the operating point, all three outputs, inputs (eta, p)."""
        eta0, p0 = self.operating_point
        if self.structure_name == "physical-linear":
            a, b, c, d, _, y0 = self.structure.linear_model(values, (eta0, p0))
            return a, b, c, d, np.asarray(y0, float)
        a, b, c, d = self.structure.matrices(values)
        x0 = self.structure.equilibrium(values, eta0, p0)
        y0 = c @ x0 + d @ np.array([eta0, p0, 1.0])
        return a, b[:, :2], c, d[:, :2], y0

    def markov(self, values: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """Markov parameters ``g`` (N, 3, 2) and equilibrium outputs ``y0`` (3,) (module notes)."""
        a, b, c, d, y0 = self.continuous(values)
        phi, gamma0, gamma1 = discretise(a, b, self.sample_period, "foh")
        if np.max(np.abs(np.linalg.eigvals(phi))) >= 1.0:
            raise IdentificationError(f"{self.structure_name}: unstable at {dict(values)}")
        drive = phi @ gamma1 + gamma0 - gamma1
        g = np.empty((self.length, c.shape[0], b.shape[1]))
        g[0] = c @ gamma1 + d
        state = drive
        for j in range(1, self.length):
            g[j] = c @ state
            state = phi @ state
        if self.pressure_lag is not None:
            lag = self.pressure_lag.impulse_response(self.sample_period, self.length)
            g[:, :, 1] = convolve(lag, g[:, :, 1].T).T
        return g, y0

    def _build(self, relative_step: float) -> None:
        rows = [OUTPUT_NAMES.index(o) for o in self.output_names]
        g, y0 = self.markov(self.parameters)
        self.impulse = g                       # (N, 3, 2), all outputs
        self.equilibrium_outputs = y0          # (3,)
        n = len(self.parameter_names)
        self.impulse_sensitivity = np.empty((n, self.length, len(rows), 2))
        self.equilibrium_sensitivity = np.empty((n, len(rows)))
        for i, name in enumerate(self.parameter_names):
            value = self.parameters[name]
            h = relative_step * (abs(value) if value != 0 else 1.0)
            (g_up, y_up), (g_down, y_down) = (self.markov(self.parameters | {name: value + s})
                                              for s in (h, -h))
            self.impulse_sensitivity[i] = (g_up - g_down)[:, rows] / (2 * h)
            self.equilibrium_sensitivity[i] = (y_up - y_down)[rows] / (2 * h)
        self._rows = rows
        size = fft.next_fast_len(2 * self.length)
        self._fft_size = size
        self._impulse_fft = fft.rfft(self.impulse, size, axis=0)                  # (F, 3, 2)
        spectrum = fft.rfft(self.impulse_sensitivity, size, axis=1)  # (n_theta, F, o, 2)
        self._sensitivity_fft = np.ascontiguousarray(
            spectrum.transpose(1, 3, 2, 0).reshape(spectrum.shape[1], 2, -1))

    # --- evaluation ------------------------------------------------------------------------

    def _deviations(self, inputs: np.ndarray) -> tuple[np.ndarray, int]:
        u = np.asarray(inputs, float)
        if u.shape[-1] != 2 or u.ndim < 2 or u.shape[-2] > self.length:
            raise IdentificationError(f"inputs must have shape (..., N <= {self.length}, 2), got "
                                      f"{u.shape}")
        n = u.shape[-2]
        du = u - np.array(self.operating_point)
        return fft.rfft(du, self._fft_size, axis=-2), n

    def simulate(self, inputs: np.ndarray, outputs: Sequence[str] | None = None) -> np.ndarray:
        """Outputs ``(..., N, n_outputs)`` for absolute inputs ``(..., N, 2)`` (eta, p*)."""
        rows = [OUTPUT_NAMES.index(o) for o in (outputs or self.output_names)]
        spectrum, n = self._deviations(inputs)
        y = fft.irfft(np.einsum("...fi,foi->...fo", spectrum, self._impulse_fft[:, rows]),
                      self._fft_size, axis=-2)[..., :n, :]
        return y + self.equilibrium_outputs[rows]

    def sensitivities(self, theta: Sequence[float] | None, inputs: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Outputs ``(..., N, n_out)`` and :math:`\\psi` ``(..., N, n_out, n_theta)``.

        `theta` is accepted for :class:`panto.identification.design.input_design.SensitivityModel` and must be
        None or the model's own parameters: the model is linearised at them.
        """
        if theta is not None and not np.allclose(theta, self.theta, rtol=1e-9):
            raise IdentificationError("LinearisedPantograph is evaluated at its own parameters; "
                                      "build a new one for other values")
        spectrum, n = self._deviations(inputs)
        kernel = self._sensitivity_fft  # (F, 2, n_out * n_theta)
        product = spectrum[..., 0, None] * kernel[:, 0] + spectrum[..., 1, None] * kernel[:, 1]
        psi = fft.irfft(product, self._fft_size, axis=-2)[..., :n, :]
        psi = psi.reshape(*psi.shape[:-1], len(self.output_names), len(self.parameter_names))
        return self.simulate(inputs), psi + self.equilibrium_sensitivity.T

    def fisher(self, inputs: np.ndarray, noise_variance: Sequence[float] | np.ndarray
               ) -> np.ndarray:
        """Fisher information (eq. 5.6) ``(..., n_theta, n_theta)`` of absolute inputs
        ``(..., N, 2)``: :math:`M = \\sum_k \\sum_j \\psi_{kj}\\psi_{kj}^T / \\sigma_j^2`."""
        _, psi = self.sensitivities(None, inputs)
        weighted = psi / np.sqrt(np.asarray(noise_variance, float))[:, None]
        stacked = weighted.reshape(*weighted.shape[:-3], -1, weighted.shape[-1])
        return np.matmul(np.swapaxes(stacked, -1, -2), stacked)

    def noise_variance_default(self) -> np.ndarray:
        """:math:`\\sigma^2` per output from the rig's sensor noise (:class:`panto.rig.imperfections.
        RigImperfections`): force noise, laser noise / 2 for the mean of the two lasers."""
        from panto.rig.imperfections import RigImperfections

        imp = RigImperfections()
        variance = {"F_c": imp.force_noise ** 2, "y_cb": imp.laser_noise ** 2 / 2.0,
                    "xi": imp.laser_noise ** 2}
        return np.array([variance[o] for o in self.output_names])
