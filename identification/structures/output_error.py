"""A generic linear output-error model of given order for any data, with optional nonlinear
feedback terms (the nominal of the sim-to-real diagnosis for systems without a physical model).

For every output ``y_j`` (deviation from ``y_ref,j``) and input ``u_i`` (deviation from
``u_ref,i``) the model is the MIMO output-error (OE) model of Ljung (*System Identification*,
1999, section 4.2) with a common denominator per output

.. math::

    F_j(q)\\, \\tilde y_j(t) = \\sum_i B_{ji}(q)\\, \\tilde u_i(t), \\qquad
    F_j = 1 + \\sum_{k=1}^{n} f_{j,k} q^{-k}, \\quad
    B_{ji} = \\sum_{k=n_k}^{n_k+n-1} b_{ji,k} q^{-k},

simulated in free run from rest. The references ``u_ref``, ``y_ref`` are the training means when
``centre=True`` (MATLAB's ``detrend`` before ``oe``), else zero.

**Feedback terms** (the diagnosis' effects inside the dynamics of a black-box nominal): a term
``c phi(y_j)`` is added to the input ``u_d`` of output ``j``'s chain,
``w(t) = u_d(t) + sum_l c_l phi_l(y_j(t), y_j(t-1))``, with ``phi = y~^3`` (cubic stiffness),
``tanh(v / v_s)`` or ``sign(v)`` of the simulated velocity ``v = (y~(t) - y~(t-1)) / T``
(Coulomb friction) or ``1`` (operating-point offset). For the Silverbox (an electronic Duffing
oscillator) this is exactly the polynomial OE model of Wigren & Schoukens (2013). The recursion
needs ``n_k >= 1`` (no algebraic loop) and runs per sample: compiled where a C compiler is at hand
(:data:`RECURSION_SOURCE`, the same operations in the same order, so the same values bit for bit),
else in Python (:func:`recursion_loop`, about 2 us per sample).

Listed in :mod:`panto.identification.structures.registry` as the family ``linear-N`` (members
``linear-2``, ``linear-4``, ``linear-6`` shown; any order accepted; not in the comparison).
"""
from __future__ import annotations

import ctypes
import functools
import math
import re
from dataclasses import replace
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import signal as sps

from panto.fmu_src import c_kernels

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 ModelStructure)

#: Effects a linear OE model can take inside its dynamics, and the function ``phi``.
FEEDBACK_EFFECTS = ("cubic_stiffness", "coulomb_friction", "offset")
_NAME = re.compile(r"^linear-(\d+)$")


def _binomial_bound(order: int, k: int) -> float:
    return float(math.comb(order, k)) + 1.0


class LinearOutputError(ModelStructure):
    """Linear MIMO output-error model of order `order` (module notes).

    Parameters
    ----------
    input_names, output_names : sequence of str
    order : int
        Number of poles per output (and of numerator coefficients per input-output pair).
    input_delay : int
        ``n_k``: samples before an input acts (1 by default, as MATLAB ``oe`` with ``nk = 1``).
    initial : mapping, optional
        Nominal parameter values (default: a stable all-zero numerator, poles at 0.5).
    input_reference, output_reference : sequence of float, optional
        ``u_ref``, ``y_ref`` (default zeros).
    feedback : sequence of (effect, setting), optional
        Terms inside the dynamics; a setting holds ``output``, ``drive`` (input), ``v_s`` (friction
        width, 0 = sign), ``start``, ``bound``, ``sample_period``.
    """

    def __init__(self, input_names: Sequence[str], output_names: Sequence[str], order: int, *,
                 input_delay: int = 1, initial: Mapping[str, float] | None = None,
                 input_reference: Sequence[float] | None = None,
                 output_reference: Sequence[float] | None = None,
                 feedback: Sequence[tuple[str, Mapping[str, Any]]] = ()) -> None:
        if order < 1 or input_delay < 0:
            raise IdentificationError(f"linear OE: order {order} and input delay {input_delay}: "
                                      "need order >= 1 and delay >= 0")
        self.name = f"linear-{order}"
        self.order, self.input_delay = int(order), int(input_delay)
        self.input_names, self.output_names = tuple(input_names), tuple(output_names)
        self.input_reference = np.zeros(len(self.input_names)) if input_reference is None \
            else np.asarray(input_reference, float)
        self.output_reference = np.zeros(len(self.output_names)) if output_reference is None \
            else np.asarray(output_reference, float)
        names = []
        for o in self.output_names:
            names += [f"{o}.f{k}" for k in range(1, order + 1)]
            names += [f"{o}.{u}.b{k}" for u in self.input_names
                      for k in range(input_delay, input_delay + order)]
        self.feedback = tuple((effect, dict(setting)) for effect, setting in feedback)
        for effect, setting in self.feedback:
            if effect not in FEEDBACK_EFFECTS:
                raise IdentificationError(f"linear OE: no feedback form for effect {effect!r}; "
                                          f"available: {FEEDBACK_EFFECTS}")
            if input_delay < 1:
                raise IdentificationError("linear OE: feedback terms need input_delay >= 1")
            names.append(self.feedback_parameter(effect, setting))
        self.parameter_names = tuple(names)
        defaults = {n: 0.0 for n in names}
        for o in self.output_names:
            poles = np.poly(np.full(order, 0.5))
            defaults.update({f"{o}.f{k}": float(poles[k]) for k in range(1, order + 1)})
        for effect, setting in self.feedback:
            defaults[self.feedback_parameter(effect, setting)] = float(setting.get("start", 0.0))
        self._nominal = {**defaults, **{k: float(v) for k, v in (initial or {}).items()
                                        if k in defaults}}

    @staticmethod
    def feedback_parameter(effect: str, setting: Mapping[str, Any]) -> str:
        """Name of a feedback term's coefficient: ``<output>.<effect>``."""
        return f"{setting['output']}.{effect}"

    def with_effect(self, effect: str, setting: Mapping[str, Any]) -> "LinearOutputError":
        """The same model with one more feedback term (its coefficient a new parameter)."""
        return LinearOutputError(self.input_names, self.output_names, self.order,
                                 input_delay=self.input_delay, initial=self._nominal,
                                 input_reference=self.input_reference,
                                 output_reference=self.output_reference,
                                 feedback=self.feedback + ((effect, dict(setting)),))

    def with_nominal(self, values: Mapping[str, float]) -> "LinearOutputError":
        """The same structure with other nominal values (e.g. the fitted ones)."""
        return LinearOutputError(self.input_names, self.output_names, self.order,
                                 input_delay=self.input_delay, initial={**self._nominal, **values},
                                 input_reference=self.input_reference,
                                 output_reference=self.output_reference, feedback=self.feedback)

    def nominal(self) -> dict[str, float]:
        """Start values (ARX estimate when built by :func:`linear_output_error_from_data`)."""
        return dict(self._nominal)

    def bounds(self) -> dict[str, tuple[float, float]]:
        """``|f_k| <= C(n, k) + 1`` (stable polynomials lie inside), wide numerator/term bounds."""
        out = {}
        for name, value in self._nominal.items():
            match = re.search(r"\.f(\d+)$", name)
            if match:
                bound = _binomial_bound(self.order, int(match.group(1)))
            else:
                setting = next((s for e, s in self.feedback
                                if self.feedback_parameter(e, s) == name), None)
                bound = float(setting["bound"]) if setting and "bound" in setting else \
                    max(1e3 * abs(value), 1e3 * self._numerator_scale(name), 1e-6)
            out[name] = (-bound, bound)
        return out

    def _numerator_scale(self, name: str) -> float:
        output = name.split(".")[0]
        values = [abs(v) for k, v in self._nominal.items() if k.startswith(output + ".")
                  and re.search(r"\.b\d+$", k)]
        return max(values, default=0.0)

    def polynomials(self, parameters: Mapping[str, float], output: str
                    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """``(F, {input: B})`` of one output as coefficient arrays in powers of ``q^-1``."""
        values = {**self._nominal, **parameters}
        f = np.r_[1.0, [values[f"{output}.f{k}"] for k in range(1, self.order + 1)]]
        b = {u: np.r_[np.zeros(self.input_delay),
                      [values[f"{output}.{u}.b{k}"] for k in
                       range(self.input_delay, self.input_delay + self.order)]]
             for u in self.input_names}
        return f, b

    def simulate(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        """Free run from rest (module notes); unstable denominators are refused."""
        unknown = sorted(set(parameters) - set(self.parameter_names))
        if unknown:
            raise IdentificationError(f"{self.name}: unknown parameter(s) {unknown}")
        u = np.column_stack([data.input(n) for n in self.input_names]) - self.input_reference
        values = {**self._nominal, **{k: float(v) for k, v in parameters.items()}}
        out = np.empty((len(data), len(self.output_names)))
        for j, output in enumerate(self.output_names):
            f, b = self.polynomials(values, output)
            if self.order > 0 and np.max(np.abs(np.roots(f))) >= 1.0:
                raise IdentificationError(f"{self.name}: unstable denominator for {output}")
            terms = [(e, s, values[self.feedback_parameter(e, s)]) for e, s in self.feedback
                     if s["output"] == output]
            if terms:
                out[:, j] = self._simulate_feedback(f, b, u, terms, data.sample_period)
            else:
                drive = sum(sps.lfilter(b[n], [1.0], u[:, i]) for i, n in enumerate(self.input_names))
                out[:, j] = sps.lfilter([1.0], f, drive)
        out += self.output_reference
        if not np.all(np.isfinite(out)):
            raise IdentificationError(f"{self.name}: non-finite simulation")
        return out

    def _simulate_feedback(self, f: np.ndarray, b: Mapping[str, np.ndarray], u: np.ndarray,
                           terms: Sequence[tuple[str, Mapping[str, Any], float]],
                           sample_period: float) -> np.ndarray:
        drive_name = terms[0][1].get("drive") or self.input_names[0]
        d = self.input_names.index(drive_name)
        other = sum((sps.lfilter(b[n], [1.0], u[:, i]) for i, n in enumerate(self.input_names)
                     if i != d), np.zeros(len(u)))
        cubic = sum(c for e, _, c in terms if e == "cubic_stiffness")
        constant = sum(c for e, _, c in terms if e == "offset")
        friction = [(c, float(s.get("v_s", 0.0)) * sample_period) for e, s, c in terms
                    if e == "coulomb_friction"]
        return _recursion(f.tolist(), b[drive_name].tolist(), other.tolist(),
                          u[:, d].tolist(), cubic, constant, friction)


def _recursion(f: list[float], b: list[float], other: list[float], drive: list[float],
               cubic: float, constant: float, friction: list[tuple[float, float]]) -> np.ndarray:
    """:func:`recursion_loop` compiled (:data:`RECURSION_SOURCE`) where a C compiler is at hand
    (``PANTO_OE_KERNEL=0`` runs the loop); the same values bit for bit."""
    kernel = _recursion_kernel() if RECURSION_KERNEL.enabled() else None
    if kernel is None or not drive:
        return recursion_loop(f, b, other, drive, cubic, constant, friction)
    n, m, count = len(f) - 1, len(b), len(drive)
    fs = [(n - k, f[k]) for k in range(1, n + 1) if f[k] != 0.0]
    bs = [(m - k, b[k]) for k in range(1, m) if b[k] != 0.0]
    f_offset, f_value = _columns(fs, np.int64), _columns(fs, float, 1)
    b_offset, b_value = _columns(bs, np.int64), _columns(bs, float, 1)
    width = np.array([w for _, w in friction], float)
    factor = np.array([c for c, _ in friction], float)
    other_, drive_ = np.asarray(other, float), np.asarray(drive, float)
    ys, ws = np.zeros(count + n), np.zeros(count + m)
    kernel(count, n, m, len(fs), f_offset.ctypes.data, f_value.ctypes.data, len(bs),
           b_offset.ctypes.data, b_value.ctypes.data, other_.ctypes.data, drive_.ctypes.data,
           float(cubic), float(constant), len(friction), factor.ctypes.data, width.ctypes.data,
           ys.ctypes.data, ws.ctypes.data)
    return ys[n:]


def _columns(pairs: list[tuple], dtype: Any, column: int = 0) -> np.ndarray:
    """Column `column` of `pairs` as a contiguous array (one element at least, for ctypes)."""
    return np.array([p[column] for p in pairs] or [0], dtype)


def recursion_loop(f: list[float], b: list[float], other: list[float], drive: list[float],
                   cubic: float, constant: float, friction: list[tuple[float, float]]
                   ) -> np.ndarray:
    """``y(t) = other(t) - sum f_k y(t-k) + sum b_k w(t-k)``, ``w = u + c3 y^3 + c0 + friction``.

    `friction` holds ``(F_f, v_s T)``: ``F_f tanh(dy / (v_s T))`` (sign when ``v_s = 0``).
    The reference of :data:`RECURSION_SOURCE`.
    """
    n, m, count = len(f) - 1, len(b), len(drive)
    fs = [(n - k, f[k]) for k in range(1, n + 1) if f[k] != 0.0]   # (index offset, coefficient)
    bs = [(m - k, b[k]) for k in range(1, m) if b[k] != 0.0]
    ys = [0.0] * (count + n)      # ys[t + n] = y(t)
    ws = [0.0] * (count + m)      # ws[t + m] = w(t)
    tanh = math.tanh
    for t in range(count):
        y = other[t]
        for offset, coefficient in fs:
            y -= coefficient * ys[t + offset]
        for offset, coefficient in bs:
            y += coefficient * ws[t + offset]
        w = drive[t] + cubic * y * y * y + constant
        if friction:
            dy = y - ys[t + n - 1] if n else y
            for c, width in friction:
                w += c * (tanh(dy / width) if width > 0 else
                          (1.0 if dy > 0 else -1.0 if dy < 0 else 0.0))
        ys[t + n] = y
        ws[t + m] = w
    out = ys[n:]
    return np.asarray(out)


#: :func:`recursion_loop` in C: every sum in the loop's order, no fused multiply-add
#: (``-ffp-contract=off``), C's ``tanh`` (the one Python's ``math.tanh`` calls); a NaN velocity
#: gives the sign 0 as in Python.
RECURSION_SOURCE = """
#include <math.h>
void panto_oe_recursion(long count, long n, long m, long nf, const long *f_offset,
                        const double *f_value, long nb, const long *b_offset,
                        const double *b_value, const double *other, const double *drive,
                        double cubic, double constant, long nfriction, const double *factor,
                        const double *width, double *ys, double *ws) {
    for (long t = 0; t < count; ++t) {
        double y = other[t];
        for (long k = 0; k < nf; ++k) y -= f_value[k] * ys[t + f_offset[k]];
        for (long k = 0; k < nb; ++k) y += b_value[k] * ws[t + b_offset[k]];
        double w = drive[t] + cubic * y * y * y + constant;
        if (nfriction > 0) {
            double dy = n ? y - ys[t + n - 1] : y;
            for (long k = 0; k < nfriction; ++k) {
                double shape;
                if (width[k] > 0) shape = tanh(dy / width[k]);
                else shape = dy > 0 ? 1.0 : (dy < 0 ? -1.0 : 0.0);
                w += factor[k] * shape;
            }
        }
        ys[t + n] = y;
        ws[t + m] = w;
    }
}
"""


def _bind_recursion(library: ctypes.CDLL):
    function = library.panto_oe_recursion
    function.restype = None
    function.argtypes = [ctypes.c_long] * 4 + [ctypes.c_void_p] * 2 + [ctypes.c_long] + \
        [ctypes.c_void_p] * 4 + [ctypes.c_double] * 2 + [ctypes.c_long] + [ctypes.c_void_p] * 4
    return function


#: The recursion's library; ``PANTO_OE_KERNEL=0`` runs :func:`recursion_loop` instead.
RECURSION_KERNEL = c_kernels.Kernel("oe_recursion", "PANTO_OE_KERNEL",
                                    ("-std=c99", "-O2", "-ffp-contract=off"), RECURSION_SOURCE,
                                    _bind_recursion)


@functools.lru_cache(maxsize=1)
def _recursion_kernel():
    return RECURSION_KERNEL.load()


def estimate_arx(data: IdentificationData, order: int, input_delay: int,
                 input_reference: np.ndarray, output_reference: np.ndarray) -> dict[str, float]:
    """Least-squares ARX estimate per output (the OE start values); unstable poles reflected."""
    u = data.inputs - input_reference
    values: dict[str, float] = {}
    start = order + input_delay + order
    for j, output in enumerate(data.output_names):
        y = data.outputs[:, j] - output_reference[j]
        rows = np.arange(start, len(y))
        columns = [-y[rows - k] for k in range(1, order + 1)]
        columns += [u[rows - k, i] for i in range(u.shape[1])
                    for k in range(input_delay, input_delay + order)]
        phi, target = np.column_stack(columns), y[rows]
        ok = np.all(np.isfinite(phi), axis=1) & np.isfinite(target)
        if ok.sum() <= phi.shape[1]:
            raise IdentificationError(f"{data.source or 'data'}: too few valid samples of "
                                      f"{output!r} for an order-{order} model")
        theta, *_ = np.linalg.lstsq(phi[ok], target[ok], rcond=None)
        f = np.r_[1.0, theta[:order]]
        roots = np.roots(f)
        size = np.abs(roots)
        roots = np.where(size >= 1.0, roots / np.maximum(size, 1e-12) ** 2, roots)
        roots = np.minimum(np.abs(roots), 0.999) * np.exp(1j * np.angle(roots))
        f = np.real(np.poly(roots))
        values.update({f"{output}.f{k}": float(f[k]) for k in range(1, order + 1)})
        for i, name in enumerate(data.input_names):
            for k in range(order):
                values[f"{output}.{name}.b{input_delay + k}"] = float(theta[order + i * order + k])
    return values


def linear_output_error_from_data(data: IdentificationData, order: int, *, input_delay: int = 1,
                                  centre: bool | None = None) -> LinearOutputError:
    """An OE structure of `order` with ARX start values from `data` (the training run).

    ``centre=None`` decides from the data whether to remove the means (inputs and outputs about
    their means, the references ``u_ref``, ``y_ref`` added back in the simulator): yes when some
    signal's mean is larger than three standard deviations (an operating point far from zero),
    else yes only when the centred ARX start simulates (free run) with less than half the
    uncentred one's squared error, i.e. when the data carry a level that a model from rest
    through zero cannot produce; data without levels keep ``u_ref = y_ref = 0``.
    """
    if not 0 <= input_delay < len(data) - 2 * order - 1:  # the ARX start needs rows
        raise IdentificationError(f"linear OE: input delay {input_delay} samples: must be from "
                                  f"0 to {len(data) - 2 * order - 2} for order {order} on "
                                  f"{len(data)} samples")
    outputs = np.where(np.isfinite(data.outputs), data.outputs, np.nan)
    u_mean, y_mean = data.inputs.mean(axis=0), np.nanmean(outputs, axis=0)
    if centre is None:
        far = np.abs(np.r_[u_mean, y_mean]) > 3 * np.r_[data.inputs.std(axis=0),
                                                         np.nanstd(outputs, axis=0)]
        centre = bool(far.any()) or _centring_helps(data, order, input_delay, u_mean, y_mean)
    u_ref = u_mean if centre else np.zeros_like(u_mean)
    y_ref = y_mean if centre else np.zeros_like(y_mean)
    initial = estimate_arx(data, order, input_delay, u_ref, y_ref)
    return LinearOutputError(data.input_names, data.output_names, order, input_delay=input_delay,
                             initial=initial, input_reference=u_ref, output_reference=y_ref)


def _centring_helps(data: IdentificationData, order: int, input_delay: int, u_mean: np.ndarray,
                    y_mean: np.ndarray) -> bool:
    """Whether the centred ARX start's free-run squared error is below half the uncentred one's."""
    errors = []
    for u_ref, y_ref in ((np.zeros_like(u_mean), np.zeros_like(y_mean)), (u_mean, y_mean)):
        initial = estimate_arx(data, order, input_delay, u_ref, y_ref)
        model = LinearOutputError(data.input_names, data.output_names, order,
                                  input_delay=input_delay, initial=initial,
                                  input_reference=u_ref, output_reference=y_ref)
        try:
            residual = data.outputs - model.simulate({}, data)
        except IdentificationError:  # an unusable start: judge by the other one
            residual = np.full(data.outputs.shape, np.inf)
        errors.append(float(np.nansum(residual ** 2)))
    return errors[1] < 0.5 * errors[0]


def describe_levels(structure: LinearOutputError) -> dict[str, Any]:
    """How the structure handles constant levels, for a result's ``details["levels"]`` and its
    message: the means removed before fitting (added back in the simulator), or none."""
    centred = bool(np.any(structure.input_reference) or np.any(structure.output_reference))
    names = list(structure.input_names) + list(structure.output_names)
    text = (f"removed the means of {', '.join(names)} before fitting; they are added back in "
            "the simulator") if centred else "no levels removed (signals used as they are)"
    return {"centred": centred, "message": text,
            "input_reference": dict(zip(structure.input_names,
                                        structure.input_reference.tolist())),
            "output_reference": dict(zip(structure.output_names,
                                         structure.output_reference.tolist()))}


def order_of(name: str) -> int | None:
    """The order in a structure name ``linear-N`` (None for other names)."""
    match = _NAME.match(name)
    return int(match.group(1)) if match else None


def identify_linear_output_error(data: IdentificationData, *, order: int = 4, executor=None,
                                 progress=None, input_delay: int = 1, centre: bool | None = None,
                                 **options: Any) -> IdentificationResult:
    """ARX start, then output error by :func:`~panto.identification.estimation.least_squares.fit_least_squares`;
    the result's message and ``details["levels"]`` say whether the means were removed."""
    from panto.identification.estimation.least_squares import fit_least_squares

    structure = linear_output_error_from_data(data, order, input_delay=input_delay, centre=centre)
    options.pop("fixed", None)
    options.pop("method", None)
    free = options.pop("free", None) or structure.parameter_names
    result = fit_least_squares(structure, data, free=free, executor=executor, progress=progress,
                               **options)
    levels = describe_levels(structure)
    return replace(result, message=f"{result.message}; {levels['message']}",
                   details={**result.details, "levels": levels})


__all__ = ["LinearOutputError", "linear_output_error_from_data", "estimate_arx", "describe_levels",
           "identify_linear_output_error", "order_of", "FEEDBACK_EFFECTS"]
