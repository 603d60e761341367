"""The thesis' dynamic DoE example (section 5.4): the one-mass oscillator as a discrete model.

The oscillator :math:`m \\ddot y + c \\dot y + k y = F` has :math:`G(s) = (1/m) / (s^2 + (c/m) s
+ k/m)`; held by a zero-order hold with sample period :math:`T_s` it becomes (eqs. 5.10-5.12)

.. math:: H(z) = \\frac{b_1 z^{-1} + b_2 z^{-2}}{1 + a_1 z^{-1} + a_2 z^{-2}},\\qquad
          \\theta = [a_1, a_2, b_1, b_2].

With m, c, k = 1 kg, 2 N s/m, 20 N/m and Ts = 0.1 s, :math:`\\theta` = [-1.6405, 0.8187,
0.0046, 0.0043] (eq. 5.24); with 2, 10, 25: [-1.5092, 0.6065, 0.0021, 0.0018] (eq. 5.25).

Sensitivities (eqs. 5.13-5.16). The model output :math:`y_m = (B/A) u` of an output-error
structure has the exact derivatives

.. math:: \\frac{\\partial y_m(k)}{\\partial a_i} = -\\frac{z^{-i}}{A(z)} y_m(k),\\qquad
          \\frac{\\partial y_m(k)}{\\partial b_j} = \\frac{z^{-j}}{A(z)} u(k),

i.e. the regressor :math:`[-y_m(k-1), -y_m(k-2), u(k-1), u(k-2)]` filtered by :math:`1/A`. They
are computed here by that recursion (two IIR filters, :func:`scipy.signal.lfilter`, compiled and
vectorised over a whole GA population). The thesis' eq. 5.13, which divides by
:math:`b_1 u(k-1) + b_2 u(k-2)`, is not the derivative of the model output (and is singular where
that sum vanishes), so it is not used; ``kind="equation_error"`` gives the unfiltered regressor,
the sensitivity of the one-step ARX predictor whose information is the inverse of the recursive
least-squares matrix P that the thesis reports (eqs. 5.26-5.28).

Estimators: :class:`RecursiveLeastSquares` (ARX, used on line by the online design),
:func:`fit_output_error` (Gauss-Newton on the output error, efficient: reaches the Cramer-Rao
bound) and :func:`fit_grey_box` (m, c, k of the continuous model, discretised by ZOH, output
error, as MATLAB's ``greyest``; Table 5.1).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm
from scipy.optimize import least_squares
from scipy.signal import lfilter

#: The thesis' example, eqs. 5.17-5.23.
TRUE_PHYSICAL = (1.0, 2.0, 20.0)        # m [kg], c [N s/m], k [N/m]
INITIAL_PHYSICAL = (2.0, 10.0, 25.0)
SAMPLE_PERIOD = 0.1                      # [s]
END_TIME = 30.0                          # [s]
RATE_LIMIT = 0.25                        # |du| [N per sample]
AMPLITUDE_LIMIT = 1.5                    # |u| [N]
NOISE_VARIANCE = 1e-10                   # sigma^2 [m^2]


def discretise_oscillator(mass: float, damping: float, stiffness: float,
                          sample_period: float = SAMPLE_PERIOD) -> np.ndarray:
    """ZOH discretisation of :math:`G(s) = 1 / (m s^2 + c s + k)` to :math:`\\theta` (eq. 5.10).

    With the state :math:`[y, \\dot y]`, :math:`A_d = e^{A T_s}`, :math:`B_d = \\int_0^{T_s}
    e^{A\\tau} d\\tau\\, B` (one matrix exponential of the augmented matrix); then
    :math:`a_1 = -\\operatorname{tr} A_d`, :math:`a_2 = \\det A_d`, :math:`b_1 = C B_d`,
    :math:`b_2 = C A_d B_d - \\operatorname{tr}(A_d) C B_d` (from
    :math:`\\operatorname{adj}(zI - A_d) = zI - \\operatorname{tr}(A_d) I + A_d`).

    Returns
    -------
    ndarray, shape (4,)
        :math:`[a_1, a_2, b_1, b_2]`.
    """
    for name, value in (("mass", mass), ("damping", damping), ("stiffness", stiffness),
                        ("sample_period", sample_period)):
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"oscillator {name} must be positive and finite, got {value!r}")
    augmented = np.zeros((3, 3))
    augmented[:2, :2] = [[0.0, 1.0], [-stiffness / mass, -damping / mass]]
    augmented[1, 2] = 1.0 / mass
    exponential = expm(augmented * sample_period)
    a_d, b_d = exponential[:2, :2], exponential[:2, 2]
    trace = np.trace(a_d)
    b1 = b_d[0]
    b2 = (a_d @ b_d)[0] - trace * b1
    return np.array([-trace, np.linalg.det(a_d), b1, b2])



def physical_from_theta(theta: Sequence[float], sample_period: float = SAMPLE_PERIOD, *,
                        initial: Sequence[float] = INITIAL_PHYSICAL) -> np.ndarray:
    """m, c, k whose ZOH discretisation best matches :math:`\\theta` (thesis section 5.4).

    Solves the four nonlinear equations ``discretise_oscillator(m, c, k) = theta`` for the three
    unknowns in the least-squares sense (each equation scaled by ``|theta_i|``), over log m, c, k.
    """
    theta = np.asarray(theta, float)
    scale = np.maximum(np.abs(theta), 1e-12)

    def residual(log_values: np.ndarray) -> np.ndarray:
        return (discretise_oscillator(*np.exp(log_values), sample_period) - theta) / scale

    result = least_squares(residual, np.log(np.asarray(initial, float)), xtol=1e-14, ftol=1e-14)
    return np.exp(result.x)

@dataclass(frozen=True)
class TransferFunctionModel:
    """SISO discrete transfer function :math:`y_m = B(z)/A(z)\\, u` (output error).

    :math:`\\theta = [a_1..a_{n_a}, b_1..b_{n_b}]`, :math:`A = 1 + \\sum a_i z^{-i}`,
    :math:`B = \\sum b_j z^{-j}`, zero initial state. Inputs are ``(..., N, 1)`` (or ``(..., N)``),
    outputs ``(..., N, 1)``, sensitivities ``(..., N, 1, n_a + n_b)``: the shapes the design
    machinery (:mod:`panto.identification.design.input_design`) takes for any model.
    """

    n_a: int = 2
    n_b: int = 2
    kind: str = "output_error"
    """``"output_error"`` (exact :math:`\\partial y_m/\\partial\\theta`) or ``"equation_error"``
    (the ARX regressor, sensitivity of the one-step predictor)."""
    input_names: tuple[str, ...] = ("F",)
    output_names: tuple[str, ...] = ("y",)

    def __post_init__(self) -> None:
        if self.kind not in ("output_error", "equation_error"):
            raise ValueError(f"kind must be 'output_error' or 'equation_error', got {self.kind!r}")
        if self.n_a < 1 or self.n_b < 1:
            raise ValueError(f"orders must be at least 1, got n_a={self.n_a}, n_b={self.n_b}")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """``a1..a_na, b1..b_nb``."""
        return tuple(f"a{i}" for i in range(1, self.n_a + 1)) + \
            tuple(f"b{j}" for j in range(1, self.n_b + 1))

    def _split(self, theta: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        theta = np.asarray(theta, float)
        if theta.shape != (self.n_a + self.n_b,):
            raise ValueError(f"theta must have {self.n_a + self.n_b} values "
                             f"{self.parameter_names}, got shape {theta.shape}")
        return np.r_[1.0, theta[:self.n_a]], np.r_[0.0, theta[self.n_a:]]

    def simulate(self, theta: Sequence[float], inputs: np.ndarray) -> np.ndarray:
        """Model output :math:`y_m`, shape ``(..., N, 1)``."""
        denominator, numerator = self._split(theta)
        return lfilter(numerator, denominator, _single_input(inputs), axis=-1)[..., None]

    def sensitivities(self, theta: Sequence[float],
                      inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Model output and :math:`\\psi = \\partial y_m / \\partial \\theta` (eqs. 5.13-5.16).

        Returns
        -------
        outputs : ndarray, shape (..., N, 1)
        sensitivities : ndarray, shape (..., N, 1, n_a + n_b)
        """
        denominator, numerator = self._split(theta)
        u = _single_input(inputs)
        y = lfilter(numerator, denominator, u, axis=-1)
        if self.kind == "output_error":
            filtered_y = lfilter([1.0], denominator, y, axis=-1)
            filtered_u = lfilter([1.0], denominator, u, axis=-1)
        else:
            filtered_y, filtered_u = y, u
        columns = [-_delay(filtered_y, i) for i in range(1, self.n_a + 1)] + \
            [_delay(filtered_u, j) for j in range(1, self.n_b + 1)]
        return y[..., None], np.stack(columns, axis=-1)[..., None, :]

    def regressor(self, inputs: np.ndarray, outputs: np.ndarray, k: int) -> np.ndarray:
        """ARX regressor :math:`\\varphi(k) = [-y(k-1) .. -y(k-n_a), u(k-1) .. u(k-n_b)]`.

        Samples before 0 are zero. `inputs`, `outputs` are 1-D histories (at least ``k`` long).
        """
        def past(signal: np.ndarray, lag: int) -> float:
            return float(signal[k - lag]) if k - lag >= 0 else 0.0
        u, y = np.ravel(inputs), np.ravel(outputs)
        return np.array([-past(y, i) for i in range(1, self.n_a + 1)] +
                        [past(u, j) for j in range(1, self.n_b + 1)])

    def is_stable(self, theta: Sequence[float]) -> bool:
        """All poles (roots of A) strictly inside the unit circle."""
        denominator, _ = self._split(theta)
        return bool(np.all(np.abs(np.roots(denominator)) < 1.0))


def _single_input(inputs: np.ndarray) -> np.ndarray:
    u = np.asarray(inputs, float)
    if u.ndim >= 2 and u.shape[-1] == 1:
        return u[..., 0]
    if u.ndim >= 2 and u.shape[-1] != 1 and u.ndim > 2:
        raise ValueError(f"a SISO model takes inputs (..., N, 1) or (..., N), got {u.shape}")
    return u


def _delay(signal: np.ndarray, lag: int) -> np.ndarray:
    delayed = np.zeros_like(signal)
    delayed[..., lag:] = signal[..., :signal.shape[-1] - lag]
    return delayed


def two_sine_input(n_samples: int = round(END_TIME / SAMPLE_PERIOD),
                   sample_period: float = SAMPLE_PERIOD, *,
                   amplitudes: tuple[float, float] = (0.75, 0.75),
                   frequencies: tuple[float, float] = (0.15, 0.35)) -> np.ndarray:
    """The thesis' conventional input and design start: two superposed sines (Fig. 5.3).

    :math:`u(t) = A_1 \\sin(2\\pi f_1 t) + A_2 \\sin(2\\pi f_2 t)`, t = 0, Ts, ...; the defaults
    keep :math:`|u| \\le 1.5` N and :math:`|\\Delta u| \\le 2\\pi T_s \\sum A_i f_i = 0.236` N
    (< 0.25 N). The thesis does not give its amplitudes and frequencies; these are ours (both
    below the resonance at 0.71 Hz; its RLS matrix P has diagonal [609, 875, 5.3, 8.7] on the
    true system, of the order of the thesis' eq. 5.26).
    """
    time = np.arange(n_samples) * sample_period
    return sum(a * np.sin(2 * np.pi * f * time) for a, f in zip(amplitudes, frequencies))


# --- estimators ------------------------------------------------------------------------------

@dataclass
class RecursiveLeastSquares:
    """Recursive least squares for :math:`y(k) = \\varphi(k)^T\\theta + e(k)`.

    Update (forgetting factor :math:`\\lambda`):
    :math:`K = P\\varphi / (\\lambda + \\varphi^T P \\varphi)`,
    :math:`\\theta \\leftarrow \\theta + K (y - \\varphi^T\\theta)`,
    :math:`P \\leftarrow (P - K \\varphi^T P) / \\lambda`. With :math:`P_0 = p_0 I` large,
    :math:`P \\approx (\\sum \\varphi\\varphi^T)^{-1}`, the matrix the thesis reports (eq. 5.26).
    """

    theta: np.ndarray
    covariance: np.ndarray
    forgetting: float = 1.0
    n_updates: int = field(default=0)

    @classmethod
    def start(cls, theta: Sequence[float], initial_covariance: float = 1e4,
              forgetting: float = 1.0) -> RecursiveLeastSquares:
        """RLS from a prior guess with :math:`P_0 = p_0 I`."""
        theta = np.array(theta, float)
        return cls(theta, initial_covariance * np.eye(theta.size), forgetting)

    def update(self, regressor: np.ndarray, measurement: float) -> np.ndarray:
        """Take one sample; returns the new estimate."""
        phi = np.asarray(regressor, float)
        gain = self.covariance @ phi / (self.forgetting + phi @ self.covariance @ phi)
        self.theta = self.theta + gain * (measurement - phi @ self.theta)
        self.covariance = (self.covariance - np.outer(gain, phi @ self.covariance)) / self.forgetting
        self.covariance = 0.5 * (self.covariance + self.covariance.T)
        self.n_updates += 1
        return self.theta


def fit_arx(model: TransferFunctionModel, inputs: np.ndarray, outputs: np.ndarray) -> np.ndarray:
    """Batch ARX least squares; `outputs` may be ``(R, N)`` realisations (returns ``(R, n)``)."""
    u = np.ravel(inputs)
    y = np.atleast_2d(np.asarray(outputs, float))
    theta = []
    for row in y:
        phi = np.array([model.regressor(u, row, k) for k in range(len(u))])
        theta.append(np.linalg.lstsq(phi, row, rcond=None)[0])
    return np.array(theta) if np.ndim(outputs) == 2 else theta[0]


def fit_output_error(model: TransferFunctionModel, inputs: np.ndarray, outputs: np.ndarray,
                     theta0: Sequence[float], *, iterations: int = 8) -> np.ndarray:
    """Output-error least squares by Gauss-Newton, :math:`\\min \\sum (y - y_m(\\theta))^2`.

    Each step solves :math:`\\Psi \\Delta\\theta \\approx y - y_m` with the output-error
    sensitivities :math:`\\Psi`; started near the optimum it converges in a few steps. For
    Gaussian output noise this is the maximum-likelihood estimator whose covariance tends to the
    Cramer-Rao bound :math:`\\sigma^2 (\\Psi^T\\Psi)^{-1}`.
    """
    oe = TransferFunctionModel(model.n_a, model.n_b, "output_error")
    theta = np.asarray(theta0, float).copy()
    y = np.ravel(outputs)
    for _ in range(iterations):
        simulated, psi = oe.sensitivities(theta, inputs)
        step = np.linalg.lstsq(psi[:, 0, :], y - simulated[:, 0], rcond=None)[0]
        theta = theta + step
        if np.all(np.abs(step) <= 1e-12 * (1.0 + np.abs(theta))):
            break
    return theta


@dataclass(frozen=True)
class GreyBoxEstimate:
    """m, c, k of the continuous oscillator fitted on sampled data (Table 5.1).

    Parameters
    ----------
    values : ndarray, shape (3,)
        [m kg, c N s/m, k N/m].
    covariance : ndarray, shape (3, 3)
        :math:`\\hat\\sigma^2 (J^T J)^{-1}` at the optimum.
    noise_variance : float
        Residual variance :math:`\\hat\\sigma^2` [m^2].
    success : bool
    message : str
    """

    values: np.ndarray
    covariance: np.ndarray
    noise_variance: float
    success: bool
    message: str

    @property
    def variances(self) -> np.ndarray:
        """Variance of m, c, k."""
        return np.diag(self.covariance)


def fit_grey_box(inputs: np.ndarray, outputs: np.ndarray,
                 sample_period: float = SAMPLE_PERIOD, *,
                 initial: Sequence[float] = INITIAL_PHYSICAL) -> GreyBoxEstimate:
    """Continuous-time grey-box estimate of m, c, k (as MATLAB's ``greyest``; Table 5.1).

    The model is :math:`G(s) = 1/(m s^2 + c s + k)` discretised by ZOH
    (:func:`discretise_oscillator`) and simulated from rest; the output error is minimised by
    :func:`scipy.optimize.least_squares` (trust-region reflective, m, c, k > 0) over
    :math:`\\log` m, c, k, from `initial`.
    """
    u, y = np.ravel(inputs), np.ravel(outputs)
    if u.shape != y.shape:
        raise ValueError(f"inputs ({u.size}) and outputs ({y.size}) differ in length")
    model = TransferFunctionModel()

    def residual(log_values: np.ndarray) -> np.ndarray:
        theta = discretise_oscillator(*np.exp(log_values), sample_period)
        return model.simulate(theta, u)[:, 0] - y

    scale = max(float(np.std(y)), 1e-300)
    result = least_squares(lambda p: residual(p) / scale, np.log(np.asarray(initial, float)),
                           method="trf", x_scale=1.0, xtol=1e-14, ftol=1e-14, gtol=1e-14,
                           max_nfev=2000)
    values = np.exp(result.x)
    noise_variance = float(np.sum((result.fun * scale) ** 2) / max(u.size - 3, 1))
    jacobian = result.jac * scale / values[None, :]     # d residual / d (m, c, k)
    covariance = noise_variance * np.linalg.pinv(jacobian.T @ jacobian)
    return GreyBoxEstimate(values, covariance, noise_variance, bool(result.success),
                           str(result.message))
