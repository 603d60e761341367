"""Black-box state-space models (thesis section 4.8): subspace identification refined by output error.

``x[k+1] = A x[k] + B (u[k] - u_ref)``, ``y[k] = C x[k] + D (u[k] - u_ref) + y_ref``, of a given
order, found in three steps:

1. **Subspace step (PO-MOESP).** Inputs and outputs are centred and scaled to unit standard
   deviation. With block Hankel matrices of ``s`` (the horizon) past and future samples, the LQ
   factorisation of ``[U_f; (U_p; Y_p); Y_f]`` gives ``L32``, whose dominant left singular
   vectors span the extended observability matrix ``Gamma_s``; ``C`` is its first block row and
   ``A`` solves the shift equation ``Gamma_s[:-p] A = Gamma_s[p:]`` in least squares
   (Verhaegen 1994, "Identification of the deterministic part of MIMO state space models given
   in innovations form from input-output data", Automatica 30(1); Van Overschee & De Moor 1996,
   *Subspace Identification for Linear Systems*, Kluwer, ch. 4). Using past outputs as
   instruments makes the estimate consistent under output noise.
2. **Well-conditioned form.** ``A`` is brought to real block-diagonal form of 2x2 blocks
   ``[[tr/2, 1], [tr^2/4 - det, tr/2]]`` (eigenvalues ``tr/2 +- sqrt(tr^2/4 - det)``: a complex
   pair or two real poles) and, for odd orders, one 1x1 block. A block is parameterised by
   ``det = tanh(a)``, ``tr = (1 + det) tanh(b)``: exactly the stable second-order blocks (Jury:
   ``|det| < 1``, ``|tr| < 1 + det``), so every parameter vector is a stable model. Unstable
   subspace poles are reflected into the unit circle first. Given ``A`` and ``C``, the free-run
   output is linear in ``B``, ``D`` and ``y_ref``: one linear least-squares solve.
3. **Output-error refinement** (``refine=True``): MINPACK's Levenberg-Marquardt over all
   parameters (block parameters, ``B``, ``C``, ``D``, the output offset) on the free-run
   simulation error, residuals per output normalised as the fit metric; the refined model is
   kept only if its cost is lower, so refinement never worsens the fit.

The free run starts at the equilibrium for the first input sample. It is computed as second-order
IIR filters per block and input (:func:`scipy.signal.lfilter`), which makes a simulation of
9000 samples cost about a millisecond.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
from scipy import linalg, signal

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 fit_percent)
from panto.identification.estimation.minpack import levenberg_marquardt

Progress = Callable[[str], None]
#: Default fitted outputs when present (the thesis' two objectives).
DEFAULT_OUTPUTS = ("F_c", "y_cb")
#: How the model handles constant levels (said in every result's message).
LEVELS = ("removed the means of every input and output before fitting (u_ref, y_ref; the output "
          "offset estimated on top); they are added back in the simulator")
#: Largest pole radius a reflected (or clipped) subspace pole gets.
_MAX_RADIUS = 0.995


# --- the parameterised model -------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class BlockModel:
    """State-space model in scaled units with the block-diagonal stable ``A`` (module notes).

    Parameters
    ----------
    order, n_inputs, n_outputs : int
    theta : ndarray
        ``[block parameters (order), vec(B), vec(C), vec(D), offset (n_outputs)]``.
    """

    order: int
    n_inputs: int
    n_outputs: int
    theta: np.ndarray

    @property
    def sizes(self) -> tuple[int, int, int, int, int]:
        n, m, p = self.order, self.n_inputs, self.n_outputs
        return n, n * m, p * n, p * m, p

    def parts(self) -> tuple[np.ndarray, ...]:
        """``(block parameters, B, C, D, offset)``."""
        n, m, p = self.order, self.n_inputs, self.n_outputs
        cuts = np.cumsum(self.sizes)[:-1]
        blocks, b, c, d, offset = np.split(np.asarray(self.theta, float), cuts)
        return blocks, b.reshape(n, m), c.reshape(p, n), d.reshape(p, m), offset

    def block_coefficients(self) -> list[tuple[float, float] | float]:
        """Per block ``(tr, det)`` (2x2) or the pole (1x1)."""
        blocks = self.parts()[0]
        out: list[tuple[float, float] | float] = []
        for i in range(self.order // 2):
            det = math.tanh(blocks[2 * i])
            out.append(((1.0 + det) * math.tanh(blocks[2 * i + 1]), det))
        if self.order % 2:
            out.append(math.tanh(blocks[-1]))
        return out

    def a_matrix(self) -> np.ndarray:
        """The block-diagonal ``A``."""
        pieces = []
        for coefficient in self.block_coefficients():
            if isinstance(coefficient, tuple):
                tr, det = coefficient
                pieces.append(np.array([[tr / 2, 1.0], [tr * tr / 4 - det, tr / 2]]))
            else:
                pieces.append(np.array([[coefficient]]))
        return linalg.block_diag(*pieces)

    def state_basis(self, u: np.ndarray) -> np.ndarray:
        """``G`` with ``x[k] = sum_ij G[k, :, i, j] B[i, j]`` (equilibrium start at ``u[0]``)."""
        n, m = self.order, self.n_inputs
        basis = np.zeros((len(u), n, n, m))
        row = 0
        for coefficient in self.block_coefficients():
            if isinstance(coefficient, tuple):
                tr, det = coefficient
                a, c = tr / 2, tr * tr / 4 - det
                den = [1.0, -tr, det]
                for j in range(m):
                    g1, g2 = _steady_pair(den, u[:, j])
                    basis[:, row, row, j] = g1 - a * g2
                    basis[:, row + 1, row, j] = c * g2
                    basis[:, row, row + 1, j] = g2
                    basis[:, row + 1, row + 1, j] = g1 - a * g2
                row += 2
            else:
                for j in range(m):
                    basis[:, row, row, j] = _steady_first(coefficient, u[:, j])
                row += 1
        return basis

    def simulate(self, u: np.ndarray) -> np.ndarray:
        """Free-run outputs (scaled units) for scaled inputs ``u`` (n, m)."""
        _, b, c, d, offset = self.parts()
        states = np.einsum("knij,ij->kn", self.state_basis(u), b)
        return states @ c.T + u @ d.T + offset


def _steady_pair(a: Sequence[float], x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`x` filtered through ``z^-1 / a(z)`` and ``z^-2 / a(z)`` (`a` of second order, ``a[0]``
    = 1), started in the steady state for the constant input ``x[0]`` (a mode at exactly 1, an integrator
    with no steady state, at rest on the input's deviation from ``x[0]``): one filter, the
    second the first delayed by a sample. The steady state in closed form (``lfilter_zi``'s
    linear solve and companion matrix cost more than the filter itself: this runs for every
    column of the black box's Jacobian); the same as ``lfilter`` from ``lfilter_zi`` to
    rounding (tests/test_identification_blackbox.py), except next to a root at 1, where the
    old path's steady state was 1e16 times the input (:func:`_at_one`)."""
    total = float(a[0] + a[1] + a[2])
    if _at_one(total, a):  # an integrator: at rest on the input's deviation from x[0]
        first = signal.lfilter([0.0, 1.0, 0.0], a, np.asarray(x, float) - x[0])
        before = 0.0
    else:  # transposed direct form II at rest: z0 = y, z1 = -a2 y, y = x[0] / a(1)
        before = float(x[0]) / total
        first, _ = signal.lfilter([0.0, 1.0, 0.0], a, x, zi=[before, -a[2] * before])
    second = np.empty_like(first)
    second[0], second[1:] = before, first[:-1]
    return first, second


def _at_one(total: float, a: Sequence[float]) -> bool:
    """Whether ``a(1)`` (`total`, the sum of the denominator `a`, ``a[0] = 1``) is zero to the
    rounding of that sum: a root at 1 (an integrator). A block whose ``tanh``-bounded
    coefficients saturate puts a root there exactly while the sum comes out 1e-17 instead of 0,
    and its steady state 1e16 times the input."""
    return abs(total) <= 8.0 * np.finfo(float).eps * sum(abs(float(c)) for c in a)


def _steady_first(pole: float, x: np.ndarray) -> np.ndarray:
    """`x` filtered through ``z^-1 / (1 - pole z^-1)`` from the steady state of ``x[0]`` (at
    rest on the deviation for a pole at 1), the steady state in closed form (as
    :func:`_steady_pair`)."""
    if _at_one(1.0 - pole, (1.0, pole)):
        return signal.lfilter([0.0, 1.0], [1.0, -pole], np.asarray(x, float) - x[0])
    y, _ = signal.lfilter([0.0, 1.0], [1.0, -pole], x, zi=[float(x[0]) / (1.0 - pole)])
    return y


# --- subspace step -----------------------------------------------------------------------------

def hankel_rows(signal_: np.ndarray, start: int, rows: int, columns: int) -> np.ndarray:
    """Block Hankel matrix: block row ``i`` holds ``signal[start + i : start + i + columns]``."""
    return np.vstack([signal_[start + i:start + i + columns].T for i in range(rows)])


def moesp(u: np.ndarray, y: np.ndarray, order: int, horizon: int) -> tuple[np.ndarray, np.ndarray,
                                                                           np.ndarray]:
    """PO-MOESP estimate ``(A, C, singular values)`` (module notes, step 1).

    Hankel columns (data windows) that contain a NaN output sample are left out.
    """
    n_samples, m = u.shape
    p = y.shape[1]
    columns = n_samples - 2 * horizon + 1
    if columns < (2 * m + 2 * p) * horizon or order >= p * horizon:
        raise IdentificationError(f"subspace identification: {n_samples} samples are too few for "
                                  f"horizon {horizon} and order {order}")
    # a column spans samples j .. j + 2 s - 1; columns touching a missing output are left out
    bad = np.concatenate([[0], np.cumsum(~np.all(np.isfinite(y), axis=1))])
    keep = bad[2 * horizon:2 * horizon + columns] - bad[:columns] == 0
    if keep.sum() < (2 * m + 2 * p) * horizon:
        raise IdentificationError(f"subspace identification: too few gap-free windows of "
                                  f"{2 * horizon} samples")
    y = np.where(np.isfinite(y), y, 0.0)
    stacked = np.vstack([hankel_rows(u, horizon, horizon, columns),
                         hankel_rows(u, 0, horizon, columns), hankel_rows(y, 0, horizon, columns),
                         hankel_rows(y, horizon, horizon, columns)])[:, keep]
    stacked /= math.sqrt(keep.sum())
    lower = linalg.qr(stacked.T, mode="r")[0][:stacked.shape[0]].T
    mf, wp = m * horizon, (m + p) * horizon
    l32 = lower[mf + wp:, mf:mf + wp]
    left, values, _ = linalg.svd(l32, full_matrices=False)
    gamma = left[:, :order] * np.sqrt(values[:order])
    c = gamma[:p]
    a = linalg.lstsq(gamma[:-p], gamma[p:])[0]
    return a, c, values


def block_form(a: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Block parameters and the transformed ``C`` (module notes, step 2); poles stabilised.

    ``A`` goes to real modal form (a 2x2 rotation block per complex pair, real poles paired two
    by two), unstable poles are reflected (the modal ``C`` is kept), and each block is mapped
    to the ``(tr, det)`` form by an exact similarity.
    """
    values, vectors = linalg.eig(a)
    order = np.argsort(-np.abs(values))
    values, vectors = _stable_poles(values[order]), vectors[:, order]
    pairs, real, used = [], [], np.zeros(len(values), bool)
    for i, lam in enumerate(values):
        if used[i]:
            continue
        used[i] = True
        if abs(lam.imag) > 1e-9 * max(1.0, abs(lam)):
            partner = int(np.argmin(np.where(used, np.inf, np.abs(values - lam.conjugate()))))
            used[partner] = True
            pairs.append((np.array([[lam.real, lam.imag], [-lam.imag, lam.real]]),
                          np.column_stack([vectors[:, i].real, vectors[:, i].imag])))
        else:
            real.append((lam.real, np.real(vectors[:, i])))
    for i in range(0, len(real) - len(real) % 2, 2):
        (l1, v1), (l2, v2) = real[i], real[i + 1]
        l2 = l2 - 1e-6 if abs(l1 - l2) < 1e-9 else l2  # a derogatory block has no (tr, det) form
        pairs.append((np.diag([l1, l2]), np.column_stack([v1, v2])))
    parameters, transforms = [], []
    for m_block, modal in pairs:
        det = float(np.clip(np.linalg.det(m_block), -_MAX_RADIUS, _MAX_RADIUS))
        tr = float(np.clip(np.trace(m_block), -(1 + det) * _MAX_RADIUS, (1 + det) * _MAX_RADIUS))
        parameters += [math.atanh(det), math.atanh(tr / (1.0 + det))]
        target = np.array([[tr / 2, 1.0], [tr * tr / 4 - det, tr / 2]])
        transforms.append(modal @ _similarity(m_block, target))
    if len(real) % 2:
        lam, v = real[-1]
        parameters.append(math.atanh(float(np.clip(lam, -_MAX_RADIUS, _MAX_RADIUS))))
        transforms.append(v[:, None])
    return np.array(parameters), np.real(c @ np.column_stack(transforms))


def _stable_poles(poles: np.ndarray) -> np.ndarray:
    """Poles outside radius 0.995 reflected to ``1 / conj`` and clipped to 0.995."""
    radius = np.abs(poles)
    reflected = np.where(radius > 1.0, 1.0 / np.conj(poles), poles)
    radius = np.abs(reflected)
    return np.where(radius > _MAX_RADIUS, reflected / np.maximum(radius, 1e-300) * _MAX_RADIUS,
                    reflected)


def _similarity(m_block: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``S`` with ``S^-1 M S`` equal to `target` (same trace/determinant up to stabilisation).

    Both are similar to the companion matrix through Krylov bases ``[v, M v]``; ``S = K_M K_T^-1``.
    When the poles were moved by the stabilisation, ``S`` still maps the modal coordinates well.
    """
    for v in (np.array([1.0, 0.381966]), np.array([0.3, 1.0]), np.array([1.0, -0.7])):
        k_m = np.column_stack([v, m_block @ v])
        k_t = np.column_stack([v, target @ v])
        if np.linalg.cond(k_m) < 1e10 and np.linalg.cond(k_t) < 1e10:
            return k_m @ np.linalg.inv(k_t)
    return np.eye(2)


# --- estimation --------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Scaling:
    """Centring and scaling: ``u_s = (u - u_mean) / u_std``, ``y_s = (y - y_mean) / y_std``."""

    u_mean: np.ndarray
    u_std: np.ndarray
    y_mean: np.ndarray
    y_std: np.ndarray

    @classmethod
    def of(cls, u: np.ndarray, y: np.ndarray, where: str) -> "Scaling":
        u_std, y_std = u.std(axis=0), np.nanstd(y, axis=0)
        flat = [i for i, s in enumerate(np.concatenate([u_std, y_std])) if not s > 0]
        if flat:
            raise IdentificationError(f"{where}: constant input/output column(s) {flat}: "
                                      "nothing to identify")
        return cls(u.mean(axis=0), u_std, np.nanmean(y, axis=0), y_std)


@dataclass(frozen=True, eq=False)
class StateSpaceSimulator:
    """``simulator(data) -> outputs``: the identified model on any data with the same inputs."""

    model: BlockModel
    scaling: Scaling
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]

    def __call__(self, data: IdentificationData) -> np.ndarray:
        u = np.column_stack([data.input(name) for name in self.input_names])
        u_s = (u - self.scaling.u_mean) / self.scaling.u_std
        return self.model.simulate(u_s) * self.scaling.y_std + self.scaling.y_mean


def _residuals(model: BlockModel, u: np.ndarray, y: np.ndarray, valid: np.ndarray,
               norms: np.ndarray) -> np.ndarray:
    """Per output ``(y - y_hat) / ||y - mean y||`` over valid samples, stacked."""
    error = (y - model.simulate(u)) / norms
    return error[valid]


def linear_part(blocks: np.ndarray, c: np.ndarray, u: np.ndarray, y: np.ndarray,
                valid: np.ndarray, norms: np.ndarray) -> BlockModel:
    """``B``, ``D`` and the offset by weighted linear least squares for given ``A`` and ``C``."""
    n, m, p = c.shape[1], u.shape[1], y.shape[1]
    probe = BlockModel(n, m, p, np.concatenate([blocks, np.zeros(n * m + p * n + p * m + p)]))
    basis = probe.state_basis(u)  # (N, n, n, m)
    columns = [np.einsum("kn,qn->kq", basis[:, :, i, j], c) for i in range(n) for j in range(m)]
    for q in range(p):
        for j in range(m):
            column = np.zeros_like(y)
            column[:, q] = u[:, j]
            columns.append(column)
    for q in range(p):
        column = np.zeros_like(y)
        column[:, q] = 1.0
        columns.append(column)
    regressors = np.column_stack([(col / norms)[valid] for col in columns])
    solution = linalg.lstsq(regressors, (y / norms)[valid])[0]
    b = solution[:n * m]
    d = solution[n * m:n * m + p * m].reshape(p, m).ravel()
    offset = solution[n * m + p * m:]
    return BlockModel(n, m, p, np.concatenate([blocks, b, c.ravel(), d, offset]))


def refine_output_error(model: BlockModel, u: np.ndarray, y: np.ndarray, valid: np.ndarray,
                        norms: np.ndarray, *, max_evaluations: int = 100
                        ) -> tuple[BlockModel, Any]:
    """Output-error refinement of all parameters (MINPACK's Levenberg-Marquardt,
    :func:`~panto.identification.estimation.minpack.levenberg_marquardt`: the parameterisation
    is unconstrained, every vector a stable model).

    The Jacobian is analytic in ``B``, ``C``, ``D`` and the offset (the output is linear in
    each of them) and by forward differences in the block parameters.
    """
    shape = (model.order, model.n_inputs, model.n_outputs)

    def residuals(theta: np.ndarray) -> np.ndarray:
        return _residuals(BlockModel(*shape, theta), u, y, valid, norms)

    def jacobian(theta: np.ndarray) -> np.ndarray:
        current = BlockModel(*shape, theta)
        blocks, b, c, d, offset = current.parts()
        basis = current.state_basis(u)
        states = np.einsum("knij,ij->kn", basis, b)
        output = states @ c.T + u @ d.T + offset
        columns = []
        for i in range(len(blocks)):
            shifted = np.array(theta, float)
            step = 1e-7 * (1.0 + abs(shifted[i]))
            shifted[i] += step
            columns.append((BlockModel(*shape, shifted).simulate(u) - output) / step)
        n, m, p = shape
        columns += [basis[:, :, i, j] @ c.T for i in range(n) for j in range(m)]
        columns += [_in_column(states[:, i], q, p) for q in range(p) for i in range(n)]
        columns += [_in_column(u[:, j], q, p) for q in range(p) for j in range(m)]
        columns += [_in_column(np.ones(len(u)), q, p) for q in range(p)]
        return -np.column_stack([(column / norms)[valid] for column in columns])

    solution = levenberg_marquardt(residuals, model.theta, jac=jacobian, x_scale="jac",
                                   max_nfev=max_evaluations, xtol=1e-8, ftol=1e-8)
    return BlockModel(*shape, solution.x), solution


def _in_column(values: np.ndarray, output: int, n_outputs: int) -> np.ndarray:
    column = np.zeros((len(values), n_outputs))
    column[:, output] = values
    return column


def fit_state_space(data: IdentificationData, order: int, *, refine: bool = True,
                    horizon: int | None = None, progress: Progress | None = None,
                    max_evaluations: int = 100) -> IdentificationResult:
    """Identify a black-box state-space model of `order` from all inputs to all outputs of `data`.

    Parameters
    ----------
    data : IdentificationData
        NaN output samples are left out (of the subspace step's data windows and of the fits).
    order : int
        State dimension (thesis: 4 and 6).
    refine : bool
        Output-error refinement after the subspace estimate (never worsens the fit).
    horizon : int, optional
        Block rows of the Hankel matrices (default ``max(15, 2 order)``).
    progress : callable, optional
    max_evaluations : int
        Refinement budget (residual evaluations; the Jacobians come on top).

    Returns
    -------
    IdentificationResult
        ``parameters`` the parameterisation's entries (``n_free`` of them), ``fit`` per output
        (free run). ``details``: ``A``, ``B``, ``C``, ``D`` (discrete, physical units, acting on
        ``u - u_ref``, output ``C x + D (u - u_ref) + y_ref``), ``u_ref``, ``y_ref``,
        ``sample_period``, ``poles`` (discrete), ``modes`` (continuous equivalents ``s = ln z / T``
        with frequency [Hz] and damping ratio), ``fit_subspace``, ``singular_values``,
        ``horizon``.
    """
    started = time.perf_counter()
    where = data.source or "data"
    if not 1 <= int(order) <= 40:
        raise IdentificationError(f"{where}: state-space order {order} (choose 1..40)")
    order = int(order)
    horizon = int(horizon or max(15, 2 * order))
    scaling = Scaling.of(data.inputs, data.outputs, where)
    u = (data.inputs - scaling.u_mean) / scaling.u_std
    y = (data.outputs - scaling.y_mean) / scaling.y_std
    valid = np.isfinite(y)
    norms = np.array([np.linalg.norm(y[valid[:, j], j] - y[valid[:, j], j].mean())
                      for j in range(y.shape[1])])
    y_zero = np.where(valid, y, 0.0)
    a, c, singular = moesp(u, y, order, horizon)
    model = linear_part(*block_form(a, c), u, y_zero, valid, norms)
    fit_subspace = fit_percent(data.outputs, _physical(model, scaling, u))
    if progress:
        progress(f"state space order {order}: subspace fit " + _describe(data, fit_subspace))
    evaluations, message = 1, "subspace estimate (PO-MOESP) with least-squares B, D, offset"
    covariance = np.full((len(model.theta),) * 2, np.nan)
    if refine:
        model, covariance, extra, message = _refined(model, covariance, u, y_zero, valid, norms,
                                                     max_evaluations)
        evaluations += extra
    fits = np.atleast_1d(fit_percent(data.outputs, _physical(model, scaling, u)))
    if progress:
        progress(f"state space order {order}: {message}; fit " + _describe(data, fits))
    details = {"fit_subspace": dict(zip(data.output_names, np.atleast_1d(fit_subspace).tolist())),
               "singular_values": singular[:2 * order + 2].tolist(), "horizon": horizon}
    return _state_space_result(data, model, scaling, covariance, fits, details,
                               (refine, message, int(evaluations), time.perf_counter() - started))


def _refined(model: BlockModel, covariance: np.ndarray, u: np.ndarray, y_zero: np.ndarray,
             valid: np.ndarray, norms: np.ndarray, max_evaluations: int
             ) -> tuple[BlockModel, np.ndarray, int, str]:
    """The output-error refinement when it lowers the cost (else `model`, `covariance` kept),
    the evaluations it took (Jacobians counted per column) and what happened."""
    candidate, solution = refine_output_error(model, u, y_zero, valid, norms,
                                              max_evaluations=max_evaluations)
    evaluations = solution.nfev + solution.njev * (len(model.parts()[0]) + 1)
    before = 0.5 * float(np.sum(_residuals(model, u, y_zero, valid, norms) ** 2))
    if solution.cost < before:
        return (candidate, _covariance(solution.jac, solution.fun), evaluations,
                f"refined by output error: {solution.message}")
    return (model, covariance, evaluations,
            "refinement did not lower the cost; the subspace estimate is kept")


def _state_space_result(data: IdentificationData, model: BlockModel, scaling: Scaling,
                        covariance: np.ndarray, fits: np.ndarray, details: dict[str, Any],
                        run: tuple[bool, str, int, float]) -> IdentificationResult:
    """The result record; `run` is (refined, message, evaluations, wall time [s])."""
    refine, message, evaluations, wall_time = run
    order = model.order
    names = parameter_names(order, data.input_names, data.output_names)
    std = np.sqrt(np.clip(np.diag(covariance), 0, None))
    return IdentificationResult(
        structure=f"blackbox-{order}", method="po-moesp+oe" if refine else "po-moesp",
        parameters=dict(zip(names, model.theta.tolist())), free=names,
        std=dict(zip(names, std.tolist())), covariance=covariance,
        fit=dict(zip(data.output_names, fits.tolist())), success=True,
        message=f"{message}; {LEVELS}",
        wall_time=wall_time, n_evaluations=evaluations,
        simulator=StateSpaceSimulator(model, scaling, data.input_names, data.output_names),
        details={**physical_matrices(model, scaling, data.sample_period), **details,
                 "levels": {"centred": True, "message": LEVELS},
                 "order": order, "input_names": data.input_names,
                 "output_names": data.output_names})


def _physical(model: BlockModel, scaling: Scaling, u: np.ndarray) -> np.ndarray:
    return model.simulate(u) * scaling.y_std + scaling.y_mean


def _describe(data: IdentificationData, fits: Any) -> str:
    return ", ".join(f"{n} {f:.2f} %" for n, f in zip(data.output_names, np.atleast_1d(fits)))


def _covariance(jac: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """``sigma^2 (J^T J)^+`` in the parameterisation's units."""
    dof = max(len(residuals) - jac.shape[1], 1)
    return float(residuals @ residuals) / dof * np.linalg.pinv(jac.T @ jac)


def parameter_names(order: int, inputs: Sequence[str], outputs: Sequence[str]) -> tuple[str, ...]:
    """Names of the parameterisation's entries (``n_free`` = their number)."""
    names = []
    for i in range(order // 2):
        names += [f"block{i + 1}_atanh_det", f"block{i + 1}_atanh_trace"]
    if order % 2:
        names.append("pole_atanh")
    names += [f"B[{i},{u}]" for i in range(order) for u in inputs]
    names += [f"C[{y},{i}]" for y in outputs for i in range(order)]
    names += [f"D[{y},{u}]" for y in outputs for u in inputs]
    names += [f"offset[{y}]" for y in outputs]
    return tuple(names)


def physical_matrices(model: BlockModel, scaling: Scaling, period: float) -> dict[str, Any]:
    """``A, B, C, D`` in physical units, reference levels, poles and their continuous modes."""
    _, b, c, d, offset = model.parts()
    a = model.a_matrix()
    b_phys = b / scaling.u_std
    c_phys = c * scaling.y_std[:, None]
    d_phys = d * scaling.y_std[:, None] / scaling.u_std
    poles = np.linalg.eigvals(a)
    return {"A": a.tolist(), "B": b_phys.tolist(), "C": c_phys.tolist(), "D": d_phys.tolist(),
            "u_ref": scaling.u_mean.tolist(),
            "y_ref": (scaling.y_mean + scaling.y_std * offset).tolist(),
            "sample_period": period, "poles": [[p.real, p.imag] for p in poles],
            "modes": modes(poles, period)}


def modes(poles: np.ndarray, period: float) -> list[dict[str, float]]:
    """Continuous equivalents ``s = ln(z) / T``: frequency ``|s| / 2 pi`` [Hz] and damping
    ``-Re(s) / |s|``, one entry per pole with ``Im z >= 0``, sorted by frequency."""
    out = []
    for z in poles:
        if z.imag < -1e-12:
            continue
        s = np.log(complex(z)) / period
        out.append({"frequency_hz": abs(s) / (2 * math.pi),
                    "damping": -s.real / abs(s) if abs(s) > 0 else 1.0,
                    "s_real": s.real, "s_imag": s.imag})
    return sorted(out, key=lambda mode: mode["frequency_hz"])


# --- identifiers -------------------------------------------------------------------------------

def identify_state_space(data: IdentificationData, *, order: int, executor: Any = None,
                         progress: Progress | None = None, outputs: Sequence[str] | None = None,
                         refine: bool = True, horizon: int | None = None,
                         max_evaluations: int = 100, **options: Any) -> IdentificationResult:
    """Identifier entry: fit the outputs (default those of ``("F_c", "y_cb")`` in `data`).

    The command line's generic options at their neutral values (no fixed parameters, ``method
    "lm"``, no multistart) mean nothing here and are accepted; any other option is an error.
    """
    neutral = {"fixed": {}, "method": "lm", "multistart": 0}
    options = {k: v for k, v in options.items() if not (k in neutral and v == neutral[k])}
    if options:
        raise IdentificationError(f"blackbox-{order}: unknown option(s) {sorted(options)}")
    del executor  # one fit takes seconds; nothing to spread
    outputs = tuple(outputs or [o for o in DEFAULT_OUTPUTS if o in data.output_names]
                    or data.output_names)
    return fit_state_space(data.select_outputs(outputs), order, refine=refine, horizon=horizon,
                           progress=progress, max_evaluations=max_evaluations)


__all__ = ["fit_state_space", "identify_state_space", "moesp", "block_form", "BlockModel",
           "StateSpaceSimulator", "modes", "parameter_names", "physical_matrices"]
