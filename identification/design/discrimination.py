"""Discrimination design (T-optimality): make a candidate effect show in the rig's outputs.

Thesis section 5.5: "an experiment whose goal is the discrimination between different model
structures [42]... the next input point is set to maximise the difference between the output of
both models". Here the rival structures are the nominal model and the model extended by one
effect (the sim-to-real diagnosis' question "is the effect there?"):

* ``"F_f1"``: Coulomb friction on the lower mass of the two-mass oscillator
  (:class:`panto.identification.structures.oscillators.OscillatorStructure` with friction; cheap);
* ``"T_f"``: hinge friction in the nonlinear pantograph
  (:class:`panto.identification.structures.physical.PhysicalNonlinear`, the FMU in the loop; use a small
  population).

The criterion is the noise-weighted difference the nominal model cannot absorb by re-fitting its
free parameters (Atkinson & Fedorov's T-optimality, linearised): with
:math:`\\Delta = (y_\\mathrm{ext} - y_\\mathrm{nom}) / \\sigma` and the whitened nominal
sensitivities :math:`\\Psi`,

.. math:: T = \\lVert (I - \\Psi (\\Psi^T \\Psi)^{-1} \\Psi^T) \\Delta \\rVert^2,

the non-centrality of the :math:`\\chi^2` test between the two structures (large T: the effect
is detectable). The inputs, their parametrisation and the rig constraints are those of
:mod:`panto.identification.design.pantograph`.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from panto.identification.design.constraints import RigInputConstraints, conventional_inputs
from panto.identification.design.pantograph import (
    DesignOptions,
    LevelProblem,
    model_inputs,
    run_level_ga,
)
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

#: Effects and (structure of the nominal model, default effect size).
EFFECTS = {"F_f1": ("two-mass", 5.0), "T_f": ("physical-linear", 20.0)}


class EffectModel:
    """Nominal structure and the structure extended by `effect` on absolute inputs (eta, p*).

    Parameters
    ----------
    effect : {"F_f1", "T_f"}
    value : float, optional
        Size of the effect (N for ``F_f1``, N m for ``T_f``; default :data:`EFFECTS`).
    model : LinearisedPantograph
        The nominal structure's sensitivities (two-mass for ``F_f1``; physical-linear for
        ``T_f``, whose nominal outputs then come from the FMU with ``T_f = 0``).
    """

    def __init__(self, effect: str, model: LinearisedPantograph, value: float | None = None,
                 *, fmu_path: str | None = None) -> None:
        if effect not in EFFECTS:
            raise ValueError(f"effect {effect!r}: choose from {sorted(EFFECTS)}")
        if model.structure_name != EFFECTS[effect][0]:
            raise ValueError(f"effect {effect!r} needs a {EFFECTS[effect][0]!r} model, got "
                             f"{model.structure_name!r}")
        self.effect, self.model = effect, model
        self.value = float(EFFECTS[effect][1] if value is None else value)
        self.fmu_path = fmu_path

    def outputs(self, inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nominal and extended outputs ``(..., N, n_out)`` for inputs ``(..., N, 2)``."""
        inputs = np.asarray(inputs, float)
        lag, period = self.model.pressure_lag, self.model.sample_period
        measured = inputs.copy()
        if lag is not None:
            measured[..., 1] = lag.apply(inputs[..., 1], period, self.model.operating_point[1])
        if self.effect == "F_f1":
            from panto.identification.structures.oscillators import OscillatorStructure

            friction = OscillatorStructure(2, friction=True, outputs=self.model.output_names)
            values = friction.values(dict(self.model.parameters)
                                     | {"F_f1": self.value, "F_f2": 0.0})
            return self.model.simulate(inputs), simulate_friction(friction, values, measured,
                                                                  period)
        flat = measured.reshape(-1, *measured.shape[-2:])
        pairs = [self._fmu_pair(row) for row in flat]
        shape = (*inputs.shape[:-1], len(self.model.output_names))
        return (np.array([p[0] for p in pairs]).reshape(shape),
                np.array([p[1] for p in pairs]).reshape(shape))

    def _fmu_pair(self, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from panto.identification.estimation.base import IdentificationData
        from panto.identification.structures.physical import PhysicalNonlinear

        fmu = PhysicalNonlinear(outputs=self.model.output_names, fmu_path=self.fmu_path)
        grid = np.arange(len(measured)) * self.model.sample_period
        data = IdentificationData(grid, measured, np.zeros((len(measured), 1)), ("eta", "p"),
                                  ("none",))
        values = {n: v for n, v in self.model.parameters.items() if n in fmu.parameter_names}
        return (fmu.simulate(values | {"T_f": 0.0}, data),
                fmu.simulate(values | {"T_f": self.value}, data))

    def criterion(self, inputs: np.ndarray, noise_variance: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
        """(T, plain) per input ``(..., N, 2)``: the unexplained and the raw whitened squared
        output difference (module notes)."""
        inputs = np.asarray(inputs, float)
        nominal, extended = self.outputs(inputs)
        sigma = np.sqrt(np.asarray(noise_variance, float))
        delta = ((extended - nominal) / sigma).reshape(-1, inputs.shape[-2] * len(sigma))
        _, psi = self.model.sensitivities(None, inputs)
        basis = (psi / sigma[:, None]).reshape(len(delta), delta.shape[1], psi.shape[-1])
        t_values = np.empty(len(delta))
        for i, (b, d) in enumerate(zip(basis, delta)):
            coefficients, *_ = np.linalg.lstsq(b, d, rcond=None)
            t_values[i] = np.sum((d - b @ coefficients) ** 2)
        shape = inputs.shape[:-2]
        return t_values.reshape(shape), np.sum(delta ** 2, axis=-1).reshape(shape)


def simulate_friction(structure, values: dict, inputs: np.ndarray, period: float) -> np.ndarray:
    """Outputs of a friction oscillator for a stack of inputs ``(..., N, 2)`` (eta, p) at once.

    The scheme of :mod:`panto.identification.structures.oscillators` (Strang splitting: half a step of the exact
    Coulomb flow, the exact linear flow, half a step of friction), written over a population so
    that one time loop serves every candidate; all start in the equilibrium at the first sample.
    """
    from panto.identification.structures.oscillators import coulomb_flow, discretise

    u = np.concatenate([inputs, np.ones((*inputs.shape[:-1], 1))], axis=-1)
    u = u.reshape(-1, *u.shape[-2:])
    a, b, c, d = structure.matrices(values)
    x0 = structure.equilibrium(values, u[0, 0, 0], u[0, 0, 1])
    n, substeps = structure.masses, structure.substeps
    h = period / substeps
    phi, gamma0, gamma1 = discretise(a, b, h, structure.hold)
    du = np.diff(u, axis=1) if structure.hold == "foh" else np.zeros_like(u[:, 1:])
    v_eps = values["v_eps"]
    friction = np.array([values[f"F_f{i + 1}"] / values[f"m{i + 1}"] for i in range(n)])
    half = np.exp(-friction * (h / 2.0) / v_eps)
    full = half * half
    x = np.tile(x0, (len(u), 1))
    x[:, n:] = coulomb_flow(x[:, n:], -np.log(half), v_eps)
    states = np.empty((len(u), u.shape[1], 2 * n))
    states[:, 0] = x0
    for k in range(u.shape[1] - 1):
        for j in range(substeps):
            start = u[:, k] + (j / substeps) * du[:, k]
            x = x @ phi.T + start @ gamma0.T + (du[:, k] / substeps) @ gamma1.T
            v = np.clip(x[:, n:] / v_eps, -700.0, 700.0)
            if j == substeps - 1:
                states[:, k + 1, :n] = x[:, :n]
                states[:, k + 1, n:] = x[:, n:] + v_eps * (np.arcsinh(np.sinh(v) * half) - v)
            x[:, n:] += v_eps * (np.arcsinh(np.sinh(v) * full) - v)
    rows = [("y_cb", "xi", "F_c").index(o) for o in structure.output_names]
    y = states @ c[rows].T + u @ d[rows].T
    return y.reshape(*inputs.shape[:-1], len(rows))


@dataclass(frozen=True)
class DiscriminationDesign:
    """A discrimination design and the conventional input's score.

    Parameters
    ----------
    effect : str
    value : float
        Effect size assumed.
    time, motor_position, pressure_demand : ndarray, shape (N,)
    conventional_motor_position, conventional_pressure_demand : ndarray, shape (N,)
    difference, conventional_difference : ndarray, shape (N, n_outputs)
        Predicted output difference extended - nominal.
    value_t, conventional_value_t : float
        T criterion (module notes) of the design and of the conventional input.
    plain, conventional_plain : float
        Whitened squared difference without re-fitting.
    constraints : RigInputConstraints
    history : ndarray
    n_evaluations : int
    wall_time : float
    message : str
    """

    effect: str
    value: float
    time: np.ndarray
    motor_position: np.ndarray
    pressure_demand: np.ndarray
    conventional_motor_position: np.ndarray
    conventional_pressure_demand: np.ndarray
    difference: np.ndarray
    conventional_difference: np.ndarray
    value_t: float
    conventional_value_t: float
    plain: float
    conventional_plain: float
    constraints: RigInputConstraints
    history: np.ndarray
    n_evaluations: int
    wall_time: float
    message: str

    def summary(self) -> dict:
        """JSON-ready summary."""
        return {"effect": self.effect, "value": self.value, "T_designed": self.value_t,
                "T_conventional": self.conventional_value_t, "plain_designed": self.plain,
                "plain_conventional": self.conventional_plain,
                "ratio": self.value_t / max(self.conventional_value_t, 1e-300),
                "n_evaluations": self.n_evaluations, "wall_time_s": self.wall_time,
                "message": self.message,
                "violations": self.constraints.violations(self.motor_position,
                                                          self.pressure_demand)}


class _DiscriminationProblem(LevelProblem):
    """Levels -> inputs as in the D design; objective -T (one simulation pair per candidate)."""

    def __init__(self, effect: EffectModel, constraints: RigInputConstraints,
                 noise_variance: np.ndarray) -> None:
        super().__init__(effect.model, constraints, effect.model.length, "D", noise_variance)
        self.effect = effect

    def scores(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        u = model_inputs(*self.inputs(x), self.constraints)
        cost = -self.effect.criterion(u, self.noise_variance)[0]
        self.n_evaluations += len(u)
        return cost, self.contact_violation(u)


def design_discrimination(effect: EffectModel,
                          constraints: RigInputConstraints = RigInputConstraints(), *,
                          noise_variance: Sequence[float] | None = None,
                          options: DesignOptions = DesignOptions(population=16, generations=20),
                          conventional: tuple[np.ndarray, np.ndarray] | None = None,
                          progress: Callable[[str], None] | None = None) -> DiscriminationDesign:
    """Inputs that maximise the T criterion of `effect` within the rig's limits.

    Parameters
    ----------
    effect : EffectModel
    constraints : RigInputConstraints
    noise_variance : sequence of float, optional
        :math:`\\sigma^2` per output (default: the rig's sensor noise).
    options : DesignOptions
        Keep the population small for ``T_f`` (two FMU runs per candidate).
    conventional : (motor, demand), optional
        Comparison input (default: the APRBS training profile of equal length).
    progress : callable, optional
    """
    began = time.perf_counter()
    model = effect.model
    variance = np.asarray(noise_variance if noise_variance is not None
                          else model.noise_variance_default(), float)
    problem = _DiscriminationProblem(effect, constraints, variance)
    history: list[float] = []

    def callback(algorithm) -> None:
        history.append(float(algorithm.opt.get("F").min()))
        if progress is not None:
            progress(f"discrimination DoE: generation {algorithm.n_gen}/{options.generations}, "
                     f"T = {-history[-1]:.6g}")

    result = run_level_ga(problem, options, callback)
    if result.X is None:
        raise ValueError("no design met the contact-force constraint")
    motor, demand = problem.inputs(np.asarray(result.X, float))
    if conventional is None:
        conventional = conventional_inputs(model.length, constraints)
    scores = []
    for m, d in ((motor, demand), conventional):
        u = model_inputs(m, d, constraints)
        nominal, extended = effect.outputs(u)
        t_value, plain = effect.criterion(u, variance)
        scores.append((extended - nominal, float(t_value), float(plain)))
    (diff, t_value, plain), (diff_c, t_c, plain_c) = scores
    return DiscriminationDesign(
        effect.effect, effect.value, np.arange(model.length) * constraints.sample_period, motor,
        demand, np.asarray(conventional[0]), np.asarray(conventional[1]), diff, diff_c, t_value,
        t_c, plain, plain_c, constraints, np.asarray(history), problem.n_evaluations,
        time.perf_counter() - began,
        f"GA: {options.generations} generations of {options.population}")
