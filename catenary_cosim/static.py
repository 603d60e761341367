"""Static pre-state of a catenary: equilibrium under gravity with the designed contact-wire heights.

The dropper lengths are not inputs: they are what a line designer computes so that the contact wire
hangs at its design height (minus the presag) at every dropper. With the contact-wire heights at the
droppers and at the supports prescribed, the dropper forces F and the steady-arm forces R follow
from the contact wire alone (a linear problem with Lagrange multipliers):

    K_C w_C = -W_C + P_C lambda,    P_C^T w_C = t,    lambda = (F, R),

where K_C is the contact wire's finite-difference stiffness, W_C its nodal weights (wire, clamps,
half droppers, steady arms), P_C the shape-function weights at the droppers and supports and t the
prescribed displacements (-presag at the droppers, 0 at the supports). The messenger then carries
its own weight and the dropper forces, held at its support height by the messenger supports:

    K_M w_M = -W_M - N_M F + S_M mu,    S_M^T w_M = 0.

A dropper's unstretched length is the vertical gap between the wires minus its stretch F / k; every
dropper must come out taut (F > 0) with a positive length, or the line is refused. The supports'
preloads (R, mu) are the spring forces in the pre-state; in the dynamics the springs act about it.
The contact wire is held at its design height at the supports (project choice: the steady arm is
adjusted to hold it there, like a dropper).

References
----------
J. Benet et al., "Numerical algorithms for the analysis of initial configuration in a railway
catenary structure and its code implementation: a software tool CALPE", 2015,
doi:10.1155/2015/819165 (dropper lengths from the static equilibrium with prescribed contact-wire
heights).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sparse
from scipy.sparse.linalg import splu

from panto.catenary_cosim.lines import LineDefinition
from panto.catenary_cosim.mesh import Mesh


@dataclass(frozen=True)
class StaticState:
    """Equilibrium of the catenary under gravity (the pre-state of the dynamics).

    Attributes
    ----------
    positions : ndarray
        x of the grid nodes [m].
    contact_wire_heights, messenger_wire_heights : ndarray
        Absolute heights of the two wires at the grid nodes [m].
    dropper_positions : ndarray
        Absolute x of every dropper [m].
    dropper_forces : ndarray
        Dropper tensions [N] (all positive).
    dropper_lengths : ndarray
        Unstretched dropper lengths [m], the quantities a line designer would cut.
    dropper_distances : ndarray
        Vertical gap between the wires at the droppers in the pre-state [m].
    dropper_elongations : ndarray
        Stretch of each dropper in the pre-state, F / k [m].
    steady_arm_forces, messenger_support_forces : ndarray
        Upward preload of each interior support on its wire [N].
    """

    positions: np.ndarray
    contact_wire_heights: np.ndarray
    messenger_wire_heights: np.ndarray
    dropper_positions: np.ndarray
    dropper_forces: np.ndarray
    dropper_lengths: np.ndarray
    dropper_distances: np.ndarray
    dropper_elongations: np.ndarray
    steady_arm_forces: np.ndarray
    messenger_support_forces: np.ndarray


def solve_static_state(line: LineDefinition, mesh: Mesh) -> StaticState:
    """Dropper forces and lengths and both wires' shapes in the pre-state.

    Parameters
    ----------
    line : LineDefinition
    mesh : Mesh
        The finite-difference model of ``line`` (`panto.catenary_cosim.mesh.build_mesh`).

    Returns
    -------
    StaticState

    Raises
    ------
    ValueError
        If a dropper would have to push (F <= 0) or would need a non-positive length.
    """
    droppers = len(mesh.dropper_positions)
    interior = mesh.support_nodes[1:-1] - 1  # node index among the interior nodes
    presag = np.tile(np.asarray(line.dropper_presag, dtype=float), line.spans)
    contact = mesh.interpolation_matrix(mesh.dropper_positions, 0)[:, 0::2]
    messenger = mesh.interpolation_matrix(mesh.dropper_positions, 1)[:, 1::2]
    at_supports = _unit_columns(interior, mesh.unknowns // 2)

    stiffness = mesh.stiffness_structure
    constraints = sparse.hstack([contact.T, at_supports]).tocsc()
    targets = np.concatenate([-presag, np.zeros(len(interior))])
    w_contact, multipliers = _constrained_solve(stiffness[0::2, 0::2], -mesh.weight[0::2],
                                                constraints, targets)
    forces = multipliers[:droppers]
    load = -mesh.weight[1::2] - messenger.T @ forces
    w_messenger, support_forces = _constrained_solve(stiffness[1::2, 1::2], load,
                                                     at_supports.tocsc(), np.zeros(len(interior)))
    distances = line.system_height + messenger @ w_messenger - contact @ w_contact
    elongations = forces / mesh.dropper_stiffness
    lengths = distances - elongations
    _check_droppers(line, mesh.dropper_positions, forces, lengths)
    return StaticState(
        positions=mesh.positions,
        contact_wire_heights=line.contact_wire_height + _with_ends(w_contact),
        messenger_wire_heights=line.contact_wire_height + line.system_height
        + _with_ends(w_messenger),
        dropper_positions=mesh.dropper_positions, dropper_forces=forces, dropper_lengths=lengths,
        dropper_distances=distances, dropper_elongations=elongations,
        steady_arm_forces=multipliers[droppers:], messenger_support_forces=support_forces)


def _constrained_solve(stiffness: sparse.spmatrix, load: np.ndarray, constraints: sparse.spmatrix,
                       targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve K w = load + P lambda with P^T w = targets (Schur complement on the multipliers)."""
    factor = splu(sparse.csc_matrix(stiffness))
    free = factor.solve(load)
    if constraints.shape[1] == 0:
        return free, np.zeros(0)
    columns = factor.solve(constraints.toarray())
    schur = constraints.T @ columns
    multipliers = np.linalg.solve(schur, targets - constraints.T @ free)
    return free + columns @ multipliers, multipliers


def _unit_columns(indices: np.ndarray, size: int) -> sparse.csr_matrix:
    return sparse.csr_matrix((np.ones(len(indices)), (indices, np.arange(len(indices)))),
                             shape=(size, len(indices)))


def _with_ends(interior: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], interior, [0.0]])


def _check_droppers(line: LineDefinition, positions: np.ndarray, forces: np.ndarray,
                    lengths: np.ndarray) -> None:
    slack = np.flatnonzero(forces <= 0.0)
    if slack.size:
        i = slack[0]
        raise ValueError(
            f"{line.source}: the dropper at x = {positions[i]:.3f} m would have to push "
            f"(force {forces[i]:.3g} N) to hold the contact wire at its design height; "
            "check dropper_positions and dropper_presag")
    short = np.flatnonzero(lengths <= 0.0)
    if short.size:
        i = short[0]
        raise ValueError(
            f"{line.source}: the dropper at x = {positions[i]:.3f} m would need a length of "
            f"{lengths[i]:.3g} m; check system_height and dropper_presag")
