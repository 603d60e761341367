"""Online input design for the pantograph rig: one receding-horizon step per sample (section 5.4-5.5).

The thesis' online DoE (section 5.4) re-optimises the next `H` inputs at every sample for the
information accumulated so far and applies the first one. For the rig this must fit in the
identification's sample period (20 ms at 50 Hz), for both inputs and every rig limit. It does,
because the linearised structure (:class:`panto.identification.design.pantograph_sensitivity.
LinearisedPantograph`) is linear in its inputs: with the deviations :math:`\\Delta u` from the
operating point, the sensitivities over the horizon are

.. math:: \\psi_k = \\psi_k^{\\mathrm{free}} + \\sum_{j \\le k} S_{k-j} \\Delta u_j,
          \\qquad k = 1..H,

where :math:`\\psi^{\\mathrm{free}}` (equilibrium term plus the response to the past inputs) is
computed once per step and :math:`S_j = \\partial g_j / \\partial \\theta` are the Markov
parameters' sensitivities, a fixed block-Toeplitz matrix :math:`G`. The D-criterion of
:math:`M = M_\\mathrm{past} + \\sum_k \\psi_k^T \\Sigma^{-1} \\psi_k` (eq. 5.6, relative
parameters) then has the exact gradient

.. math:: \\frac{\\partial \\log\\det M}{\\partial \\Delta u} =
          2 \\sum_k \\sum_o \\sigma_o^{-2} (M^{-1} \\psi_{ko})^T G_{ko},

and SLSQP (:func:`scipy.optimize.minimize`) maximises it from the previous step's plan shifted
by one sample (warm start). Every limit is a *linear* constraint on the variables (the motor
acceleration :math:`a_i` and the pressure demand :math:`p^*_i` of each horizon sample):

* :math:`|a_i| \\le a_\\max` (box), :math:`v_i = v_0 + T \\sum_{l \\le i} a_l`,
  :math:`|v_i| \\le v_\\max`, :math:`x_i = x_0 + T \\sum_{l \\le i} v_l \\in [x_\\min, x_\\max]`;
* :math:`v_H = 0` at the end of the horizon (a terminal rest, so the shifted plan is always
  feasible at the next step: recursive feasibility);
* :math:`p^* \\in [p_\\min, p_\\max]` (box);
* the predicted contact force :math:`F_c = F_c^{\\mathrm{free}} + \\sum g_{F} \\Delta u \\ge
  F_\\min` (linear in the inputs as well).

The applied inputs are clipped to the boxes; a failed or infeasible optimisation falls back to
the feasible warm start (or braking to rest), so the step always returns inputs meeting the rig's
limits.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import LinearConstraint, minimize

from panto.identification.design.constraints import RigInputConstraints
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph


@dataclass(frozen=True)
class OnlineStep:
    """One receding-horizon step.

    Parameters
    ----------
    motor_position, pressure_demand : ndarray, shape (H,)
        The planned horizon [m about mid-stroke, bar]; the first sample is applied next.
    motor_acceleration : ndarray, shape (2 n_blocks,)
        The optimisation variables: motor acceleration [m/s^2] and pressure demand [bar] per
        block (the warm start of the next step).
    value : float
        :math:`\\log\\det` of the relative-parameter Fisher information with the plan.
    start_value : float
        The same for the warm start.
    iterations : int
    success : bool
    wall_time : float
        Seconds for the whole step.
    """

    motor_position: np.ndarray
    pressure_demand: np.ndarray
    motor_acceleration: np.ndarray
    value: float
    start_value: float
    iterations: int
    success: bool
    wall_time: float


class OnlineDesigner:
    r"""Precomputed horizon matrices for :func:`design_online_step` (module notes).

    Parameters
    ----------
    model : LinearisedPantograph
        Structure, free parameters, operating point and sample period; ``model.length`` must be
        at least ``memory + horizon``.
    constraints : RigInputConstraints
    horizon : int
        :math:`H` samples planned per step.
    memory : int
        Past samples whose response enters :math:`\\psi^{\\mathrm{free}}` (older inputs are taken
        as settled; their information is in the prior).
    noise_variance : sequence of float, optional
        :math:`\\sigma^2` per model output (default: the rig's sensor noise).
    max_iterations : int
        SLSQP iterations per step.
    block : int
        Move blocking: each variable (motor acceleration, pressure demand) is held for `block`
        samples, so SLSQP works on :math:`2 \lceil H / \mathrm{block} \rceil` variables.
    """

    def __init__(self, model: LinearisedPantograph, constraints: RigInputConstraints, *,
                 horizon: int = 20, memory: int = 150,
                 noise_variance: Sequence[float] | None = None, max_iterations: int = 15,
                 block: int = 4) -> None:
        if horizon < 2 or memory < 1 or memory + horizon > model.length:
            raise ValueError(f"horizon = {horizon} (>= 2) and memory = {memory} (>= 1) must fit "
                             f"in the model's length {model.length}")
        if model.sample_period != constraints.sample_period:
            raise ValueError(f"model sample period {model.sample_period} s differs from the "
                             f"constraints' {constraints.sample_period} s")
        self.model, self.constraints = model, constraints
        self.horizon, self.memory, self.max_iterations = int(horizon), int(memory), max_iterations
        variance = np.asarray(noise_variance if noise_variance is not None
                              else model.noise_variance_default(), float)
        self.weight = 1.0 / variance                                     # (n_out,)
        self.scale = np.abs(model.theta) + (model.theta == 0)
        # kernels in relative parameters: S (L, n_out, n_theta, 2), F_c Markov row (L, 2)
        kernel = model.impulse_sensitivity * self.scale[:, None, None, None]
        self.kernel = np.ascontiguousarray(kernel.transpose(1, 2, 0, 3))
        self.equilibrium = (model.equilibrium_sensitivity * self.scale[:, None]).T
        self.force_row = model.impulse[:, 2, :] if constraints.minimum_contact_force is not None \
            else None
        h = self.horizon
        lag = np.arange(h)[:, None] - np.arange(h)[None, :]             # k - j
        toeplitz = np.where(lag[..., None, None, None] >= 0,
                            self.kernel[np.clip(lag, 0, None)], 0.0)     # (H, H, o, th, 2)
        self.toeplitz = np.ascontiguousarray(toeplitz.transpose(0, 2, 3, 1, 4))  # (H,o,th,H,2)
        # lag of past sample w (of the last `memory`) seen from horizon sample k: k + W - w
        self.past_lags = np.arange(h)[:, None] + self.memory - np.arange(self.memory)[None, :]
        t = constraints.sample_period
        lower = np.tril(np.ones((h, h)))
        self.velocity_map = t * lower                                   # v = v0 + T L a
        self.position_map = t * lower @ self.velocity_map               # x = x0 + T L v0 1 + ...
        self.motor_to_input = np.zeros((h, 2, 2 * h))                   # du per variable
        self.motor_to_input[:, 0, :h] = self.position_map
        self.motor_to_input[np.arange(h), 1, h + np.arange(h)] = 1.0
        n_blocks = -(-h // block)
        hold = np.zeros((h, n_blocks))
        hold[np.arange(h), np.arange(h) // block] = 1.0
        self.expand = np.zeros((2 * h, 2 * n_blocks))                  # samples <- blocks
        self.expand[:h, :n_blocks], self.expand[h:, n_blocks:] = hold, hold
        self.n_blocks = n_blocks
        self.motor_to_input = self.motor_to_input @ self.expand
        self.gradient_map = np.einsum("kotji,jiv->kotv", self.toeplitz, self.motor_to_input)
        if self.force_row is not None:
            self.force_toeplitz = np.where(lag[..., None] >= 0,
                                           self.force_row[np.clip(lag, 0, None)], 0.0)
            self.force_map = np.einsum("kji,jiv->kv", self.force_toeplitz, self.motor_to_input)

    # --- pieces of a step --------------------------------------------------------------------

    def free_response(self, past_inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """:math:`\\psi^{\\mathrm{free}}` (H, n_out, n_theta) and the free contact force (H,) with
        the inputs held at the operating point from now on."""
        du = np.asarray(past_inputs, float)[-self.memory:] - np.array(self.model.operating_point)
        lags = self.past_lags[:, self.memory - len(du):]                # (H, W)
        psi = self.equilibrium + np.einsum("kwoti,wi->kot", self.kernel[lags], du)
        force = None
        if self.force_row is not None:
            force = self.model.equilibrium_outputs[2] + np.einsum("kwi,wi->k",
                                                                 self.force_row[lags], du)
        return psi, force

    def decode(self, variables: np.ndarray, motor_state: tuple[float, float],
               ) -> tuple[np.ndarray, np.ndarray]:
        """Motor positions and pressure demands (H,) of the variables ``[a (H), p* (H)]``."""
        h, t = self.horizon, self.constraints.sample_period
        x0, v0 = motor_state
        samples = self.expand @ variables
        motor = x0 + t * v0 * np.arange(1, h + 1) + self.position_map @ samples[:h]
        return motor, samples[h:]

    def cost(self, variables: np.ndarray, psi_free: np.ndarray, base: np.ndarray,
             prior: np.ndarray) -> tuple[float, np.ndarray]:
        """:math:`-\\log\\det M` and its gradient in the variables (module notes)."""
        psi = psi_free + np.einsum("kotv,v->kot", self.gradient_map, variables) + base
        weighted = psi * self.weight[None, :, None]
        fisher = prior + np.einsum("kot,kos->ts", weighted, psi)
        sign, logdet = np.linalg.slogdet(fisher)
        if sign <= 0:
            return 1e6, np.zeros_like(variables)
        r = np.linalg.solve(fisher, weighted.reshape(-1, psi.shape[-1]).T)  # (th, k*o)
        gradient = 2.0 * np.einsum("tn,ntv->v", r, self.gradient_map.reshape(
            -1, psi.shape[-1], variables.size))
        return -float(logdet), -gradient

    def linear_constraints(self, motor_state: tuple[float, float],
                           force_free: np.ndarray | None, base_force: np.ndarray | float
                           ) -> list[LinearConstraint]:
        """Speed, position, terminal rest and contact force as :class:`LinearConstraint`."""
        c, h, t = self.constraints, self.horizon, self.constraints.sample_period
        x0, v0 = motor_state
        zeros = np.zeros((h, h))
        speed = np.hstack([self.velocity_map, zeros]) @ self.expand
        position = np.hstack([self.position_map, zeros]) @ self.expand
        drift = x0 + t * v0 * np.arange(1, h + 1)
        rows = [LinearConstraint(speed[:-1], -c.motor_speed - v0, c.motor_speed - v0),
                LinearConstraint(speed[-1:], -v0, -v0),
                LinearConstraint(position, c.motor_min - drift, c.motor_max - drift)]
        if force_free is not None:
            rows.append(LinearConstraint(self.force_map, c.minimum_contact_force - force_free
                                         - base_force, np.inf))
        return rows

    def bounds(self) -> list[tuple[float, float]]:
        c, n = self.constraints, self.n_blocks
        return [(-c.motor_acceleration, c.motor_acceleration)] * n + \
            [(c.pressure_min, c.pressure_max)] * n


def design_online_step(designer: OnlineDesigner, past_motor: np.ndarray,
                       past_demand: np.ndarray, *, prior_fisher: np.ndarray | None = None,
                       warm_start: OnlineStep | None = None) -> OnlineStep:
    """Plan the next H motor positions and pressure demands (module notes); apply the first.

    Parameters
    ----------
    designer : OnlineDesigner
    past_motor, past_demand : ndarray, shape (k,)
        Motor positions [m about mid-stroke] and pressure demands [bar] applied so far (sample 0
        is the rest point); the motor's speed is taken from the last two.
    prior_fisher : ndarray, shape (n_theta, n_theta), optional
        Information of the samples already measured, in *relative* parameters
        (:math:`D M D`, :math:`D = \\operatorname{diag}|\\theta|`); default a tiny multiple of I.
    warm_start : OnlineStep, optional
        The previous step; its plan shifted by one sample (padded by braking) is the start.

    Returns
    -------
    OnlineStep
        A plan meeting every limit; ``motor_position[0]``, ``pressure_demand[0]`` are applied.
    """
    began = time.perf_counter()
    d, c, h = designer, designer.constraints, designer.horizon
    past_motor, past_demand = np.asarray(past_motor, float), np.asarray(past_demand, float)
    speed = (past_motor[-1] - past_motor[-2]) / c.sample_period if len(past_motor) > 1 else 0.0
    state = (float(past_motor[-1]), float(speed))
    past = np.stack([c.motor_zero_height + past_motor, past_demand], axis=-1)
    psi_free, force_free = d.free_response(past)
    prior = prior_fisher if prior_fisher is not None else 1e-9 * np.eye(len(d.scale))
    start = _warm_start(d, state, past_demand[-1], warm_start)
    # the part of du not in the variables: the motor's drift x0 + T v0 k, the demand's -p0
    offset = np.column_stack([state[0] + c.sample_period * state[1] * np.arange(1, h + 1),
                              np.full(h, -d.model.operating_point[1])])
    base = np.einsum("kotji,ji->kot", d.toeplitz, offset)
    base_force = np.einsum("kji,ji->k", d.force_toeplitz, offset) \
        if force_free is not None else 0.0
    constraints = d.linear_constraints(state, force_free, base_force)
    start_cost, _ = d.cost(start, psi_free, base, prior)
    result = minimize(d.cost, start, args=(psi_free, base, prior), jac=True, method="SLSQP",
                      bounds=d.bounds(), constraints=constraints,
                      options={"maxiter": d.max_iterations, "ftol": 1e-9})
    candidates = [np.clip(result.x, *np.array(d.bounds()).T), start,
                  _brake(d, state, past_demand[-1]), _brake(d, state, c.pressure_start)]
    scored = [(_violation(constraints, x), d.cost(x, psi_free, base, prior)[0], i)
              for i, x in enumerate(candidates)]
    # feasible first (violation within tolerance), then the lowest cost
    best = min(scored, key=lambda item: (item[0] > 1e-7, item[0] if item[0] > 1e-7 else 0.0,
                                         item[1]))
    chosen, feasible = candidates[best[2]], best[0] <= 1e-7
    value = best[1]
    motor, demand = d.decode(chosen, state)
    return OnlineStep(motor, demand, chosen, -value, -start_cost, int(result.nit),
                      bool(feasible), time.perf_counter() - began)


def _violation(constraints: list[LinearConstraint], x: np.ndarray) -> float:
    """Largest violation of the linear constraints (0 when all hold), in their units."""
    worst = 0.0
    for item in constraints:
        value = item.A @ x
        worst = max(worst, float(np.max(item.lb - value)), float(np.max(value - item.ub)))
    return worst


def _brake(d: OnlineDesigner, state: tuple[float, float], demand: float) -> np.ndarray:
    """Decelerate (per block, at most the largest allowed rate) to rest, pressure held."""
    n, t = d.n_blocks, d.constraints.sample_period
    _, v = state
    a = np.zeros(n)
    for i in range(n):
        length = min(-(-d.horizon // n), d.horizon - i * (-(-d.horizon // n)))
        a[i] = np.clip(-v / (t * max(length, 1)), -d.constraints.motor_acceleration,
                       d.constraints.motor_acceleration)
        v += t * length * a[i]
    return np.concatenate([a, np.full(n, demand)])


def _warm_start(d: OnlineDesigner, state: tuple[float, float], demand: float,
                previous: OnlineStep | None) -> np.ndarray:
    """The previous step's block variables (the plan one sample later); else brake to rest."""
    if previous is None:
        return _brake(d, state, demand)
    return previous.motor_acceleration.copy()


def run_online_design(designer: OnlineDesigner, n_samples: int, *,
                      progress=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed loop on the model: ``n_samples`` steps from rest, the information of each applied
    sample added to the prior. Returns motor positions, pressure demands (n_samples,) and the
    seconds per step."""
    c, model = designer.constraints, designer.model
    motor, demand = [0.0], [c.pressure_start]
    prior = 1e-9 * np.eye(len(designer.scale))
    step, times = None, []
    scale = np.outer(designer.scale, designer.scale)
    for k in range(1, n_samples):
        step = design_online_step(designer, np.array(motor), np.array(demand),
                                  prior_fisher=prior, warm_start=step)
        motor.append(float(step.motor_position[0]))
        demand.append(float(step.pressure_demand[0]))
        times.append(step.wall_time)
        window = slice(max(0, len(motor) - designer.memory), None)
        u = np.stack([c.motor_zero_height + np.array(motor[window]), np.array(demand[window])],
                     axis=-1)
        _, psi = model.sensitivities(None, u)
        newest = psi[-1] * np.sqrt(designer.weight)[:, None]
        prior = prior + scale * (newest.T @ newest)
        if progress is not None and k % max(1, n_samples // 10) == 0:
            progress(f"online DoE: sample {k}/{n_samples}, log det {step.value:.4g}, "
                     f"{1e3 * step.wall_time:.1f} ms")
    return np.array(motor), np.array(demand), np.array(times)
