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
(LAPACK ``dpbtrf``, half-bandwidth 4). A step runs in the small compiled kernel of
`panto.catenary_cosim.kernel` (substitution with that factor, the slack droppers' active set
below and the vector updates in one foreign call, about ten times cheaper than LAPACK's
``dpbtrs`` plus NumPy) when a C compiler is available, else with ``dpbtrs`` and NumPy into
buffers allocated once; both give the same iterates to round-off (tests/test_catenary.py checks
each against a dense textbook step and against each other with slack droppers). Slack droppers are handled exactly by an active-set iteration
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

import ctypes
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sparse
from scipy.linalg import lapack

from panto.catenary_cosim import kernel
from panto.catenary_cosim.mesh import HALF_BANDWIDTH, Mesh, banded_upper

BLOCK_PIVOTING_ITERATIONS = kernel.BLOCK_PIVOTING_ITERATIONS
MAX_ACTIVE_SET_ITERATIONS = kernel.MAX_ACTIVE_SET_ITERATIONS


class BandedCholesky:
    """Cholesky factor of a symmetric positive definite banded matrix (LAPACK ``dpbtrf``)."""

    def __init__(self, matrix: sparse.spmatrix):
        factor, info = lapack.dpbtrf(banded_upper(matrix), lower=0)
        if info != 0:
            raise RuntimeError(f"dpbtrf: matrix is not positive definite (info = {info})")
        self._factor = np.asfortranarray(factor)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A^{-1} rhs for a vector or a matrix of right-hand sides (columns)."""
        solution, info = lapack.dpbtrs(self._factor, rhs, lower=0)
        if info != 0:
            raise RuntimeError(f"dpbtrs failed (info = {info})")
        return solution

    def solve_in_place(self, rhs: np.ndarray) -> np.ndarray:
        """Overwrite the contiguous float vector ``rhs`` with A^{-1} rhs; returns ``rhs``."""
        solution, info = lapack.dpbtrs(self._factor, rhs, lower=0, overwrite_b=1)
        if info != 0:
            raise RuntimeError(f"dpbtrs failed (info = {info})")
        if solution is not rhs and not np.shares_memory(solution, rhs):
            rhs[:] = solution  # LAPACK worked on a copy (not contiguous float64)
        return rhs


class SymmetricBandProduct:
    """y = K x for a symmetric banded matrix, by shifted diagonal products into reused buffers.

    Cheaper per call than a CSR product for the few diagonals of the catenary's structure matrix
    (offsets 0, 2, 4: the wires are not coupled without their droppers).

    Parameters
    ----------
    matrix : sparse matrix
        Symmetric, half-bandwidth at most `bandwidth`.
    """

    def __init__(self, matrix: sparse.spmatrix, bandwidth: int = HALF_BANDWIDTH):
        band = banded_upper(matrix, bandwidth)
        self.n = matrix.shape[0]
        self.main = band[bandwidth].copy()
        # (offset, d) with d[i] = K[i, i + offset], only the diagonals that hold something
        self.upper = [(k, band[bandwidth - k, k:].copy()) for k in range(1, bandwidth + 1)
                      if np.any(band[bandwidth - k, k:])]
        self._work = np.empty(self.n)

    def apply(self, x: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``out[:] = K x`` (``out`` must not be ``x``); returns ``out``."""
        n, work = self.n, self._work
        np.multiply(self.main, x, out=out)
        for k, d in self.upper:
            part = work[:n - k]
            np.multiply(d, x[k:], out=part)
            out[:n - k] += part
            np.multiply(d, x[:n - k], out=part)
            out[k:] += part
        return out


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
        u = np.array(rhs, dtype=float)
        return u, self.solve_in_place(u)

    def solve_in_place(self, rhs: np.ndarray) -> np.ndarray:
        """Overwrite the float vector ``rhs`` with the displacement u; returns the stretch e.

        A step in which every dropper stays taut costs one banded solve and one product with B.
        """
        free = self.factor.solve_in_place(rhs)
        return self.correct(free, self.elongations + self.dropper_matrix @ free)

    def correct(self, free: np.ndarray, stretch: np.ndarray) -> np.ndarray:
        """Add the slack droppers' correction to ``free`` = A^{-1} rhs in place.

        ``stretch`` is e0 + B free; returns the corrected stretch (``stretch`` itself when no
        dropper is slack) and sets ``iterations``.
        """
        self.iterations = 0
        if not stretch.size or not stretch.min() < 0.0:  # (NaN: as taut)
            return stretch
        slack = stretch < 0.0
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
                free += np.einsum("ij,j->i", self._z[:, index], coefficients)
                return corrected
            if iteration <= BLOCK_PIVOTING_ITERATIONS:
                slack[wrong] = ~slack[wrong]
            else:  # Murty's least-index rule: finite for the positive definite LCP matrix
                slack[wrong[0]] = not slack[wrong[0]]
        raise RuntimeError("the set of slack droppers did not settle within "
                           f"{MAX_ACTIVE_SET_ITERATIONS} iterations")


class NewmarkIntegrator:
    """Average-acceleration Newmark stepping of the catenary about its pre-state.

    The step carries the right-hand side's history instead of the velocity and acceleration:
    with s = 2/dt u + v and the history h = M (4/dt^2 u + 4/dt v + a) + C s (the right-hand
    side without the load), the rule above becomes

        A u_{n+1} = f_{n+1} + h_n,    s_{n+1} = 4/dt u_{n+1} - s_n,
        h_{n+1} = (16/dt^2 + 4/dt alpha) M u_{n+1} + 4/dt beta K_s u_{n+1} - h_n - 4/dt M s_n,

    the same iterates in exact arithmetic, in about a third of the vector operations (all into
    buffers allocated once); v = s - 2/dt u and a follow from s and h when asked for.

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
        self.structure = SymmetricBandProduct(mesh.stiffness_structure)
        self._c0, self._c1 = c0, c1
        self._history_u = (4.0 * c0 + 2.0 * c1 * self.alpha) * mass
        self._history_s = 2.0 * c1 * mass
        self._alpha_mass = self.alpha * mass
        n = mesh.unknowns
        # u, the spare buffer the next solve runs in, s, h, K_s u (two), u_{n+1} - u_n, scratch
        self._u, self._spare, self._s, self._history = (np.zeros(n) for _ in range(4))
        self._structure_u, self._structure_spare = np.zeros(n), np.zeros(n)
        self._change, self._scratch = np.zeros(n), np.zeros(n)
        self._stretch = self.solver.elongations.copy()
        self._compiled = _CompiledStep(self) if kernel.enabled() else None
        if self._compiled is not None and self._compiled.library is None:
            self._compiled = None
        # work, dissipated, defect: the C step's own counters, else plain attributes
        self._counters = _Counters() if self._compiled is None else self._compiled.state
        #: "compiled" (the C kernel of `panto.catenary_cosim.kernel`) or "numpy" (LAPACK)
        self.backend = "numpy" if self._compiled is None else "compiled"
        self.reset()

    def reset(self) -> None:
        """Back to the pre-state at rest, no load, energy counters zero."""
        for buffer in (self._u, self._s, self._history, self._structure_u):
            buffer.fill(0.0)
        self.work = 0.0
        self.dissipated = 0.0
        self.defect = 0.0
        np.copyto(self._stretch, self.solver.elongations)
        self._load: tuple[tuple[int, float], ...] = ()
        if self._compiled is not None:
            self._compiled.state.load_count = 0

    work = property(lambda self: self._counters.work,
                    lambda self, value: setattr(self._counters, "work", value),
                    doc="Work done by the loads since the reset [J] (trapezoidal in time).")
    dissipated = property(lambda self: self._counters.dissipated,
                          lambda self, value: setattr(self._counters, "dissipated", value),
                          doc="Energy dissipated by the Rayleigh damping since the reset [J].")
    defect = property(lambda self: self._counters.defect,
                      lambda self, value: setattr(self._counters, "defect", value),
                      doc="Sum of the droppers' trapezoid defects since the reset [J].")

    @property
    def compiled_state(self) -> "kernel.CatenaryState | None":
        """The C step's state (`panto.catenary_cosim.kernel.CatenaryState`), None for NumPy."""
        return None if self._compiled is None else self._compiled.state

    @property
    def displacement(self) -> np.ndarray:
        """u [m] about the pre-state (the integrator's own buffer: copy it to keep it)."""
        return self._u

    @property
    def velocity(self) -> np.ndarray:
        """v = s - 2/dt u [m/s] (a new array)."""
        return self._s - self._c1 * self._u

    @property
    def acceleration(self) -> np.ndarray:
        """a [m/s^2] (a new array): M a = h - C s - M (4/dt^2 u + 4/dt v)."""
        s, mass = self._s, self.mesh.mass
        damping = self.alpha * mass * s
        if self.beta:
            damping += self.beta * self.structure.apply(s, np.empty_like(s))
        return ((self._history - damping) / mass - self._c0 * self._u
                - 2.0 * self._c1 * self.velocity)

    def step(self, load_index: np.ndarray, load_value: np.ndarray) -> None:
        """Advance one step with the nodal load ``load_value`` [N] at ``load_index`` at t_{n+1}.

        A repeated index adds its loads.
        """
        load = tuple(zip((int(i) for i in load_index), (float(f) for f in load_value)))
        if self._compiled is not None:
            self._compiled.step(self, load)
        else:
            self._numpy_step(load)

    def _numpy_step(self, load: tuple[tuple[int, float], ...]) -> None:
        """The step with LAPACK's banded solve and NumPy operations into the buffers."""
        u, new, s, history = self._u, self._spare, self._s, self._history
        np.copyto(new, history)
        for i, force in load:
            new[i] += force
        stretch = self.solver.solve_in_place(new)
        change, scratch = self._change, self._scratch
        np.subtract(new, u, out=change)
        self.work += 0.5 * (sum(force * change[i] for i, force in load)
                            + sum(force * change[i] for i, force in self._load))
        structure_u = self.structure.apply(new, self._structure_spare)
        # the dissipation (change . C change) / dt; einsum, not a BLAS dot, which OpenBLAS runs on
        # several threads for long vectors (milliseconds on a busy machine)
        dissipated = 0.0
        if self.alpha:
            np.multiply(self._alpha_mass, change, out=scratch)
            dissipated += float(np.einsum("i,i->", scratch, change))
        if self.beta:
            np.subtract(structure_u, self._structure_u, out=scratch)
            dissipated += self.beta * float(np.einsum("i,i->", scratch, change))
        self.dissipated += dissipated / self.time_step
        # h <- P u_{n+1} + 2 c1 beta K_s u_{n+1} - h - R s;  s <- 2 c1 u_{n+1} - s
        np.multiply(self._history_u, new, out=scratch)
        np.subtract(scratch, history, out=history)
        np.multiply(self._history_s, s, out=scratch)
        history -= scratch
        if self.beta:
            np.multiply(structure_u, 2.0 * self._c1 * self.beta, out=scratch)
            history += scratch
        np.multiply(new, 2.0 * self._c1, out=scratch)
        np.subtract(scratch, s, out=s)
        if self.solver.iterations or self._stretch.min(initial=0.0) < 0.0:
            self.defect += self._trapezoid_defect(self._stretch, stretch)
        self._u, self._spare = new, u
        self._structure_u, self._structure_spare = structure_u, self._structure_u
        self._stretch, self._load = stretch, load

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


@dataclass
class _Counters:
    """The energy counters of the NumPy step [J]."""

    work: float = 0.0
    dissipated: float = 0.0
    defect: float = 0.0


class _CompiledStep:
    """`NewmarkIntegrator.step` through the C kernel (`panto.catenary_cosim.kernel`).

    Fills the kernel's :class:`~panto.catenary_cosim.kernel.CatenaryState` with the unit factor,
    the K_s rows, the dropper rows, Z = A^{-1} B^T, G = B Z and the addresses of the integrator's
    buffers, which stay in place (the C step copies u_{n+1} into u), so that a step, slack
    droppers and energy counters included, is one foreign call without allocation.
    """

    def __init__(self, integrator: NewmarkIntegrator):
        self.library = kernel.load_library()
        if self.library is None:
            return
        mesh, solver = integrator.mesh, integrator.solver
        w, dinv = kernel.unit_factor(solver.factor._factor)
        index, weight = kernel.dropper_rows(mesh.dropper_matrix)
        droppers = len(solver.elongations)
        z = np.zeros((droppers, mesh.unknowns)) if not droppers else solver._z.T
        g = np.zeros((droppers, droppers)) if not droppers else solver._g
        self._arrays = {"w": w, "dinv": dinv, "index": index, "weight": weight,
                        "e0": np.ascontiguousarray(solver.elongations, dtype=float),
                        "stiffness": np.ascontiguousarray(solver.stiffness, dtype=float),
                        "z": np.ascontiguousarray(z), "g": np.ascontiguousarray(g),
                        "static_height": np.zeros(mesh.elements + 1),
                        "rows": kernel.band_rows(banded_upper(mesh.stiffness_structure)),
                        "hu": integrator._history_u, "hs": integrator._history_s,
                        "alpha_mass": np.ascontiguousarray(integrator._alpha_mass),
                        "stretch_old": np.zeros(droppers),
                        "system": np.zeros(max(1, droppers * droppers)),
                        "coefficients": np.zeros(max(1, droppers)),
                        "corrected": np.zeros(max(1, droppers)),
                        "slack": np.zeros(max(1, droppers), dtype=np.int64),
                        "members": np.zeros(max(1, droppers), dtype=np.int64)}
        rows = self._arrays["rows"]
        state = kernel.CatenaryState(
            n=mesh.unknowns, droppers=droppers, elements=mesh.elements,
            odd=int(np.any(rows[[1, 3]])), kb=2.0 * integrator._c1 * integrator.beta,
            c1=integrator._c1, beta=integrator.beta, time_step=integrator.time_step,
            element_length=mesh.element_length)
        buffers = {"u": integrator._u, "fresh": integrator._spare, "s": integrator._s,
                   "h": integrator._history, "ks": integrator._structure_u,
                   "stretch": integrator._stretch}
        for name, array in {**self._arrays, **buffers}.items():
            if name in {f[0] for f in kernel.CatenaryState._fields_}:
                assert array.flags.c_contiguous and array.dtype.itemsize == 8
                setattr(state, name, array.ctypes.data)
        self.state, self._buffers = state, buffers
        self._pointer = ctypes.byref(state)
        self._load_index, self._load_value = (ctypes.c_long * 4)(), (ctypes.c_double * 4)()
        self._step = self.library.catenary_step

    def set_static_heights(self, heights: np.ndarray) -> None:
        """Contact-wire heights of the pre-state at the nodes [m] (for ``catenary_height``)."""
        np.copyto(self._arrays["static_height"], heights)

    def step(self, integrator: NewmarkIntegrator, load: tuple[tuple[int, float], ...]) -> None:
        """One step of the integrator (see `NewmarkIntegrator.step`)."""
        n = integrator.mesh.unknowns
        if len(load) > 4:
            raise ValueError("the compiled step takes at most 4 point loads")
        for k, (i, force) in enumerate(load):
            if not 0 <= i < n:
                raise IndexError(f"load index {i} outside 0..{n - 1}")
            self._load_index[k], self._load_value[k] = i, force
        check_status(self._step(self._pointer, len(load), self._load_index, self._load_value))


def check_status(status: int) -> None:
    """Raise for a failed C step (-1: the slack set did not settle; -2: singular system)."""
    if status == -1:
        raise RuntimeError("the set of slack droppers did not settle within "
                           f"{MAX_ACTIVE_SET_ITERATIONS} iterations")
    if status:
        raise RuntimeError(f"the slack droppers' system is singular (status {status})")
