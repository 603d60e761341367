"""The collector head alone (thesis sections 2.2 and 4.3): PT2 transfer functions and m, c, k.

The head is a one-degree-of-freedom oscillator on the cross bar. With ``Delta Y = y_cb - xi``
(cross bar minus head) and the contact force ``F`` (pressing down on the head), its equation
``m Delta'' + c Delta' + k Delta = F + m y_cb''`` gives (eq. 4.15, = eq. 2.20)::

    Delta Y(s) = 1/m / (s^2 + c/m s + k/m) F(s) + s^2 / (s^2 + c/m s + k/m) Y_cb(s)

and, neglecting the cross bar's motion, eq. 4.16: ``Delta Y(s) = 1/m / (s^2 + c/m s + k/m) F(s)``.
Both are fitted here by output error in the time domain (free run of the exact first-order-hold
discretisation, parameters ``ln m``, ``ln c``, ``ln k`` and a static offset for the weight and
rest length, MINPACK's Levenberg-Marquardt from the best of a grid of start frequencies
and damping ratios), with the standard deviations from the Jacobian. The non-parametric
reference is the H1 estimate from Welch cross and auto spectra (SISO for eq. 4.16, two-input for
eq. 4.15) with the coherence.

What can be identified: the head position comes from video at 50 Hz (thesis 3.3, 4.3), which is
reliable only up to about 10 Hz; the head resonance of Table 4.1 (``sqrt(k_c / m_c)`` = 9.4 Hz)
sits at that limit, so on rig data ``k / m`` is defined by the resonance only when the coherence
there is high, and the 4.16 fit is biased whenever the cross bar moves (it ignores the
``s^2 Y_cb`` path; the thesis' 4.16 values differ from its 4.15 values for that reason).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Mapping

import numpy as np
from scipy import signal

from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.estimation.minpack import levenberg_marquardt
from panto.identification.structures.oscillators import discretise, propagate

#: Frequency up to which the video position is reliable (thesis 4.3) [Hz].
RELIABLE_UP_TO_HZ = 10.0


@dataclass(frozen=True)
class HeadFit:
    """One PT2 model of the head: eq. ``"4.15"`` (force and cross bar) or ``"4.16"`` (force)."""

    equation: str
    mass: float
    damping: float
    stiffness: float
    offset: float
    std: Mapping[str, float]
    fit: float
    natural_frequency_hz: float
    damping_ratio: float


@dataclass(frozen=True, eq=False)
class CollectorHeadResult:
    """Both PT2 fits and the non-parametric estimates (frequency [Hz], complex responses)."""

    full: HeadFit
    force_only: HeadFit
    frequency: np.ndarray
    response_force: np.ndarray
    response_cross_bar: np.ndarray
    response_force_only: np.ndarray
    coherence_force: np.ndarray
    sample_period: float
    source: str = ""
    reliable_up_to_hz: float = RELIABLE_UP_TO_HZ
    notes: tuple[str, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the table of section 4.3 and the notes)."""
        return {"source": self.source, "sample_period": self.sample_period,
                "reliable_up_to_hz": self.reliable_up_to_hz,
                "eq_4_15": asdict(self.full), "eq_4_16": asdict(self.force_only),
                "notes": list(self.notes)}


def head_signals(data: IdentificationData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(F_c, y_cb, xi)`` from `data`'s inputs or outputs (by those names); NaN-free."""
    columns = dict(zip(data.input_names, data.inputs.T))
    columns.update(zip(data.output_names, data.outputs.T))
    missing = [n for n in ("F_c", "y_cb", "xi") if n not in columns]
    if missing:
        raise IdentificationError(f"{data.source or 'data'}: the collector head needs signals "
                                  f"{missing} (head position xi: video channel video_pan_head_y "
                                  "or a virtual run's truth)")
    signals = [np.asarray(columns[n], float) for n in ("F_c", "y_cb", "xi")]
    for name, values in zip(("F_c", "y_cb", "xi"), signals):
        if not np.all(np.isfinite(values)):
            raise IdentificationError(f"{data.source or 'data'}: {name} has NaN samples "
                                      "(fill or crop first)")
    return signals[0], signals[1], signals[2]


def simulate_head(mass: float, damping: float, stiffness: float, offset: float,
                  force: np.ndarray, cross_bar: np.ndarray | None, period: float) -> np.ndarray:
    """``Delta Y`` of eq. 4.15 (or 4.16 when `cross_bar` is None), from the equilibrium.

    ``Delta = G_F F + Y - G_Y Y`` with ``G_F = 1 / (m s^2 + c s + k)`` and
    ``G_Y = (c s + k) / (m s^2 + c s + k)`` (so that ``s^2 m / (...) = 1 - G_Y``), realised in
    controllable canonical form, discretised with first-order hold.
    """
    a2 = np.array([[0.0, 1.0], [-stiffness / mass, -damping / mass]])
    with_bar = cross_bar is not None
    inputs = np.column_stack([force, cross_bar] if with_bar else [force])
    a = np.kron(np.eye(inputs.shape[1]), a2)
    b = np.zeros((len(a), inputs.shape[1]))
    b[1::2, :] = np.eye(inputs.shape[1])
    c = np.zeros(len(a))
    c[0] = 1.0 / mass
    if with_bar:
        c[2:] = [-stiffness / mass, -damping / mass]
    phi, gamma0, gamma1 = discretise(a, b, period, "foh")
    x0 = -np.linalg.solve(a, b @ inputs[0])
    states = propagate(phi, inputs[:-1] @ gamma0.T + np.diff(inputs, axis=0) @ gamma1.T, x0)
    return states @ c + (cross_bar if with_bar else 0.0) + offset


def fit_head(force: np.ndarray, cross_bar: np.ndarray | None, difference: np.ndarray,
             period: float) -> HeadFit:
    """Output-error fit of eq. 4.15 (with `cross_bar`) or 4.16 (without)."""
    spread = np.linalg.norm(difference - difference.mean())

    def residuals(z: np.ndarray) -> np.ndarray:
        m, c, k = np.exp(z[:3])
        return (difference - simulate_head(m, c, k, z[3], force, cross_bar, period)) / spread

    slope, intercept = np.polyfit(force, difference, 1)
    k0 = 1.0 / abs(slope) if slope != 0 else 1e4
    starts = [np.array([math.log(k0 / (2 * math.pi * f) ** 2),
                        math.log(2 * zeta * math.sqrt(k0 * k0 / (2 * math.pi * f) ** 2)),
                        math.log(k0), intercept])
              for f in (1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 18.0) for zeta in (0.05, 0.2, 0.6)]
    costs = [float(np.sum(residuals(z) ** 2)) for z in starts]
    solution = levenberg_marquardt(residuals, starts[int(np.argmin(costs))], x_scale="jac")
    m, c, k = np.exp(solution.x[:3])
    jac, r = solution.jac, solution.fun
    covariance = float(r @ r) / max(len(r) - 4, 1) * np.linalg.pinv(jac.T @ jac)
    std_z = np.sqrt(np.clip(np.diag(covariance), 0, None))
    std = {"mass": m * std_z[0], "damping": c * std_z[1], "stiffness": k * std_z[2],
           "offset": std_z[3]}
    return HeadFit("4.15" if cross_bar is not None else "4.16", float(m), float(c), float(k),
                   float(solution.x[3]), {n: float(v) for n, v in std.items()},
                   float(100.0 * (1.0 - np.linalg.norm(r))),
                   float(math.sqrt(k / m) / (2 * math.pi)), float(c / (2 * math.sqrt(k * m))))


def estimate_responses(force: np.ndarray, cross_bar: np.ndarray, difference: np.ndarray,
                       period: float, segment: int | None = None) -> dict[str, np.ndarray]:
    """H1 estimates (Welch): two-input F, Y_cb -> Delta Y, and SISO F -> Delta Y with coherence."""
    segment = int(segment or min(len(force), 512))
    rate = 1.0 / period
    inputs = [force - force.mean(), cross_bar - cross_bar.mean()]
    out = difference - difference.mean()

    def cross(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return signal.csd(x, y, fs=rate, nperseg=segment)

    frequency, s_ff = cross(inputs[0], inputs[0])
    spectra = np.empty((len(frequency), 2, 2), complex)
    targets = np.empty((len(frequency), 2), complex)
    for i in range(2):
        targets[:, i] = cross(inputs[i], out)[1]
        for j in range(2):
            spectra[:, i, j] = cross(inputs[i], inputs[j])[1]
    both = np.array([np.linalg.lstsq(s.T, t, rcond=None)[0] for s, t in zip(spectra, targets)])
    _, s_dd = cross(out, out)
    coherence = np.abs(targets[:, 0]) ** 2 / np.maximum(np.real(s_ff) * np.real(s_dd), 1e-300)
    return {"frequency": frequency, "force": both[:, 0], "cross_bar": both[:, 1],
            "force_only": targets[:, 0] / s_ff, "coherence": np.real(coherence)}


def identify_collector_head(data: IdentificationData) -> CollectorHeadResult:
    """Identify the collector head from ``F_c``, ``y_cb`` and ``xi`` (thesis 4.3).

    Returns both PT2 fits (eqs. 4.15 and 4.16) with the mass, damping and stiffness they imply,
    and the H1 estimates for the Bode plots
    (:func:`panto.identification.structures.plots.plot_collector_head`).
    """
    force, cross_bar, head = head_signals(data)
    difference = cross_bar - head
    period = data.sample_period
    full = fit_head(force, cross_bar, difference, period)
    force_only = fit_head(force, None, difference, period)
    responses = estimate_responses(force, cross_bar, difference, period)
    nyquist = 0.5 / period
    notes = [f"time-domain output-error fits at {1 / period:g} Hz; resonance "
             f"{full.natural_frequency_hz:.2f} Hz (eq. 4.15), {force_only.natural_frequency_hz:.2f}"
             f" Hz (eq. 4.16)"]
    if full.natural_frequency_hz > RELIABLE_UP_TO_HZ and nyquist <= 25.0:
        notes.append(f"the resonance lies above {RELIABLE_UP_TO_HZ:g} Hz, beyond which video "
                     "positions at 50 Hz are unreliable (thesis 4.3): m and k are uncertain")
    return CollectorHeadResult(full, force_only, responses["frequency"], responses["force"],
                               responses["cross_bar"], responses["force_only"],
                               responses["coherence"], period, data.source, notes=tuple(notes))


def pt2_response(fit: HeadFit, frequency: np.ndarray, path: str = "force") -> np.ndarray:
    """Frequency response of a fitted PT2: ``"force"`` (1 / (m s^2 + c s + k)) or
    ``"cross_bar"`` (m s^2 / (m s^2 + c s + k))."""
    s = 2j * math.pi * np.asarray(frequency, float)
    denominator = fit.mass * s ** 2 + fit.damping * s + fit.stiffness
    return (1.0 if path == "force" else fit.mass * s ** 2) / denominator


def identify_collector_head_result(data: IdentificationData, **options: Any):
    """Identifier adapter: the 4.15 fit as an :class:`IdentificationResult` (details: both)."""
    import time

    from panto.identification.estimation.base import IdentificationResult

    started = time.perf_counter()
    result = identify_collector_head(data)
    full = result.full
    parameters = {"m_c": full.mass, "c_c": full.damping, "k_c": full.stiffness,
                  "offset": full.offset}
    std = {"m_c": full.std["mass"], "c_c": full.std["damping"], "k_c": full.std["stiffness"],
           "offset": full.std["offset"]}
    force, cross_bar, _ = head_signals(data)

    def simulator(other: IdentificationData) -> np.ndarray:
        f, y, _ = head_signals(other)
        return simulate_head(full.mass, full.damping, full.stiffness, full.offset, f, y,
                             other.sample_period)[:, None]

    del force, cross_bar, options
    return IdentificationResult(
        structure="collector-head", method="output-error PT2 (eq. 4.15)", parameters=parameters,
        free=tuple(parameters), std=std, covariance=np.diag([s * s for s in std.values()]),
        fit={"delta_y": full.fit}, success=True, message="; ".join(result.notes),
        wall_time=time.perf_counter() - started, n_evaluations=0, simulator=simulator,
        details=result.to_dict())


__all__ = ["identify_collector_head", "CollectorHeadResult", "HeadFit",
           "simulate_head", "fit_head", "estimate_responses", "pt2_response", "head_signals"]
