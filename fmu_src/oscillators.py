"""The simple model structures of thesis sections 2.6-2.7: two- and three-mass oscillators.

Masses are numbered from the bottom (1, attached to the base by k1/c1) to the top (the head, in
contact with the wire through the carbon-contact spring k_E to the input eta). The bellow acts as a
force ``p_gain * p + F_0`` on the lowest mass; Coulomb friction ``F_f,i tanh(v_i / v_eps)``
(eq. 2.35, smoothed as the thesis suggests) acts on every mass and is off by default. Gravity is
not modelled: as in EN 50318 and eq. 2.33 the weight is part of the calibrated uplift force, and
all springs are relaxed when every mass is at the height ``y_0``.

Outputs are those of the physical model so that the structures are interchangeable: ``y_cb``
(the mass under the head, the frame / cross-bar analogue), ``xi`` (the head) and ``F_c``.

The EN 50318:2002 reference pantograph is the two-mass oscillator with m1 = 15 kg (frame),
m2 = 7.2 kg (head), k1 = 50 N/m, c1 = 90 N s/m, k2 = 4200 N/m, c2 = 10 N s/m, F_0 = 120 N,
k_E = 50 000 N/m (``reference/catenary_en50318.md``); it is the default parameter set of
``TwoMass``.
"""
from __future__ import annotations

from functools import lru_cache

import sympy as sp

from panto.fmu_src.spec import ParameterSpec, Variable
from panto.fmu_src.symbolic import MechanicalModel

_EN = "EN 50318:2002 reference pantograph [2nd], reference/catenary_en50318.md"
_BRUNI = "Bruni et al. 2015 benchmark pantograph [2nd/recall], reference/catenary_en50318.md"
_CHOICE = "project choice"

#: Default masses, stiffnesses, dampers per structure, bottom to top.
DEFAULTS = {
    2: {"m": (15.0, 7.2), "k": (50.0, 4200.0), "c": (90.0, 10.0), "F_0": 120.0,
        "source": _EN},
    3: {"m": (6.0, 9.0, 7.5), "k": (160.0, 15500.0, 7000.0), "c": (100.0, 0.0, 0.0),
        "F_0": 120.0, "source": _BRUNI + "; dampers other than the frame's and F_0: project choice"},
}


def _parameters(n: int) -> tuple[ParameterSpec, ...]:
    d = DEFAULTS[n]
    src = d["source"]
    specs = []
    for i in range(n):
        place = "base" if i == 0 else f"mass {i}"
        specs += [
            ParameterSpec(f"m{i + 1}", d["m"][i], "kg", f"mass {i + 1} (1 = bottom)", 1e-6, 1e5, src),
            ParameterSpec(f"k{i + 1}", d["k"][i], "N/m", f"spring between {place} and mass {i + 1}", 0.0, 1e10, src),
            ParameterSpec(f"c{i + 1}", d["c"][i], "N.s/m", f"damper between {place} and mass {i + 1}", 0.0, 1e8, src),
        ]
    specs += [
        ParameterSpec("k_E", 50000.0, "N/m", "carbon contact stiffness to the wire", 0.0, 1e10,
                      "EN 50318 value (thesis section 4.5)"),
        ParameterSpec("p_gain", 0.0, "N/bar", "uplift force per bellow pressure on mass 1", -1e6, 1e6,
                      _CHOICE + " (identified from rig data, thesis section 4.6)"),
        ParameterSpec("F_0", d["F_0"], "N", "constant uplift force on mass 1", -1e6, 1e6, src),
        ParameterSpec("y_0", 0.0, "m", "height at which all springs are relaxed", -100.0, 100.0, _CHOICE),
    ]
    specs += [ParameterSpec(f"F_f{i + 1}", 0.0, "N", f"Coulomb friction on mass {i + 1} (eq. 2.35)",
                            0.0, 1e6, _CHOICE + ": off by default") for i in range(n)]
    specs += [
        ParameterSpec("v_eps", 1e-3, "m/s", "velocity scale of the tanh-smoothed friction", 1e-9, 10.0, _CHOICE),
        ParameterSpec("unilateral_contact", 0.0, "1", "contact can only push (contact loss)",
                      0.0, 1.0, _CHOICE, boolean=True),
    ]
    return tuple(specs)


@lru_cache(maxsize=2)
def derive_oscillator(n: int) -> MechanicalModel:
    """The n-mass oscillator (n = 2 or 3) as a :class:`MechanicalModel`.

    Equations (eq. 2.33/2.37 generalised to n masses)::

        m_i a_i = -k_i (x_i - x_{i-1}) - c_i (v_i - v_{i-1})
                  + k_{i+1} (x_{i+1} - x_i) + c_{i+1} (v_{i+1} - v_i) - F_f,i tanh(v_i / v_eps)
                  + [i = 1] (p_gain p + F_0) - [i = n] F_c

    with x_0 = v_0 = 0 measured from y_0, and ``F_c = k_E (x_n - eta)`` (zero for x_n < eta
    when the contact is unilateral).
    """
    if n not in DEFAULTS:
        raise ValueError(f"oscillator with {n} masses is not defined (choose 2 or 3)")
    params = _parameters(n)
    sym = {par.name: sp.Symbol(par.name, real=True) for par in params}
    x = [sp.Symbol(f"x{i + 1}", real=True) for i in range(n)]
    v = [sp.Symbol(f"v{i + 1}", real=True) for i in range(n)]
    eta, p = sp.symbols("eta p", real=True)
    rel = [xi - sym["y_0"] for xi in x]  # spring deflection from the relaxed height
    spring = sym["k_E"] * (x[-1] - eta)
    contact = sp.Piecewise((0, sp.And(sym["unilateral_contact"] > sp.Rational(1, 2), x[-1] < eta)),
                           (spring, True))

    def link(i: int) -> sp.Expr:
        """Force of the spring-damper below mass i (index from 0) on that mass."""
        below_x = rel[i - 1] if i > 0 else 0
        below_v = v[i - 1] if i > 0 else 0
        return -sym[f"k{i + 1}"] * (rel[i] - below_x) - sym[f"c{i + 1}"] * (v[i] - below_v)

    forces = []
    for i in range(n):
        f = link(i) - sym[f"F_f{i + 1}"] * sp.tanh(v[i] / sym["v_eps"])
        if i + 1 < n:
            f -= link(i + 1)
        if i == 0:
            f += sym["p_gain"] * p + sym["F_0"]
        if i == n - 1:
            f -= contact
        forces.append(f)
    mass = sp.diag(*[sym[f"m{i + 1}"] for i in range(n)])
    potential = sum(sym[f"k{i + 1}"] * (rel[i] - (rel[i - 1] if i else 0)) ** 2 / 2 for i in range(n))
    work = (sym["p_gain"] * p + sym["F_0"]) * x[0]
    kinetic = sum(sym[f"m{i + 1}"] * v[i] ** 2 / 2 for i in range(n))
    name = {2: "TwoMass", 3: "ThreeMass"}[n]
    return MechanicalModel(
        name=name,
        description=f"{n}-mass oscillator pantograph (thesis sections 2.6-2.7)",
        coordinates=tuple(Variable(f"x{i + 1}", "m", f"height of mass {i + 1}") for i in range(n)),
        velocities=tuple(Variable(f"v{i + 1}", "m/s", f"velocity of mass {i + 1}") for i in range(n)),
        inputs=(Variable("eta", "m", "contact wire / linear motor height", 0.0),
                Variable("p", "bar", "bellow pressure", 0.0)),
        outputs=(Variable("y_cb", "m", "height of the mass under the head (frame)"),
                 Variable("xi", "m", "head height"),
                 Variable("F_c", "N", "contact force, positive when the head presses up on the wire")),
        parameters=params, mass_matrix=mass, forces=sp.Matrix(forces),
        output_expressions=sp.Matrix([x[-2], x[-1], contact]),
        energy=kinetic + potential + sym["k_E"] * (x[-1] - eta) ** 2 / 2 - work,
    )


@lru_cache(maxsize=2)
def derive_oscillator_force(n: int) -> MechanicalModel:
    """The n-mass oscillator (n = 2 or 3) excited by force: contact force in, head motion out.

    The model of :func:`derive_oscillator` without the contact spring (thesis section 4.8: the
    derived models "in force-input form"): the contact force ``F_c`` [N] is an input that pushes
    the head (mass n) down, so that a co-simulation master coupling by force feeds it the
    catenary's contact force. Equations::

        m_i a_i = -k_i (x_i - x_{i-1}) - c_i (v_i - v_{i-1})
                  + k_{i+1} (x_{i+1} - x_i) + c_{i+1} (v_{i+1} - v_i) - F_f,i tanh(v_i / v_eps)
                  + [i = 1] (p_gain p + F_0) - [i = n] F_c

    with x_0 = v_0 = 0 measured from y_0. The spring k1 grounds the chain: for k1 > 0 constant
    inputs settle at x_1 - y_0 = (p_gain p + F_0 - F_c) / k1, each spring k_j above mass 1
    shortened by F_c / k_j; for k1 = 0 the chain has a zero eigenvalue and a constant net force
    drives it away at the terminal speed (p_gain p + F_0 - F_c) / c1.
    """
    if n not in DEFAULTS:
        raise ValueError(f"oscillator with {n} masses is not defined (choose 2 or 3)")
    params = tuple(s for s in _parameters(n) if s.name not in ("k_E", "unilateral_contact"))
    sym = {par.name: sp.Symbol(par.name, real=True) for par in params}
    x = [sp.Symbol(f"x{i + 1}", real=True) for i in range(n)]
    v = [sp.Symbol(f"v{i + 1}", real=True) for i in range(n)]
    f_c, p = sp.symbols("F_c p", real=True)
    rel = [xi - sym["y_0"] for xi in x]
    uplift = sym["p_gain"] * p + sym["F_0"]

    def link(i: int) -> sp.Expr:
        """Force of the spring-damper below mass i (index from 0) on that mass."""
        below_x, below_v = (rel[i - 1], v[i - 1]) if i > 0 else (0, 0)
        return -sym[f"k{i + 1}"] * (rel[i] - below_x) - sym[f"c{i + 1}"] * (v[i] - below_v)

    forces = [link(i) - sym[f"F_f{i + 1}"] * sp.tanh(v[i] / sym["v_eps"])
              - (link(i + 1) if i + 1 < n else f_c) + (uplift if i == 0 else 0) for i in range(n)]
    potential = sum(sym[f"k{i + 1}"] * (rel[i] - (rel[i - 1] if i else 0)) ** 2 / 2 for i in range(n))
    kinetic = sum(sym[f"m{i + 1}"] * v[i] ** 2 / 2 for i in range(n))
    return MechanicalModel(
        name={2: "TwoMassForce", 3: "ThreeMassForce"}[n],
        description=f"{n}-mass oscillator pantograph excited by the contact force (thesis "
                    "sections 2.6-2.7 in the force-input form of section 4.8)",
        coordinates=tuple(Variable(f"x{i + 1}", "m", f"height of mass {i + 1}") for i in range(n)),
        velocities=tuple(Variable(f"v{i + 1}", "m/s", f"velocity of mass {i + 1}") for i in range(n)),
        inputs=(Variable("F_c", "N", "contact force on the head, positive when the head presses "
                         "up on the wire (it acts downward on the head)", DEFAULTS[n]["F_0"]),
                Variable("p", "bar", "bellow pressure", 0.0)),
        outputs=(Variable("y_cb", "m", "height of the mass under the head (frame)"),
                 Variable("xi", "m", "head height"),
                 Variable("v_cb", "m/s", "velocity of the mass under the head"),
                 Variable("v_head", "m/s", "head velocity")),
        parameters=params, mass_matrix=sp.diag(*[sym[f"m{i + 1}"] for i in range(n)]),
        forces=sp.Matrix(forces),
        output_expressions=sp.Matrix([x[-2], x[-1], v[-2], v[-1]]),
        energy=kinetic + potential - uplift * x[0] + f_c * x[-1],
    )
