"""Which states and inputs each state derivative and output depends on, from the symbolic model.

The FMU declares, in its ``<ModelStructure>``, the structure of the Jacobian of
``[dx/dt; y]`` with respect to ``[x; u]`` (FMI 2.0.4 §3.3.4.1, FMI 3.0.1 §2.4.8). For a model
``dq/dt = v``, ``M(q) dv/dt = r(q, v, u)``, ``y = h(q, v, u)`` (:mod:`panto.fmu_src.symbolic`)
the entries are

.. math::

    \\frac{\\partial \\dot q_i}{\\partial v_k} = \\delta_{ik}, \\qquad
    \\frac{\\partial a}{\\partial q_k} = M^{-1}\\Big(\\frac{\\partial r}{\\partial q_k}
        - \\frac{\\partial M}{\\partial q_k} a\\Big), \\qquad
    \\frac{\\partial a}{\\partial [v, u]} = M^{-1} \\frac{\\partial r}{\\partial [v, u]},

and the output Jacobian of ``h``. Structurally, ``M^{-1}`` couples exactly the coordinates of
one connected component of the graph of ``M`` (``M`` is symmetric positive definite), so
acceleration ``a_i`` depends on a known if some ``r_j`` or some ``M_jl`` of its component does
(``dM/dq`` is dropped for a linearised model: ``a = 0`` at its equilibrium). For a linearised
model the entries are evaluated at rest (``v = 0``), where the velocity-product terms vanish.

Each nonzero entry also gets its FMI ``dependenciesKind``: ``"constant"`` (a number),
``"tunable"`` (a function of the tunable parameters only: every entry of a linearised model) or
``"dependent"`` (a function of states or inputs, or switching).
"""
from __future__ import annotations

import sympy as sp

from panto.fmu_src.symbolic import MechanicalModel

#: Dependency kinds from weakest to strongest ("" is no dependency).
KINDS = ("", "constant", "tunable", "dependent")


def _strongest(*kinds: str) -> str:
    return max(kinds, key=KINDS.index, default="")


def _kind(expression, variables: set, rest: dict, linearised: bool) -> str:
    """The dependency kind of one Jacobian entry (``""`` if it is structurally zero)."""
    entry = sp.sympify(expression)
    if rest:
        entry = entry.xreplace(rest)
    if entry == 0:
        return ""
    if entry.is_number:
        return "constant"
    if linearised:
        return "tunable"
    if entry.free_symbols & variables or entry.has(sp.Piecewise):
        return "dependent"
    return "tunable"


def _components(mass: sp.Matrix) -> list[set[int]]:
    """Connected components of the graph of the mass matrix (i ~ j if M_ij is not zero)."""
    n = mass.shape[0]
    component = list(range(n))

    def root(i: int) -> int:
        while component[i] != i:
            i = component[i]
        return i

    for i in range(n):
        for j in range(n):
            if mass[i, j] != 0:
                component[root(i)] = root(j)
    groups: dict[int, set[int]] = {}
    for i in range(n):
        groups.setdefault(root(i), set()).add(i)
    return [groups[root(i)] for i in range(n)]


def jacobian_structure(model: MechanicalModel, *, linearised: bool = False
                       ) -> tuple[tuple[str, ...], ...]:
    """The dependency kinds of ``[dx/dt; y]`` on ``[x; u]`` (see the module notes).

    Parameters
    ----------
    model : MechanicalModel
        The symbolic model.
    linearised : bool
        Structure of the model linearised about its static equilibrium.

    Returns
    -------
    tuple of tuple of str
        ``2 NQ + NY`` rows (state derivatives, then outputs) of ``2 NQ + NU`` entries (states
        ``[q; v]``, then inputs), each ``""`` or a kind of :data:`KINDS`.
    """
    nq = len(model.q)
    variables = set(model.q) | set(model.v) | set(model.u) | {d.symbol for d in model.dependents}
    rest = {v: sp.Integer(0) for v in model.v} if linearised else {}

    def kind(expression) -> str:
        return _kind(expression, variables, rest, linearised)

    drdq, drdv, drdu = model.forces_jacobian
    force_kinds = [[kind(m[j, k]) for m in (drdq, drdv, drdu) for k in range(m.shape[1])]
                   for j in range(nq)]
    mass_kinds = [[kind(model.mass_matrix[j, l]) for l in range(nq)] for j in range(nq)]
    mass_rates = [[_strongest(*(kind(dM[j, l]) for l in range(nq))) for dM in
                   model.mass_matrix_derivative] for j in range(nq)]
    rows = []
    for i in range(nq):  # dq_i/dt = v_i
        rows.append(tuple("constant" if k == nq + i else "" for k in range(2 * nq + len(model.u))))
    for i, component in enumerate(_components(model.mass_matrix)):
        inverse = _strongest(*(mass_kinds[j][l] for j in component for l in component))
        row = []
        for k in range(2 * nq + len(model.u)):
            entry = _strongest(*(force_kinds[j][k] for j in component))
            if k < nq and not linearised:
                entry = _strongest(entry, *(mass_rates[j][k] for j in component))
            row.append(_strongest(entry, inverse) if entry else "")
        rows.append(tuple(row))
    dydq, dydv, dydu = model.outputs_jacobian
    for o in range(len(model.outputs)):
        rows.append(tuple(kind(m[o, k]) for m in (dydq, dydv, dydu) for k in range(m.shape[1])))
    return tuple(rows)
