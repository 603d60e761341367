"""The finite-difference catenary: a two-wire simple catenary driven by a moving contact force.

`Catenary` is the object the co-simulation master steps: it builds the mesh
(`panto.catenary_cosim.mesh`), solves the static pre-state with the designed contact-wire heights
(`panto.catenary_cosim.static`) and advances the dynamics about it with the implicit average-acceleration
Newmark rule, factorised once, with tension-only droppers (`panto.catenary_cosim.integration`).

Modelling choices (see the line files for the data):

* contact wire and messenger wire: tensioned Euler-Bernoulli beams on a uniform grid, lumped mass;
* droppers: springs between the wires that carry k max(e, 0) (no compression), their clamp masses
  and half their own mass lumped at each end;
* steady arms: a spring and a lumped mass on the contact wire at every interior support, adjusted
  (preloaded) so that the contact wire is at its design height there in the pre-state; messenger
  supports: a spring (and mass) on the messenger;
* ends: both wires pinned at the first and last supports (``end_treatment = "pinned"``), several
  spans away from the analysed section;
* damping: Rayleigh alpha M + beta K_s from the line file (``damping=False`` switches it off);
* the moving contact point acts through the linear shape functions of the element it is in; the
  wire height is read back with the same functions.

Sign conventions: heights and displacements are positive upwards; the contact force is positive
when the pantograph pushes the wire up; x = 0 at the first support.
"""
from __future__ import annotations

import ctypes
import math
from typing import Any, Callable

import numpy as np

from panto.catenary_cosim.integration import (NewmarkIntegrator, SlackDropperSolver,
                                               check_status)
from panto.catenary_cosim.lines import LineDefinition
from panto.catenary_cosim.mesh import build_mesh
from panto.catenary_cosim.static import StaticState, solve_static_state

DEFAULT_ELEMENT_LENGTH = 0.25  # [m], from benchmarks/catenary_convergence.py


class Catenary:
    """A simple catenary as a finite-difference model, advanced in fixed time steps.

    Parameters
    ----------
    line : LineDefinition
        The overhead line (`panto.catenary_cosim.lines.load_line`).
    time_step : float
        Fixed step [s].
    element_length : float
        Requested node spacing [m], rounded to a whole number of elements per span.
    damping : bool
        Rayleigh damping of the line file (True) or none (False).
    progress : callable, optional
        Receives short messages while the model is built.

    Examples
    --------
    >>> from panto.catenary_cosim.lines import load_line
    >>> catenary = Catenary(load_line("en50318-2002"), time_step=1e-3)
    >>> catenary.advance(120.0, 250.0)
    >>> round(catenary.contact_wire_height(250.0), 2)
    5.3
    """

    def __init__(self, line: LineDefinition, *, time_step: float,
                 element_length: float = DEFAULT_ELEMENT_LENGTH, damping: bool = True,
                 progress: Callable[[str], None] | None = None):
        if not (math.isfinite(time_step) and time_step > 0.0):
            raise ValueError(f"time_step = {time_step!r} must be a positive number of seconds")
        say = progress or (lambda message: None)
        self.line = line
        self.time_step = float(time_step)
        say(f"{line.name}: building the mesh (element length ~{element_length} m)")
        mesh = build_mesh(line, element_length)
        state = solve_static_state(line, mesh)
        # the droppers' own mass depends on their length: one more pass with the computed gaps
        mesh = build_mesh(line, element_length, dropper_lengths=state.dropper_distances)
        self.mesh = mesh
        say(f"{line.name}: static pre-state ({len(state.dropper_forces)} droppers)")
        self.static_state: StaticState = solve_static_state(line, mesh)
        self.length = float(mesh.positions[-1])
        self.element_length = mesh.element_length
        self.support_positions = mesh.positions[mesh.support_nodes]
        say(f"{line.name}: factorising {mesh.unknowns} unknowns")
        alpha, beta = (line.rayleigh_alpha, line.rayleigh_beta) if damping else (0.0, 0.0)
        self._integrator = NewmarkIntegrator(mesh, self.static_state.dropper_elongations,
                                             self.time_step, alpha, beta)
        self._state_pointer: Any = None
        state = self._integrator.compiled_state  # the C step locates the load itself
        if state is not None:
            self._integrator._compiled.set_static_heights(self.static_state.contact_wire_heights)
            self._advance_compiled = self._integrator._compiled.library.catenary_advance
            self._state_pointer = ctypes.byref(state)
        self._static_solver: SlackDropperSolver | None = None
        self.time = 0.0
        self._steps = 0

    # --- stepping ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the static pre-state at rest, time = 0, energy counters zero."""
        self._integrator.reset()
        self.time = 0.0
        self._steps = 0

    def advance(self, force: float, x: float) -> None:
        """One implicit step of ``time_step`` with an upward point force ``force`` [N] at ``x`` [m].

        The force is the load at the end of the step (t + time_step); it is shared between the two
        nodes of the element holding ``x`` with the linear shape functions.
        """
        if self._state_pointer is not None and math.isfinite(force) and 0.0 <= x <= self.length:
            check_status(self._advance_compiled(self._state_pointer, force, x))
        else:
            index, value = self._load(force, x)
            self._integrator.step(index, value)
        self._steps += 1
        self.time = self._steps * self.time_step

    @property
    def compiled_state(self) -> Any:
        """The compiled step's state (`panto.catenary_cosim.kernel.CatenaryState`) for a loop
        that steps the catenary in C (`panto.catenary_cosim.coupling_kernel`); None for the
        NumPy step."""
        return self._integrator.compiled_state

    def count_compiled_steps(self, count: int) -> None:
        """Advance the clock over `count` steps taken in C through :attr:`compiled_state`."""
        self._steps += int(count)
        self.time = self._steps * self.time_step

    def _load(self, force: float, x: float) -> tuple[list[int], list[float]]:
        if not math.isfinite(force):
            raise ValueError(f"contact force {force!r} is not finite")
        j, xi = self._locate(x)
        elements = self.mesh.elements
        index, value = [], []
        for node, weight in ((j, 1.0 - xi), (j + 1, xi)):
            if 0 < node < elements:  # the pinned end nodes take no load
                index.append(2 * (node - 1))
                value.append(force * weight)
        return index, value

    def _locate(self, x: float) -> tuple[int, float]:
        if not (0.0 <= x <= self.length):
            raise ValueError(f"position x = {x!r} m is outside the line [0, {self.length}] m")
        s = x / self.element_length
        j = min(int(s), self.mesh.elements - 1)
        return j, s - j

    # --- reading the state --------------------------------------------------------------------
    def contact_wire_height(self, x: float) -> float:
        """Current absolute contact-wire height at ``x`` [m] (pre-state + displacement)."""
        j, xi = self._locate(x)
        static = self.static_state.contact_wire_heights
        u = self._integrator.displacement
        lower = u[2 * (j - 1)] if j > 0 else 0.0
        upper = u[2 * j] if j + 1 < self.mesh.elements else 0.0
        return float((1.0 - xi) * (static[j] + lower) + xi * (static[j + 1] + upper))

    def static_contact_wire_height(self, x: float | np.ndarray) -> float | np.ndarray:
        """Contact-wire height of the pre-state at ``x`` [m], same shape functions."""
        heights = np.interp(x, self.mesh.positions, self.static_state.contact_wire_heights)
        return float(heights) if np.ndim(heights) == 0 else heights

    def contact_wire_displacement(self) -> np.ndarray:
        """Current contact-wire displacement from the pre-state at every grid node [m]."""
        return np.concatenate([[0.0], self._integrator.displacement[0::2], [0.0]])

    def messenger_wire_displacement(self) -> np.ndarray:
        """Current messenger displacement from the pre-state at every grid node [m]."""
        return np.concatenate([[0.0], self._integrator.displacement[1::2], [0.0]])

    def support_uplift(self) -> np.ndarray:
        """Current uplift of the contact wire at every support (ends included) [m]."""
        nodes = self.mesh.support_nodes
        moving = (nodes > 0) & (nodes < self.mesh.elements)  # the pinned ends stay at 0
        uplift = np.zeros(len(nodes))
        uplift[moving] = self._integrator.displacement[2 * (nodes[moving] - 1)]
        return uplift

    def dropper_forces(self) -> np.ndarray:
        """Current dropper tensions k max(e, 0) [N], one per dropper (never negative)."""
        return self.mesh.dropper_stiffness * np.maximum(self._integrator.stretch(), 0.0)

    def dropper_stretches(self) -> np.ndarray:
        """Current dropper stretch e = (gap between the wires) - (unstretched length) [m].

        Negative for a slack dropper, whose force is then exactly zero.
        """
        return self._integrator.stretch().copy()

    def dropper_lengths(self) -> np.ndarray:
        """Unstretched dropper lengths found by the static pre-state [m]."""
        return self.static_state.dropper_lengths.copy()

    def motion(self) -> dict[str, np.ndarray]:
        """Copies of the unknowns' displacement [m], velocity [m/s] and acceleration [m/s^2]
        about the pre-state (interleaved: contact wire node j at 2 (j - 1), messenger at
        2 (j - 1) + 1; matrices in ``self.mesh``)."""
        integrator = self._integrator
        return {"displacement": integrator.displacement.copy(),
                "velocity": integrator.velocity.copy(),
                "acceleration": integrator.acceleration.copy()}

    @property
    def nodes(self) -> np.ndarray:
        """x of the grid nodes [m]."""
        return self.mesh.positions

    def energy(self) -> dict[str, float]:
        """Energy of the motion about the pre-state [J].

        Returns
        -------
        dict
            ``kinetic`` 1/2 v^T M v; ``strain`` change of elastic energy (wire tension and bending,
            supports, droppers k max(e, 0)^2 / 2); ``gravity`` change of potential energy of the
            weights; ``potential`` = strain + gravity; ``dissipated`` by Rayleigh damping;
            ``work`` done by the contact force (trapezoidal in time, as the integrator sees it);
            ``balance`` = kinetic + potential + dissipated - work; ``dropper_defect`` the
            energy error of the trapezoidal rule in the steps where a dropper went slack or taut
            again (exact minus trapezoidal dropper energy). The integrator guarantees
            ``balance == dropper_defect`` up to round-off; both are zero while every dropper
            stays taut.
        """
        return self._integrator.energy()

    # --- statics ------------------------------------------------------------------------------
    def static_uplift(self, force: float, x: float) -> np.ndarray:
        """Contact-wire uplift at every grid node [m] under a static upward force at ``x``.

        Droppers may go slack (solved exactly like the dynamics); mass and damping play no part.
        """
        if self._static_solver is None:
            self._static_solver = SlackDropperSolver(
                self.mesh.stiffness_linear(), self.mesh.dropper_matrix,
                self.mesh.dropper_stiffness, self.static_state.dropper_elongations)
        index, value = self._load(force, x)
        rhs = np.zeros(self.mesh.unknowns)
        rhs[index] += value
        u, _ = self._static_solver.solve(rhs)
        return np.concatenate([[0.0], u[0::2], [0.0]])

    def elasticity(self, x: float | np.ndarray, *, force: float = 100.0) -> np.ndarray:
        """Static uplift per newton at the loaded point [m/N] (EN 50318 style elasticity curve)."""
        points = np.atleast_1d(np.asarray(x, dtype=float))
        result = np.empty(len(points))
        for i, point in enumerate(points):
            uplift = self.static_uplift(force, float(point))
            result[i] = np.interp(point, self.mesh.positions, uplift) / force
        return result
