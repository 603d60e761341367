"""Finite-difference mesh of a simple catenary: node grid, mass and stiffness matrices, droppers.

Both wires are Euler-Bernoulli beams under tension on the same uniform grid x_j = j h,
j = 0..N (x = 0 at the first support),

    rho A w_tt = T w_xx - EI w_xxxx - rho A g + q(x, t),

discretised with the central differences w_xx ~ (w_{j-1} - 2 w_j + w_{j+1}) / h^2 and
w_xxxx ~ (w_{j-2} - 4 w_{j-1} + 6 w_j - 4 w_{j+1} + w_{j+2}) / h^4 and multiplied by h, so that
the matrices are in N/m and kg and the mass is lumped (rho A h per node). The ends j = 0 and j = N
are pinned: w = 0 and w_xx = 0 (ghost node w_{-1} = -w_1), which keeps the stiffness matrix
symmetric positive definite and second-order accurate.

The unknowns are the interior nodes of both wires, interleaved node by node (contact wire node j at
index 2 (j - 1), messenger node j at 2 (j - 1) + 1), so that the fourth difference and the droppers
couple indices at most 4 apart: every matrix is banded with half-bandwidth 4.

Point items (droppers, their clamps, the contact point) that fall between nodes act through the
linear shape functions N_j = 1 - xi, N_{j+1} = xi with xi = x / h - j: a displacement is
interpolated with them and a force or a mass is shared with the same weights (consistent in the
sense of virtual work).

References
----------
K. F. Graff, *Wave Motion in Elastic Solids*, Dover 1991 (strings and beams under tension).
M. Arnold, B. Simeon, "Pantograph and catenary dynamics: a benchmark problem and its numerical
solution", *Applied Numerical Mathematics* 34 (2000) 345-362 (wires as tensioned beams, droppers
as springs between them).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sparse

from panto.catenary_cosim.lines import LineDefinition

GRAVITY = 9.81  # [m/s^2]
HALF_BANDWIDTH = 4


@dataclass(frozen=True)
class Mesh:
    """Node grid and assembled matrices of one catenary.

    Attributes
    ----------
    element_length : float
        Node spacing h [m] (the requested value rounded so that every span holds a whole number of
        elements).
    positions : ndarray
        x of the grid nodes j = 0..N [m].
    unknowns : int
        Number of unknowns n = 2 (N - 1).
    support_nodes : ndarray of int
        Grid index of every support, the two pinned ends included.
    stiffness_structure : csr_matrix
        Tension, bending and support springs (n x n) [N/m]; droppers excluded.
    mass : ndarray
        Lumped mass per unknown [kg] (wire, clamps, half dropper, steady arm, messenger support).
    dropper_positions : ndarray
        Absolute x of every dropper [m].
    dropper_matrix : csr_matrix
        B (droppers x n): dropper elongation increment = B u (messenger up, contact wire down).
    dropper_stiffness : ndarray
        Axial stiffness of each dropper [N/m].
    """

    element_length: float
    positions: np.ndarray
    unknowns: int
    support_nodes: np.ndarray
    stiffness_structure: sparse.csr_matrix
    mass: np.ndarray
    dropper_positions: np.ndarray
    dropper_matrix: sparse.csr_matrix
    dropper_stiffness: np.ndarray

    @property
    def elements(self) -> int:
        """Number of elements N."""
        return len(self.positions) - 1

    @property
    def weight(self) -> np.ndarray:
        """Gravity force per unknown [N] (downward, positive)."""
        return self.mass * GRAVITY

    def stiffness_linear(self) -> sparse.csr_matrix:
        """Structure plus all droppers taut: K = K_s + B^T diag(k) B [N/m]."""
        b = self.dropper_matrix
        return (self.stiffness_structure + b.T @ sparse.diags(self.dropper_stiffness) @ b).tocsr()

    def locate(self, x: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Element index j and local coordinate xi in [0, 1] of the points x (clipped to the line)."""
        s = np.asarray(x, dtype=float) / self.element_length
        j = np.clip(np.floor(s).astype(int), 0, self.elements - 1)
        return j, s - j

    def interpolation_matrix(self, x: np.ndarray, wire: int) -> sparse.csr_matrix:
        """Rows of shape-function weights (len(x) x n) for points on a wire (0 contact, 1 messenger).

        Weights on the pinned end nodes are dropped: those nodes do not move.
        """
        j, xi = self.locate(np.atleast_1d(x))
        rows = np.repeat(np.arange(len(j)), 2)
        nodes = np.column_stack([j, j + 1]).ravel()
        weights = np.column_stack([1.0 - xi, xi]).ravel()
        keep = (nodes > 0) & (nodes < self.elements)
        columns = 2 * (nodes[keep] - 1) + wire
        return sparse.csr_matrix((weights[keep], (rows[keep], columns)),
                                 shape=(len(j), self.unknowns))


def build_mesh(line: LineDefinition, element_length: float,
               dropper_lengths: np.ndarray | None = None) -> Mesh:
    """Assemble the finite-difference model of ``line``.

    Parameters
    ----------
    line : LineDefinition
    element_length : float
        Requested node spacing [m]; rounded so that each span has a whole number of elements
        (at least 2).
    dropper_lengths : ndarray, optional
        Length of every dropper [m], used for its own mass (lumped half to each end); the system
        height minus the presag is used when not given.

    Returns
    -------
    Mesh
    """
    if not (np.isfinite(element_length) and element_length > 0.0):
        raise ValueError(f"element_length = {element_length!r} must be a positive number of metres")
    per_span = max(2, int(round(line.span_length / element_length)))
    h = line.span_length / per_span
    elements = per_span * line.spans
    if elements < 2:
        raise ValueError(f"{line.source}: the line needs at least two elements")
    positions = h * np.arange(elements + 1)
    unknowns = 2 * (elements - 1)
    support_nodes = per_span * np.arange(line.spans + 1)
    dropper_positions = (line.span_length * np.arange(line.spans)[:, None]
                         + np.asarray(line.dropper_positions)[None, :]).ravel()
    if dropper_lengths is None:
        presag = np.tile(np.asarray(line.dropper_presag, dtype=float), line.spans)
        dropper_lengths = line.system_height - presag
    skeleton = Mesh(h, positions, unknowns, support_nodes, sparse.csr_matrix((unknowns, unknowns)),
                    np.zeros(unknowns), dropper_positions, sparse.csr_matrix((0, unknowns)),
                    np.zeros(0))
    contact_at_droppers = skeleton.interpolation_matrix(dropper_positions, 0)
    messenger_at_droppers = skeleton.interpolation_matrix(dropper_positions, 1)
    dropper_matrix = (messenger_at_droppers - contact_at_droppers).tocsr()
    stiffness = (_wire_matrix(line.contact_wire.tension, line.contact_wire.bending_stiffness, h,
                              elements, 0)
                 + _wire_matrix(line.messenger_wire.tension, line.messenger_wire.bending_stiffness,
                                h, elements, 1))
    springs, mass = _point_items(line, skeleton, contact_at_droppers, messenger_at_droppers,
                                 np.asarray(dropper_lengths, dtype=float))
    mass[0::2] += line.contact_wire.mass_per_length * h
    mass[1::2] += line.messenger_wire.mass_per_length * h
    structure = (stiffness + sparse.diags(springs)).tocsr()
    return Mesh(h, positions, unknowns, support_nodes, structure, mass, dropper_positions,
                dropper_matrix, np.full(len(dropper_positions), line.dropper_stiffness))


def _wire_matrix(tension: float, bending: float, h: float, elements: int,
                 wire: int) -> sparse.csr_matrix:
    """h (T D2 + EI D4) of one pinned-pinned wire, placed at the interleaved indices of ``wire``."""
    m = elements - 1
    main = np.full(m, 2.0 * tension / h + 6.0 * bending / h**3)
    main[[0, -1]] -= bending / h**3  # ghost node w_{-1} = -w_1 at a pinned end
    first = np.full(m - 1, -tension / h - 4.0 * bending / h**3)
    second = np.full(max(m - 2, 0), bending / h**3)
    block = sparse.diags([main, first, first, second, second], [0, 1, -1, 2, -2], shape=(m, m))
    select = np.zeros((2, 2))
    select[wire, wire] = 1.0
    return sparse.kron(block, select, format="csr")


def _point_items(line: LineDefinition, mesh: Mesh, contact_at_droppers: sparse.csr_matrix,
                 messenger_at_droppers: sparse.csr_matrix,
                 dropper_lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Support springs and the lumped masses of clamps, droppers and supports per unknown."""
    springs = np.zeros(mesh.unknowns)
    mass = np.zeros(mesh.unknowns)
    interior = mesh.support_nodes[1:-1]
    springs[2 * (interior - 1)] += line.steady_arm_stiffness
    springs[2 * (interior - 1) + 1] += line.messenger_support_stiffness
    mass[2 * (interior - 1)] += line.steady_arm_mass
    mass[2 * (interior - 1) + 1] += line.messenger_support_mass
    half_dropper = 0.5 * line.dropper_mass_per_length * dropper_lengths
    mass += contact_at_droppers.T @ (line.dropper_clamp_mass_contact + half_dropper)
    mass += messenger_at_droppers.T @ (line.dropper_clamp_mass_messenger + half_dropper)
    return springs, mass


def banded_upper(matrix: sparse.spmatrix, bandwidth: int = HALF_BANDWIDTH) -> np.ndarray:
    """Upper band storage (LAPACK ``?pbtrf`` layout) of a symmetric sparse matrix."""
    upper = sparse.triu(matrix, format="coo")
    offsets = upper.col - upper.row
    if offsets.size and offsets.max() > bandwidth:
        raise ValueError(f"matrix half-bandwidth {offsets.max()} exceeds {bandwidth}")
    band = np.zeros((bandwidth + 1, matrix.shape[0]))
    np.add.at(band, (bandwidth - offsets, upper.col), upper.data)
    return band
