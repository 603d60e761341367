"""The physically based pantograph model of thesis chapter 2 (extended model of section 2.5).

Four-bar substitute linkage (lower arm l1, upper arm with short lever l2 and long arm l4, flexible
thrust rod l3 + delta) in the closed-form Freudenstein solution, a collector head m_c on the
suspension k_c/c_c above the cross bar, a carbon-contact spring k_ph to the input eta and the
bellow torque k_p p on phi1. Conventions: ``reference/pantograph_model.md``.

Generalised coordinates q = (phi1, delta, xi); the equations of motion follow from the Lagrangian
(2.22) with Rayleigh dissipation (2.24, damper names of section 4.5) via the Euler-Lagrange
equations (2.23), derived here with SymPy (the thesis used Maple).

Three extensions, all zero by default so that the defaults are the thesis model: Coulomb friction in
the lower-arm hinge (``T_f``), an angle-dependent bellow torque (``kappa_p``) and a cubic stiffening of
the head suspension (``k_c3``). The virtual test bed uses them as rig imperfections and the diagnosis
as candidate effects.
"""
from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from math import pi

import sympy as sp

from panto.fmu_src.spec import ParameterSpec, Variable
from panto.fmu_src.symbolic import Dependent, Guard, MechanicalModel, lagrangian_forces, total_derivative

_T21 = "thesis Table 2.1 (dimensions of the test pantograph)"
_T41 = "thesis Table 4.1 (identified, section 4.5)"
_DEFAULT = "reference/pantograph_model.md default (not given by the thesis)"
_EXTENSION = ("project extension for rig imperfections and diagnosis candidates; "
              "0 reproduces the thesis model")

PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec("l1", 1.600, "m", "lower arm length", 1e-3, 20.0, _T21),
    ParameterSpec("l2", 0.314, "m", "upper arm short lever length", 1e-3, 20.0, _T21),
    ParameterSpec("l3", 1.182, "m", "thrust rod nominal length", 1e-3, 20.0, _T21),
    ParameterSpec("l4", 1.910, "m", "upper arm length (elbow to cross bar)", 1e-3, 20.0, _T21),
    ParameterSpec("c", 0.720, "m", "horizontal offset of the thrust rod's frame hinge", -20.0, 20.0, _T21),
    ParameterSpec("d", 0.150, "m", "vertical offset of the thrust rod's frame hinge (below)", -20.0, 20.0, _T21),
    ParameterSpec("alpha", 0.0, "rad", "angle between short lever and upper arm", -pi, pi, _DEFAULT),
    ParameterSpec("s1", 0.800, "m", "centroid of lower arm from frame hinge", 0.0, 20.0, _DEFAULT + ": l1/2"),
    ParameterSpec("s2", 0.157, "m", "centroid of short lever from elbow", 0.0, 20.0, _DEFAULT + ": l2/2"),
    ParameterSpec("s3", 0.591, "m", "centroid of thrust rod from frame hinge", 0.0, 20.0, _DEFAULT + ": l3/2"),
    ParameterSpec("s4", 0.955, "m", "centroid of upper arm from elbow", 0.0, 20.0, _DEFAULT + ": l4/2"),
    ParameterSpec("g", 9.81, "m/s2", "gravitational acceleration", 0.0, 30.0, _DEFAULT),
    ParameterSpec("m1", 22.1, "kg", "lower arm mass", 1e-6, 1e4, _T41),
    ParameterSpec("m2", 4.5, "kg", "short lever mass", 1e-6, 1e4, _T41),
    ParameterSpec("m3", 6.7, "kg", "thrust rod mass", 1e-6, 1e4, _T41),
    ParameterSpec("m4", 21.1, "kg", "upper arm mass", 1e-6, 1e4, _T41),
    ParameterSpec("m_c", 6.0, "kg", "collector head mass", 1e-6, 1e4, _T41),
    ParameterSpec("c1", 277.7, "N.m.s/rad", "damping on dphi1", 0.0, 1e7, _T41),
    ParameterSpec("c2", 329.4, "N.s/m", "damping on ddelta (thrust rod)", 0.0, 1e9, _T41),
    ParameterSpec("c3", 1082.8, "N.m.s/rad", "damping on dphi2", 0.0, 1e7, _T41),
    ParameterSpec("c_c", 65.8, "N.s/m", "collector head suspension damping", 0.0, 1e7, _T41),
    ParameterSpec("k", 1399423.0, "N/m", "thrust rod axial stiffness", 1.0, 1e12, _T41),
    ParameterSpec("k_c", 21073.0, "N/m", "collector head suspension stiffness", 1e-3, 1e10, _T41),
    ParameterSpec("k_ph", 11931.0, "N/m", "carbon contact stiffness (EN 50318: 50000)", 0.0, 1e10, _T41),
    ParameterSpec("k_p", 260.0, "N.m/bar", "bellow torque per pressure", 0.0, 1e6, _T41 + " (text)"),
    ParameterSpec("T_f", 0.0, "N.m", "Coulomb friction torque in the lower-arm hinge, T_f tanh(dphi1/omega_eps)",
                  0.0, 1e5, _EXTENSION),
    ParameterSpec("omega_eps", 1e-3, "rad/s", "angular velocity scale of the tanh-smoothed hinge friction",
                  1e-9, 10.0, _EXTENSION),
    ParameterSpec("kappa_p", 0.0, "1/rad", "angle dependence of the bellow torque, "
                  "k_p p (1 + kappa_p (phi1 - phi1_ref))", -100.0, 100.0, _EXTENSION),
    ParameterSpec("phi1_ref", 0.532, "rad", "lower-arm angle at which the bellow torque is k_p p",
                  -pi, pi, _EXTENSION),
    ParameterSpec("k_c3", 0.0, "N/m3", "cubic stiffening of the head suspension, k_c3 (xi - y_cb)^3",
                  -1e12, 1e12, _EXTENSION),
    ParameterSpec(
        "unilateral_contact", 0.0, "1",
        "contact can only push (contact loss when xi < eta); thesis model is bilateral",
        0.0, 1.0, "project choice (reference/pantograph_model.md)", boolean=True,
    ),
)

COORDINATES = (
    Variable("phi1", "rad", "lower arm angle from the horizontal", 0.532),
    Variable("delta", "m", "elastic length change of the thrust rod", 0.0),
    Variable("xi", "m", "collector head height (absolute)", 2.0),
)
VELOCITIES = (
    Variable("dphi1", "rad/s", "lower arm angular velocity", 0.0),
    Variable("ddelta", "m/s", "thrust rod elongation rate", 0.0),
    Variable("dxi", "m/s", "collector head velocity", 0.0),
)
INPUTS = (
    Variable("eta", "m", "contact wire / linear motor height", 2.0),
    Variable("p", "bar", "bellow pressure", 4.0),
)
OUTPUTS = (
    Variable("y_cb", "m", "cross bar height"),
    Variable("xi", "m", "collector head height"),
    Variable("F_c", "N", "contact force, positive when the head presses up on the wire"),
)

#: Lower and upper bound [rad] of phi1 searched for the initial equilibrium guess.
PHI1_SEARCH_RANGE = (0.0, 1.35)


def _symbols(names: str) -> list[sp.Symbol]:
    return list(sp.symbols(names, real=True))


@lru_cache(maxsize=1)
def linkage() -> dict:
    """Closed-form kinematics of the four-bar linkage with the flexible thrust rod.

    Returns a dict of SymPy expressions and symbols: ``phi2``, ``phi3`` (symbols of the dependent
    angles), ``phi2_expr``, ``phi3_expr`` (Freudenstein solution, eqs. 2.3-2.12 with
    l3 -> l3 + delta), ``discriminant`` (k1^2 + k2^2 - k3^2 >= 0 for the linkage to close),
    ``S2``, ``D2``, ``S3``, ``D3`` (eqs. 2.17-2.18), ``y_cb``, ``x_cb`` (eqs. 2.13-2.14).
    """
    phi1, delta = _symbols("phi1 delta")
    l1, l2, l3, l4, c, d, alpha = _symbols("l1 l2 l3 l4 c d alpha")
    phi2, phi3 = _symbols("phi2 phi3")
    L3 = l3 + delta
    k1 = -2 * l2 * (l1 * sp.sin(phi1) + d)  # (2.4)
    k2 = 2 * l2 * (l1 * sp.cos(phi1) - c)  # (2.5)
    k3 = (l1**2 + l2**2 - L3**2 + c**2 + d**2
          + 2 * d * l1 * sp.sin(phi1) - 2 * c * l1 * sp.cos(phi1))  # (2.6)
    discriminant = k1**2 + k2**2 - k3**2
    # (2.11), working branch (the '-' root), written with atan2 so that k3 = k2 is harmless.
    phi2_expr = 2 * sp.atan2(-k1 - sp.sqrt(discriminant), k3 - k2)
    # (2.12) with the rod at angle phi3 from frame point C = (-c, -d).
    phi3_expr = sp.atan2(l1 * sp.sin(phi1) - l2 * sp.sin(phi2) + d,
                         l1 * sp.cos(phi1) + l2 * sp.cos(phi2) - c)
    s23 = sp.sin(phi2 + phi3)
    return {
        "phi1": phi1, "delta": delta, "phi2": phi2, "phi3": phi3,
        "phi2_expr": phi2_expr, "phi3_expr": phi3_expr, "discriminant": discriminant,
        "S2": l1 * sp.sin(phi3 - phi1) / (l2 * s23),  # (2.17)
        "D2": -1 / (l2 * s23),
        "S3": l1 * sp.sin(phi1 + phi2) / (L3 * s23),  # (2.18)
        "D3": sp.cos(phi2 + phi3) / (L3 * s23),
        "y_cb": l1 * sp.sin(phi1) + l4 * sp.sin(phi2 - alpha),  # (2.14)
        "x_cb": -l1 * sp.cos(phi1) + l4 * sp.cos(phi2 - alpha),  # (2.13)
    }


def _centroids(kin: dict) -> list[tuple[sp.Expr, sp.Expr, sp.Expr]]:
    """(x, y, rotation angle) of each bar's centroid (reference page conventions)."""
    phi1, phi2, phi3 = kin["phi1"], kin["phi2"], kin["phi3"]
    l1, c, d, alpha = _symbols("l1 c d alpha")
    s1, s2, s3, s4 = _symbols("s1 s2 s3 s4")
    ax, ay = -l1 * sp.cos(phi1), l1 * sp.sin(phi1)  # elbow A
    return [
        (-s1 * sp.cos(phi1), s1 * sp.sin(phi1), phi1),  # lower arm
        (ax - s2 * sp.cos(phi2), ay - s2 * sp.sin(phi2), phi2),  # short lever
        (-c - s3 * sp.cos(phi3), -d + s3 * sp.sin(phi3), phi3),  # thrust rod
        (ax + s4 * sp.cos(phi2 - alpha), ay + s4 * sp.sin(phi2 - alpha), phi2),  # upper arm
    ]


def _linkage_guard(kin: dict) -> Guard:
    """The closure check of the four-bar linkage (both excitation forms)."""
    return Guard(kin["discriminant"], "the linkage cannot close at phi1 = {phi1} rad, delta = "
                 "{delta} m (thrust rod and arms out of reach)")


@lru_cache(maxsize=1)
def derive_pantograph() -> MechanicalModel:
    """Derive the equations of motion of the extended pantograph model (section 2.5).

    Returns
    -------
    MechanicalModel
        ``M(q) dv/dt = r(q, v, u)`` with q = (phi1, delta, xi), u = (eta, p) and outputs
        (y_cb, xi, F_c).
    """
    kin = linkage()
    phi1, delta, phi2, phi3 = kin["phi1"], kin["delta"], kin["phi2"], kin["phi3"]
    xi, dphi1, ddelta, dxi = _symbols("xi dphi1 ddelta dxi")
    q, v = [phi1, delta, xi], [dphi1, ddelta, dxi]
    dependents = (
        Dependent(phi2, kin["phi2_expr"], {phi1: kin["S2"], delta: kin["D2"]}),
        Dependent(phi3, kin["phi3_expr"], {phi1: kin["S3"], delta: kin["D3"]}),
    )

    def d(expression: sp.Expr, coordinate: sp.Symbol) -> sp.Expr:
        return total_derivative(expression, coordinate, dependents)

    mass, potential = _mass_matrix_and_gravity(kin, q, d)
    forces, contact, energy = _forces_and_energy(kin, q, v, mass, potential, d)
    return _pantograph_model(kin, mass, forces, contact, energy, dependents)


def _mass_matrix_and_gravity(kin: dict, q: list[sp.Symbol],
                             d: Callable[[sp.Expr, sp.Symbol], sp.Expr],
                             ) -> tuple[sp.Matrix, sp.Expr]:
    """Mass matrix of the kinetic energy (2.22) and the potential of gravity."""
    xi = q[2]
    m = _symbols("m1 m2 m3 m4")
    m_c, g = _symbols("m_c g")
    lengths = _symbols("l1 l2 l3 l4")
    # Kinetic energy (2.22): T = 1/2 v^T M v with M = sum m J^T J + I w^T w (+ m_c for xi).
    mass = sp.zeros(3, 3)
    potential = m_c * g * xi
    for (x, y, angle), mi, li in zip(_centroids(kin), m, lengths):
        jac = sp.Matrix([[d(x, qk) for qk in q], [d(y, qk) for qk in q]])
        w = sp.Matrix([[d(angle, qk) for qk in q]])
        mass += mi * jac.T * jac + (mi * li**2 / 12) * w.T * w  # (2.21)
        potential += mi * g * y
    mass[2, 2] += m_c
    return mass.applyfunc(sp.expand), potential  # simple trigonometric polynomials in S2, S3, ...


def _forces_and_energy(kin: dict, q: list[sp.Symbol], v: list[sp.Symbol], mass: sp.Matrix,
                       potential: sp.Expr, d: Callable[[sp.Expr, sp.Symbol], sp.Expr],
                       ) -> tuple[sp.Matrix, sp.Expr, sp.Expr]:
    """Right-hand side of the Euler-Lagrange equations (2.23), the contact force and the energy."""
    (phi1, delta, xi), (dphi1, ddelta, dxi) = q, v
    eta, p, k, k_c, k_ph, k_p = _symbols("eta p k k_c k_ph k_p")
    c1, c2, c3, c_c, unilateral = _symbols("c1 c2 c3 c_c unilateral_contact")
    t_f, omega_eps, kappa_p, phi1_ref, k_c3 = _symbols("T_f omega_eps kappa_p phi1_ref k_c3")
    y_cb = kin["y_cb"]
    dy_cb = sum(d(y_cb, qk) * vk for qk, vk in zip(q, v))
    dphi2 = sum(d(kin["phi2"], qk) * vk for qk, vk in zip(q, v))
    stroke = xi - y_cb  # head suspension deflection
    potential += k * delta**2 / 2 + k_c * stroke**2 / 2 + k_c3 * stroke**4 / 4
    rayleigh = (c1 * dphi1**2 + c2 * ddelta**2 + c3 * dphi2**2 + c_c * (dxi - dy_cb) ** 2) / 2
    spring = k_ph * (xi - eta)
    contact = sp.Piecewise((0, sp.And(unilateral > sp.Rational(1, 2), xi < eta)), (spring, True))
    # Bellow torque on phi1 (optionally angle dependent), hinge friction, contact on xi.
    bellow = k_p * p * (1 + kappa_p * (phi1 - phi1_ref))
    friction = t_f * sp.tanh(dphi1 / omega_eps)
    external = sp.Matrix([bellow - friction, 0, -contact])
    generalised = sp.Matrix(
        [-d(potential, qk) - sp.diff(rayleigh, vk) for qk, vk in zip(q, v)]
    ) + external
    mass_derivative = [mass.applyfunc(lambda e, qk=qk: d(e, qk)) for qk in q]
    forces = lagrangian_forces(mass, generalised, v, mass_derivative)

    kinetic = (sp.Matrix(v).T * mass * sp.Matrix(v))[0, 0] / 2
    bellow_work = k_p * p * (phi1 + kappa_p * (phi1 - phi1_ref) ** 2 / 2)  # integral of the torque
    energy = kinetic + potential + k_ph * (xi - eta) ** 2 / 2 - bellow_work
    return forces, contact, energy


def _pantograph_model(kin: dict, mass: sp.Matrix, forces: sp.Matrix, contact: sp.Expr,
                      energy: sp.Expr, dependents: tuple[Dependent, ...]) -> MechanicalModel:
    """The derived equations as a :class:`MechanicalModel` with its outputs, guard and start."""
    y_cb, xi, eta = kin["y_cb"], *_symbols("xi eta")
    return MechanicalModel(
        name="Pantograph",
        description="Physically based high-speed pantograph (four-bar linkage, flexible thrust "
                    "rod, collector head, bellow torque, carbon contact)",
        coordinates=COORDINATES, velocities=VELOCITIES, inputs=INPUTS, outputs=OUTPUTS,
        parameters=PARAMETERS, mass_matrix=mass, forces=forces,
        output_expressions=sp.Matrix([y_cb, xi, contact]),
        dependents=dependents,
        guards=(_linkage_guard(kin),),
        energy=energy,
        extra={
            "y_cb": y_cb, "x_cb": kin["x_cb"], "linkage": kin,
            # Start the equilibrium solve with the cross bar at the wire and the head on it.
            "initial_guess": {"values": {"delta": 0, "xi": eta},
                              "bisect": ("phi1", y_cb, eta, *PHI1_SEARCH_RANGE)},
        },
    )


# --- force excitation (thesis Fig. 2.6, sections 2.3 and 4.4) --------------------------------

#: Parameters of the force-excited pantograph: those of the displacement-excited model without
#: the carbon contact (k_ph, unilateral_contact) and the bellow's pressure law (k_p, kappa_p,
#: phi1_ref): the bellow torque is an input.
FORCE_PARAMETERS: tuple[ParameterSpec, ...] = tuple(
    spec for spec in PARAMETERS
    if spec.name not in ("k_ph", "unilateral_contact", "k_p", "kappa_p", "phi1_ref"))

FORCE_INPUTS = (
    Variable("M_b", "N.m", "bellow torque on the lower arm (thesis Fig. 2.6 and eq. 2.26: M); "
             "start: 4 bar at the Table 4.1 gain k_p = 260 N m/bar", 1040.0),
    Variable("F_c", "N", "contact force on the head, positive when the head presses up on the "
             "wire (it acts downward on the head; thesis Fig. 2.6: F)", 80.0),
)
FORCE_OUTPUTS = (
    Variable("y_cb", "m", "cross bar height"),
    Variable("xi", "m", "collector head height"),
    Variable("v_cb", "m/s", "cross bar velocity"),
    Variable("v_head", "m/s", "collector head velocity"),
)


@lru_cache(maxsize=1)
def derive_pantograph_force() -> MechanicalModel:
    """Derive the force-excited pantograph of thesis Fig. 2.6 (sections 2.3 and 4.4).

    The model of :func:`derive_pantograph` without the carbon-contact spring: the bellow torque
    ``M_b`` [N m] acts on phi1 and the contact force ``F_c`` [N] pushes the head down (section
    4.8: "removing the contact spring and adding an input force"). Nothing holds the linkage at a
    height but the balance of ``M_b`` against the weight and ``F_c``; the static torque that
    balances them falls as the pantograph rises, so the equilibrium is unstable (one small
    positive eigenvalue, the slow rise or fall the thesis reports in section 4.4).

    Returns
    -------
    MechanicalModel
        ``M(q) dv/dt = r(q, v, u)`` with q = (phi1, delta, xi), u = (M_b, F_c) and outputs
        (y_cb, xi, v_cb, v_head).
    """
    kin = linkage()
    phi1, delta = kin["phi1"], kin["delta"]
    xi, dphi1, ddelta, dxi = _symbols("xi dphi1 ddelta dxi")
    q, v = [phi1, delta, xi], [dphi1, ddelta, dxi]
    dependents = (
        Dependent(kin["phi2"], kin["phi2_expr"], {phi1: kin["S2"], delta: kin["D2"]}),
        Dependent(kin["phi3"], kin["phi3_expr"], {phi1: kin["S3"], delta: kin["D3"]}),
    )

    def d(expression: sp.Expr, coordinate: sp.Symbol) -> sp.Expr:
        return total_derivative(expression, coordinate, dependents)

    mass, gravity = _mass_matrix_and_gravity(kin, q, d)
    forces, energy, velocity_cb = _force_input_forces(kin, q, v, mass, gravity, d)
    m_c, g, f_c = _symbols("m_c g F_c")
    # Static torque that holds the linkage at phi1 (delta = 0): the bars' weight plus the head's
    # weight and the contact force passed on through the suspension (eq. 2.23 at rest).
    arms = gravity - m_c * g * xi
    holding = d(arms, phi1) + (m_c * g + f_c) * d(kin["y_cb"], phi1)
    return MechanicalModel(
        name="PantographForce",
        description="Physically based high-speed pantograph excited by force (thesis Fig. 2.6): "
                    "bellow torque on the lower arm and contact force on the head as inputs, "
                    "no contact spring",
        coordinates=COORDINATES, velocities=VELOCITIES, inputs=FORCE_INPUTS,
        outputs=FORCE_OUTPUTS, parameters=FORCE_PARAMETERS, mass_matrix=mass, forces=forces,
        output_expressions=sp.Matrix([kin["y_cb"], xi, velocity_cb, dxi]),
        dependents=dependents,
        guards=(_linkage_guard(kin),),
        energy=energy,
        extra={
            "y_cb": kin["y_cb"], "x_cb": kin["x_cb"], "linkage": kin, "holding_torque": holding,
            # Start the equilibrium solve where the holding torque equals the bellow torque.
            "initial_guess": {"values": {"delta": 0, "xi": 0},
                              "bisect": ("phi1", holding, sp.Symbol("M_b", real=True),
                                         *PHI1_SEARCH_RANGE)},
        },
    )


def _force_input_forces(kin: dict, q: list[sp.Symbol], v: list[sp.Symbol], mass: sp.Matrix,
                        potential: sp.Expr, d: Callable[[sp.Expr, sp.Symbol], sp.Expr],
                        ) -> tuple[sp.Matrix, sp.Expr, sp.Expr]:
    """Right-hand side (2.23) of the force-excited model, its energy and the cross-bar velocity."""
    (phi1, delta, xi), (dphi1, ddelta, dxi) = q, v
    k, k_c, k_c3, t_f, omega_eps = _symbols("k k_c k_c3 T_f omega_eps")
    c1, c2, c3, c_c, m_b, f_c = _symbols("c1 c2 c3 c_c M_b F_c")
    dy_cb = sum(d(kin["y_cb"], qk) * vk for qk, vk in zip(q, v))
    dphi2 = sum(d(kin["phi2"], qk) * vk for qk, vk in zip(q, v))
    stroke = xi - kin["y_cb"]
    potential += k * delta**2 / 2 + k_c * stroke**2 / 2 + k_c3 * stroke**4 / 4
    rayleigh = (c1 * dphi1**2 + c2 * ddelta**2 + c3 * dphi2**2 + c_c * (dxi - dy_cb) ** 2) / 2
    external = sp.Matrix([m_b - t_f * sp.tanh(dphi1 / omega_eps), 0, -f_c])
    generalised = sp.Matrix(
        [-d(potential, qk) - sp.diff(rayleigh, vk) for qk, vk in zip(q, v)]) + external
    mass_derivative = [mass.applyfunc(lambda e, qk=qk: d(e, qk)) for qk in q]
    forces = lagrangian_forces(mass, generalised, v, mass_derivative)
    kinetic = (sp.Matrix(v).T * mass * sp.Matrix(v))[0, 0] / 2
    energy = kinetic + potential - m_b * phi1 + f_c * xi  # work potential of constant inputs
    return forces, energy, dy_cb
