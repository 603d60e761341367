"""Symbolic mechanical models in generalised coordinates, and their exact derivatives.

Every model of the project (the pantograph of thesis chapter 2 and the oscillators of sections
2.6-2.7) is written as

.. math::

    \\dot q = v, \\qquad M(q)\\,\\dot v = r(q, v, u), \\qquad y = h(q, v, u)

where ``r`` holds the generalised forces of the Euler-Lagrange equations (2.23) minus the
velocity-product terms. Some models carry *dependent* quantities: the pantograph's linkage
angles phi2 and phi3 are closed-form functions of (phi1, delta) (Freudenstein solution, eqs.
2.3-2.14) whose partial derivatives S2, D2, S3, D3 are known in closed form (eqs. 2.17-2.18).
They are kept as symbols and differentiated with the chain rule (:meth:`MechanicalModel.total_derivative`),
which keeps the expressions small and the derivatives exact.
"""
from __future__ import annotations

import pickle
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import sympy as sp

# The cache helpers live apart (reading the cache needs no SymPy); imported here for
# cached_derivation and for the modules that take them from here.
from panto.fmu_src.disk_cache import (default_cache_dir, prune, read_verified, source_digest,
                                      write_atomic)
from panto.fmu_src.spec import ParameterSpec, Variable


@dataclass(frozen=True)
class Dependent:
    """A quantity computed from coordinates and parameters before everything else.

    Parameters
    ----------
    symbol : sympy.Symbol
        The symbol used for it in the model's expressions.
    expression : sympy.Expr
        Its closed form in coordinates, parameters and earlier dependents.
    partials : dict
        ``{coordinate: d symbol / d coordinate}`` in closed form (may use any dependents).
        Coordinates missing from the mapping do not influence the quantity.
    """

    symbol: sp.Symbol
    expression: sp.Expr
    partials: dict


@dataclass(frozen=True)
class Guard:
    """A condition ``expression >= 0`` that must hold before the dependents can be computed.

    ``message`` is a C/Python format string; ``{coordinates}`` is replaced by the values.
    """

    expression: sp.Expr
    message: str


@dataclass(frozen=True)
class MechanicalModel:
    """A mechanical model ``M(q) dv/dt = r(q, v, u)``, ``y = h(q, v, u)``.

    Parameters
    ----------
    name : str
        Model identifier (FMU model identifier).
    description : str
        One sentence for the FMU's description.
    coordinates, velocities, inputs, outputs : tuple of Variable
        The signals, in order; ``velocities[i]`` is the derivative of ``coordinates[i]``.
    parameters : tuple of ParameterSpec
        All parameters, in the order of the parameter vector.
    mass_matrix : sympy.Matrix
        ``M(q)``, NQ x NQ.
    forces : sympy.Matrix
        ``r(q, v, u)``, NQ x 1.
    output_expressions : sympy.Matrix
        ``h(q, v, u)``, NY x 1.
    dependents : tuple of Dependent
        Quantities computed first (in order).
    guards : tuple of Guard
        Conditions checked before the dependents are computed.
    energy : sympy.Expr, optional
        Total mechanical energy including the work potential of constant inputs (for tests).
    """

    name: str
    description: str
    coordinates: tuple[Variable, ...]
    velocities: tuple[Variable, ...]
    inputs: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    parameters: tuple[ParameterSpec, ...]
    mass_matrix: sp.Matrix
    forces: sp.Matrix
    output_expressions: sp.Matrix
    dependents: tuple[Dependent, ...] = ()
    guards: tuple[Guard, ...] = ()
    energy: sp.Expr | None = None
    extra: dict = field(default_factory=dict, compare=False, hash=False)

    # --- symbols -------------------------------------------------------------------------
    @cached_property
    def q(self) -> list[sp.Symbol]:
        """Coordinate symbols."""
        return [sp.Symbol(v.name, real=True) for v in self.coordinates]

    @cached_property
    def v(self) -> list[sp.Symbol]:
        """Velocity symbols."""
        return [sp.Symbol(v.name, real=True) for v in self.velocities]

    @cached_property
    def u(self) -> list[sp.Symbol]:
        """Input symbols."""
        return [sp.Symbol(v.name, real=True) for v in self.inputs]

    @cached_property
    def p(self) -> list[sp.Symbol]:
        """Parameter symbols."""
        return [sp.Symbol(par.name, real=True) for par in self.parameters]

    # --- exact derivatives ---------------------------------------------------------------
    def total_derivative(self, expression: sp.Expr, coordinate: sp.Symbol) -> sp.Expr:
        """Derivative of ``expression`` w.r.t. a coordinate, through the dependents.

        ``d e / d q = de/dq + sum_j de/dd_j * dd_j/dq`` (thesis eq. 2.19 for phi2, phi3).
        """
        return total_derivative(expression, coordinate, self.dependents)

    def total_jacobian(self, matrix: sp.Matrix) -> sp.Matrix:
        """Jacobian of a column matrix w.r.t. the coordinates, through the dependents."""
        return sp.Matrix(
            [[self.total_derivative(e, qk) for qk in self.q] for e in matrix]
        )

    @cached_property
    def mass_matrix_derivative(self) -> list[sp.Matrix]:
        """``[dM/dq_k for k]``."""
        return [self.mass_matrix.applyfunc(lambda e: self.total_derivative(e, qk)) for qk in self.q]

    @cached_property
    def forces_jacobian(self) -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
        """``(dr/dq, dr/dv, dr/du)``."""
        return (
            self.total_jacobian(self.forces),
            self.forces.jacobian(self.v),
            self.forces.jacobian(self.u),
        )

    @cached_property
    def outputs_jacobian(self) -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
        """``(dy/dq, dy/dv, dy/du)``."""
        return (
            self.total_jacobian(self.output_expressions),
            self.output_expressions.jacobian(self.v),
            self.output_expressions.jacobian(self.u),
        )


def total_derivative(
    expression: sp.Expr, coordinate: sp.Symbol, dependents: tuple[Dependent, ...]
) -> sp.Expr:
    """``d e / d q = de/dq + sum_j de/dd_j * dd_j/dq`` over the dependents ``d_j``."""
    result = sp.diff(expression, coordinate)
    for dependent in dependents:
        partial = dependent.partials.get(coordinate, 0)
        if partial != 0:
            result += sp.diff(expression, dependent.symbol) * partial
    return result


def lagrangian_forces(
    mass_matrix: sp.Matrix,
    generalised_forces: sp.Matrix,
    velocities: list[sp.Symbol],
    mass_matrix_derivative: list[sp.Matrix],
) -> sp.Matrix:
    """Right-hand side ``r`` of ``M(q) dv/dt = r`` from the Euler-Lagrange equations (2.23).

    With ``T = v^T M(q) v / 2``: ``d/dt dT/dv - dT/dq = M dv/dt + (sum_l dM/dq_l v_l) v -
    1/2 [v^T dM/dq_k v]_k``, so ``r = Q - (sum_l dM/dq_l v_l) v + 1/2 [v^T dM/dq_k v]_k``,
    where ``Q`` collects potential, dissipative (Rayleigh) and external generalised forces.
    """
    v = sp.Matrix(velocities)
    n = len(velocities)
    mass_rate = sp.zeros(n, n)
    for dM, vl in zip(mass_matrix_derivative, velocities):
        mass_rate += dM * vl
    centrifugal = sp.Matrix([(v.T * dM * v)[0, 0] / 2 for dM in mass_matrix_derivative])
    return generalised_forces - mass_rate * v + centrifugal


# --- cache of derived models ------------------------------------------------------------------

_DERIVED: dict[str, MechanicalModel] = {}


def cached_derivation(name: str, derive: Callable[[], MechanicalModel],
                      cache_dir: str | Path | None = None) -> MechanicalModel:
    """The model ``derive()`` returns, pickled in the cache folder for later processes.

    The derivation of the pantograph takes about a second in SymPy; the pickle loads in
    milliseconds. The file is keyed by :func:`source_digest`, so any change of the model
    sources derives again; a corrupted file is derived again and replaced.

    Parameters
    ----------
    name : str
        Model name (part of the file name).
    derive : callable
        Derivation without arguments.
    cache_dir : str or Path, optional
        Cache folder (default :func:`default_cache_dir`).
    """
    path = Path(cache_dir or default_cache_dir()) / f"{name}-{source_digest()}.model.pickle"
    if str(path) in _DERIVED:
        return _DERIVED[str(path)]
    payload = read_verified(path)
    model = None
    if payload is not None:
        try:
            model = pickle.loads(payload)  # noqa: S301 - our own file, checked by its digest
        except Exception:  # noqa: BLE001 - a bad pickle is rebuilt, whatever it raises
            model = None
    if not isinstance(model, MechanicalModel) or model.name != name:
        model = derive()
        if write_atomic(path, pickle.dumps(model, protocol=pickle.HIGHEST_PROTOCOL)):
            prune(path.parent, f"{name}-*.model.pickle")
    _DERIVED[str(path)] = model
    return model
