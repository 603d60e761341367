"""Implicit time integration of the catenary with tension-only droppers, factorised once.

Equations of motion about the static pre-state (u = 0):

    M u'' + C u' + K u + sum_d k_d max(-e_d, 0) b_d = f(t),    e_d = e0_d + b_d . u,

where K = K_s + sum_d k_d b_d b_d^T is the stiffness with every dropper taut, e_d the stretch of
dropper d (e0_d > 0 in the pre-state) and the sum removes the force of a slack dropper: a dropper
carries k_d max(e_d, 0) >= 0, never compression. Damping is Rayleigh, C = alpha M + beta K_s, on
the structure only, so that a slack dropper transmits no damping force either.

Integrator: Newmark's average-acceleration rule (beta = 1/4, gamma = 1/2), chosen because it is
unconditionally stable, second-order accurate and adds no numerical damping: for a linear system
without load it conserves the discrete energy exactly, which the energy test checks, and the only
dissipation in the line is the physical Rayleigh damping (HHT-alpha would add algorithmic damping
that changes the contact-force statistics). Each step solves

    (K + 2/dt C + 4/dt^2 M) u_{n+1} + sum_{d slack} (...) = f_{n+1} + M (4/dt^2 u_n + 4/dt v_n + a_n)
                                                           + C (2/dt u_n + v_n).

The matrix A = K + 2/dt C + 4/dt^2 M is constant: it is Cholesky-factorised once in band storage
(LAPACK ``dpbtrf``, half-bandwidth 4). Slack droppers are handled exactly by an active-set iteration
on the small set S of slack droppers, using the Woodbury identity with Z = A^{-1} B^T and
G = B A^{-1} B^T computed once; a step in which no dropper is slack costs one banded solve. In the
droppers' coordinates the slack condition is a linear complementarity problem with the positive
definite matrix diag(1/k) - G (positive definite because A without the slack droppers still is),
so its solution is unique; block pivoting (flip every violated dropper) usually finds it in one
or two passes, and Murty's least-index rule, which is finite for such matrices, takes over if
block pivoting has not settled after a few passes.

References
----------
N. M. Newmark, "A method of computation for structural dynamics", *J. Eng. Mech. Div. ASCE* 85
(1959) 67-94.
T. J. R. Hughes, *The Finite Element Method*, Dover 2000, ch. 9 (energy of the trapezoidal rule).
W. W. Hager, "Updating the inverse of a matrix", *SIAM Review* 31 (1989) 221-239 (Woodbury).
K. G. Murty, *Linear Complementarity, Linear and Nonlinear Programming*, Heldermann 1988, ch. 4
(principal pivoting, least-index rule).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sparse
from scipy.linalg import lapack

from panto.catenary_cosim.mesh import Mesh, banded_upper

BLOCK_PIVOTING_ITERATIONS = 20
MAX_ACTIVE_SET_ITERATIONS = 2000


class BandedCholesky:
    """Cholesky factor of a symmetric positive definite banded matrix (LAPACK ``dpbtrf``)."""

    def __init__(self, matrix: sparse.spmatrix):
        factor, info = lapack.dpbtrf(banded_upper(matrix), lower=0)
        if info != 0:
            raise RuntimeError(f"dpbtrf: matrix is not positive definite (info = {info})")
        self._factor = factor

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^{-1} rhs for a vector or a matrix of right-hand sides (columns)."""
        solution, info = lapack.dpbtrs(self._factor, rhs, lower=0)
        if info != 0:
            raise RuntimeError(f"dpbtrs failed (info = {info})")
        return solution


class SlackDropperSolver:
    """Solve A u + sum_d k_d max(-e_d, 0) b_d = rhs with e = e0 + B u (tension-only droppers).

    Parameters
    ----------
    matrix : sparse matrix
        A, symmetric positive definite with every dropper taut (``K`` or the Newmark matrix).
    dropper_matrix : csr_matrix
        B (droppers x n).
    stiffness, elongations : ndarray
        k_d [N/m] and the pre-state stretch e0_d [m] of the droppers.
    """

    def __init__(self, matrix: sparse.spmatrix, dropper_matrix: sparse.csr_matrix,
                 stiffness: np.ndarray, elongations: np.ndarray):
        self.factor = BandedCholesky(matrix)
        self.dropper_matrix = dropper_matrix
        self.stiffness = np.asarray(stiffness, dtype=float)
        self.elongations = np.asarray(elongations, dtype=float)
        if dropper_matrix.shape[0]:
            self._z = self.factor.solve(np.asfortranarray(dropper_matrix.T.toarray()))
            self._g = np.asarray(dropper_matrix @ self._z)
        self.iterations = 0

    def solve(self, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The displacement u and the dropper stretch e = e0 + B u.

        ``iterations`` holds the number of active-set passes used (0: no dropper slack).
        """
        free = self.factor.solve(rhs)
        self.iterations = 0
        stretch = self.elongations + self.dropper_matrix @ free
        slack = stretch < 0.0
        if not slack.any():
            return free, stretch
        for iteration in range(1, MAX_ACTIVE_SET_ITERATIONS + 1):
            self.iterations = iteration
            index = np.flatnonzero(slack)
            k = self.stiffness[index]
            system = np.eye(len(index)) - k[:, None] * self._g[np.ix_(index, index)]
            coefficients = np.linalg.solve(system, k * stretch[index])
            corrected = stretch + self._g[:, index] @ coefficients
            # a slack dropper must not be stretched, a taut one must not be compressed
            wrong = np.flatnonzero(np.where(slack, corrected > 0.0, corrected < 0.0))
            if not wrong.size:
                # einsum, not BLAS: a multithreaded gemv costs more than it saves here
                return free + np.einsum("ij,j->i", self._z[:, index], coefficients), corrected
            if iteration <= BLOCK_PIVOTING_ITERATIONS:
                slack[wrong] = ~slack[wrong]
            else:  # Murty's least-index rule: finite for the positive definite LCP matrix
                slack[wrong[0]] = not slack[wrong[0]]
        raise RuntimeError("the set of slack droppers did not settle within "
                           f"{MAX_ACTIVE_SET_ITERATIONS} iterations")


class NewmarkIntegrator:
    """Average-acceleration Newmark stepping of the catenary about its pre-state.

    Parameters
    ----------
    mesh : Mesh
        Matrices of the line.
    elongations : ndarray
        Pre-state dropper stretch e0 [m].
    time_step : float
        dt [s].
    alpha, beta : float
        Rayleigh coefficients (0, 0 for an undamped line).
    """

    def __init__(self, mesh: Mesh, elongations: np.ndarray, time_step: float, alpha: float,
                 beta: float):
        self.mesh = mesh
        self.time_step = dt = float(time_step)
        self.alpha, self.beta = float(alpha), float(beta)
        mass = mesh.mass
        c0, c1 = 4.0 / dt**2, 2.0 / dt
        matrix = (mesh.stiffness_linear() + c1 * beta * mesh.stiffness_structure
                  + sparse.diags((c0 + c1 * alpha) * mass))
        self.solver = SlackDropperSolver(matrix, mesh.dropper_matrix, mesh.dropper_stiffness,
                                         elongations)
        self._c1 = c1
        self._mass_u = (c0 + c1 * alpha) * mass
        self._mass_v = (4.0 / dt + alpha) * mass
        self.reset()

    def reset(self) -> None:
        """Back to the pre-state at rest, no load, energy counters zero."""
        n = self.mesh.unknowns
        self.displacement = np.zeros(n)
        self.velocity = np.zeros(n)
        self.acceleration = np.zeros(n)
        self.work = 0.0
        self.dissipated = 0.0
        self.defect = 0.0
        self._stretch = self.solver.elongations.copy()
        self._structure_u = np.zeros(n)  # K_s u and K_s v, kept to save a product per step
        self._structure_v = np.zeros(n)
        self._load_index = np.zeros(0, dtype=int)
        self._load_value = np.zeros(0)

    def step(self, load_index: np.ndarray, load_value: np.ndarray) -> None:
        """Advance one step with the nodal load ``load_value`` [N] at ``load_index`` at t_{n+1}.

        ``load_index`` must not repeat an index.
        """
        u, v, a = self.displacement, self.velocity, self.acceleration
        mesh, c1 = self.mesh, self._c1
        rhs = self._mass_u * u + self._mass_v * v + mesh.mass * a
        if self.beta:
            rhs += self.beta * (c1 * self._structure_u + self._structure_v)
        rhs[load_index] += load_value
        new, stretch = self.solver.solve(rhs)
        change = new - u
        new_velocity = c1 * change - v
        self.acceleration = c1 * (new_velocity - v) - a
        self.work += 0.5 * (load_value @ change[load_index]
                            + self._load_value @ change[self._load_index])
        # element-wise products and numpy sums rather than BLAS dot products: OpenBLAS runs long
        # dot products on several threads, which on a busy machine costs milliseconds
        dissipated = self.alpha * float(np.sum(mesh.mass * change * change))
        if self.beta:
            structure_u = mesh.stiffness_structure @ new
            structure_change = structure_u - self._structure_u
            self._structure_v = c1 * structure_change - self._structure_v
            self._structure_u = structure_u
            dissipated += self.beta * float(np.sum(change * structure_change))
        self.dissipated += dissipated / self.time_step
        if self.solver.iterations or (self._stretch < 0.0).any():
            self.defect += self._trapezoid_defect(self._stretch, stretch)
        self.displacement, self.velocity, self._stretch = new, new_velocity, stretch
        self._load_index, self._load_value = load_index, load_value

    def _trapezoid_defect(self, before: np.ndarray, after: np.ndarray) -> float:
        """Exact minus trapezoidal change of the droppers' energy over one step [J].

        Zero while a dropper stays taut (its force is linear in e); non-zero only in a step in
        which it goes slack or taut. The discrete energy balance of the average-acceleration rule
        is off by exactly the sum of these defects.
        """
        k = self.solver.stiffness
        f0, f1 = k * np.maximum(before, 0.0), k * np.maximum(after, 0.0)
        exact = 0.5 * (f1 * np.maximum(after, 0.0) - f0 * np.maximum(before, 0.0))
        return float(np.sum(exact - 0.5 * (f0 + f1) * (after - before)))

    def stretch(self) -> np.ndarray:
        """Current dropper stretch e = e0 + B u [m] (negative: slack)."""
        return self._stretch

    def energy(self) -> dict[str, float]:
        """Energy relative to the pre-state [J] (see `panto.catenary_cosim.catenary.Catenary.energy`)."""
        u, mesh = self.displacement, self.mesh
        k, e0 = self.solver.stiffness, self.solver.elongations
        e = self.stretch()
        droppers = float(np.sum(0.5 * k * (np.maximum(e, 0.0)**2 - e0**2)))
        gravity = float(mesh.weight @ u)
        structure = 0.5 * float(u @ (mesh.stiffness_structure @ u))
        # The pre-state forces of the structure balance gravity and the dropper preloads, so the
        # structure's energy change carries the linear term -(W + B^T k e0) . u.
        structure -= gravity + float((k * e0) @ (mesh.dropper_matrix @ u))
        kinetic = 0.5 * float(self.velocity @ (mesh.mass * self.velocity))
        potential = structure + droppers + gravity
        balance = kinetic + potential + self.dissipated - self.work
        return {"kinetic": kinetic, "strain": structure + droppers, "gravity": gravity,
                "potential": potential, "dissipated": float(self.dissipated),
                "work": float(self.work), "balance": float(balance),
                "dropper_defect": float(self.defect)}
