"""The co-simulation master (panto.catenary_cosim.master): coupling convergence, contact loss, input checks.

A single-mass "line" (a test double with the Catenary interface) coupled with the TwoMass FMU is
a linear 3-mass system whose exact solution scipy gives independently; the real catenary is used
on a short three-span line with a coarse mesh.
"""
import dataclasses
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from panto.catenary_cosim.lines import load_line
from panto.catenary_cosim.master import cosimulate
from panto.catenary_cosim.pantographs import pantograph_setup, user_pantograph

H0 = 5.3  # design contact-wire height of the lines [m]
REFERENCE = dict(m1=15.0, k1=50.0, c1=90.0, m2=7.2, k2=4200.0, c2=10.0, F_0=120.0, k_E=5e4)


class MassLine:
    """A 'line' that is one mass on a spring under the contact point (Newmark, like Catenary)."""

    def __init__(self, *, time_step, mass=20.0, stiffness=5000.0, damping=10.0, length=40.0,
                 jump_time=None, jump=0.0):
        self.time_step, self.m, self.k, self.c = time_step, mass, stiffness, damping
        self.length, self.jump_time, self.jump = length, jump_time, jump
        self.support_positions = np.array([0.0, length / 2, length])
        self.line = SimpleNamespace(
            name="mass-line", contact_wire_height=H0, analysed_section=(0.0, length),
            contact_wire=SimpleNamespace(tension=20000.0, mass_per_length=1.35))
        self.reset()

    def reset(self):
        self.u = self.v = self.a = self.time = 0.0

    def contact_wire_height(self, x):
        forced = self.jump if self.jump_time is not None and self.time >= self.jump_time else 0.0
        return H0 + self.u + forced

    def static_contact_wire_height(self, x):
        return H0 + 0.0 * np.asarray(x, dtype=float)

    def advance(self, force, x):
        dt, m, k, c = self.time_step, self.m, self.k, self.c
        a = (force - c * (self.v + dt / 2 * self.a)
             - k * (self.u + dt * self.v + dt * dt / 4 * self.a)) / (m + c * dt / 2 + k * dt * dt / 4)
        self.u += dt * self.v + dt * dt / 4 * (self.a + a)
        self.v += dt / 2 * (self.a + a)
        self.a = a
        self.time += dt

    def support_uplift(self):
        return np.array([0.0, self.u, 0.0])


def _monolithic_contact_force(duration, mass=20.0, stiffness=5000.0, damping=10.0):
    """Exact contact force of TwoMass + the mass line as one linear ODE (Radau, tight)."""
    p = SimpleNamespace(**REFERENCE)
    # static equilibrium of the pantograph on the undisturbed wire (springs relaxed at H0)
    matrix = np.array([[p.k1 + p.k2, -p.k2], [-p.k2, p.k2 + p.k_E]])
    x1, x2 = np.linalg.solve(matrix, [p.F_0 + p.k1 * H0, p.k_E * H0])

    def rhs(t, s):
        x1, x2, u, v1, v2, vu = s
        force = p.k_E * (x2 - H0 - u)
        return [v1, v2, vu,
                (-p.k1 * (x1 - H0) - p.c1 * v1 + p.k2 * (x2 - x1) + p.c2 * (v2 - v1) + p.F_0) / p.m1,
                (-p.k2 * (x2 - x1) - p.c2 * (v2 - v1) - force) / p.m2,
                (-stiffness * u - damping * vu + force) / mass]

    solution = solve_ivp(rhs, (0.0, duration), [x1, x2, 0, 0, 0, 0], method="Radau",
                         rtol=1e-11, atol=1e-13, dense_output=True)
    return lambda t: p.k_E * (solution.sol(t)[1] - H0 - solution.sol(t)[2])


@pytest.fixture(scope="module")
def setup(project_fmus):
    return pantograph_setup("en50318-2002").with_fmu(project_fmus["TwoMass.fmu"].path)


@pytest.fixture(scope="module")
def short_line():
    """The EN 50318 line cut to three spans (analysed: the middle one)."""
    return dataclasses.replace(load_line("en50318-2002"), spans=3, analysed_spans=(2, 2))


def test_coupling_converges_to_the_monolithic_solution(setup):
    duration = 0.5
    exact = _monolithic_contact_force(duration)
    errors = []
    for step in (4e-4, 2e-4, 1e-4):
        result = cosimulate(MassLine(time_step=step), setup, speed_kmh=3.6 * 40.0 / duration)
        errors.append(np.max(np.abs(result.contact_force - exact(result.time))))
        assert result.settings["coupling_gain"] < 0.1
    # first order in the communication step (the wire height lags one step)
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=0.2)
    assert errors[1] / errors[2] == pytest.approx(2.0, rel=0.2)
    assert errors[2] < 0.02 * REFERENCE["F_0"]


def test_start_in_equilibrium_with_relaxed_springs_at_the_design_height(setup):
    result = cosimulate(MassLine(time_step=1e-4), setup, speed_kmh=100.0, stop_position=1.0)
    p = SimpleNamespace(**REFERENCE)
    # static: k1 x1 = F_0 - F, k2 (x2 - x1) = -F, F = k_E x2 (heights above H0)
    static = p.F_0 / (1.0 + p.k_E / p.k1 + p.k_E / p.k2) * p.k_E / p.k1
    assert result.contact_force[0] == pytest.approx(static, rel=1e-9)
    assert result.contact_force[1] == pytest.approx(static, rel=1e-9)  # no kick at the start


def test_coupling_step_error_vanishes_on_the_catenary(setup, short_line):
    """Fixed catenary step; communication step 4, 2, 1 times it: differences halve."""
    from panto.catenary_cosim.catenary import Catenary

    catenary = Catenary(short_line, time_step=2.5e-4, element_length=1.0)
    runs = [cosimulate(catenary, setup, speed_kmh=250.0, communication_step=m * 2.5e-4)
            for m in (4, 2, 1)]
    coarse, middle, fine = (run.contact_force for run in runs)
    first = np.max(np.abs(coarse - middle[::2]))
    second = np.max(np.abs(middle[::2] - fine[::4]))
    assert second < 0.65 * first
    section = runs[2].in_section
    assert not np.any(fine[section] == 0.0)
    assert fine[section].max() < 3 * fine[0]  # bounded: the stiff contact coupling is stable


def test_contact_loss_on_a_wire_forced_away(setup):
    # the wire jumps 1 m up at t = 0.2 s: the head (120 N on 22 kg) needs > 0.6 s to follow,
    # so from then on every sample to the end (0.5 s) is a contact loss
    line = MassLine(time_step=1e-4, jump_time=0.2, jump=1.0)
    result = cosimulate(line, setup, speed_kmh=3.6 * 40.0 / 0.5)
    stats = result.statistics()
    lost = result.contact_force == 0.0
    assert stats.loss_pct == pytest.approx(100.0 * 0.3 / 0.5, abs=0.05)
    assert result.counters["contact_loss_events"] == 1
    assert np.all(result.head_height[lost] < result.wire_height[lost])


def test_contact_loss_is_counted_and_means_head_below_wire(project_fmus, short_line):
    weak = pantograph_setup("en50318-2002").with_fmu(
        project_fmus["TwoMass.fmu"].path).with_parameters(F_0=40.0)
    result = cosimulate(short_line, weak, speed_kmh=300.0, time_step=2e-4, element_length=1.0)
    lost = result.contact_force[1:] == 0.0
    # F_{n+1} = 0 exactly when the head ended the step below the wire height it was given
    below = result.head_height[1:] < result.wire_height[:-1]
    np.testing.assert_array_equal(lost, below)
    assert result.counters["contact_loss_samples"] == lost.sum() > 0
    stats = result.statistics()
    section = result.in_section
    assert stats.loss_pct == pytest.approx(
        100.0 * np.count_nonzero(result.contact_force[section] == 0.0) / section.sum())
    assert stats.loss_pct > 0.0 and stats.min < stats.mean


def test_physical_pantograph_height_mapping(project_fmus, short_line):
    """The design wire height maps to eta = 2 m: the first force is the FMU's static force there."""
    from panto.build_fmu.stepping import FmuStepper

    path = project_fmus["Pantograph.fmu"].path
    setup = pantograph_setup("physical").with_fmu(path)
    result = cosimulate(short_line, setup, speed_kmh=200.0, time_step=2e-4,
                        element_length=1.0, stop_position=5.0)
    with FmuStepper(path, step_size=1e-3, inputs=["eta", "p"], outputs=["F_c"]) as alone:
        static = alone.initialise([2.0, 4.0])[0]
    assert static == pytest.approx(81.0, abs=1.0)  # the documented operating point
    assert result.contact_force[0] == pytest.approx(static, rel=1e-9)
    assert result.settings["eta_offset_m"] == pytest.approx(2.0 - H0)


def test_result_files(setup, short_line, tmp_path):
    result = cosimulate(short_line, setup, speed_kmh=250.0, time_step=5e-4, element_length=2.0)
    csv = result.to_csv(tmp_path / "run.csv", every=5)
    header = csv.read_text().splitlines()[0].split(",")
    assert header[:4] == ["time [s]", "position [m]", "contact_force [N]",
                          "contact_force_20Hz [N]"]
    assert len(csv.read_text().splitlines()) == 1 + len(result.time[::5])
    metadata = json.loads((tmp_path / "run.csv.json").read_text())
    assert metadata["settings"]["speed_kmh"] == 250.0
    for path in result.save_plots(tmp_path):
        assert path.stat().st_size > 10_000
    timing = result.timing
    assert timing["loop"] == pytest.approx(timing["catenary"] + timing["fmu"] + timing["python"])


def test_bad_input_is_refused_clearly(setup, short_line, project_fmus):
    with pytest.raises(ValueError, match="unknown line 'nowhere'"):
        cosimulate("nowhere", setup, speed_kmh=250.0)
    with pytest.raises(ValueError, match="speed must be a positive"):
        cosimulate(short_line, setup, speed_kmh=-10.0)
    with pytest.raises(ValueError, match="wave speed"):
        cosimulate(short_line, setup, speed_kmh=450.0)
    with pytest.raises(ValueError, match="unknown pantograph"):
        cosimulate(short_line, "nobody", speed_kmh=250.0)
    with pytest.raises(ValueError, match="integer multiple"):
        cosimulate(short_line, setup, speed_kmh=250.0, time_step=2e-4,
                   communication_step=3e-4, element_length=2.0)
    stranger = user_pantograph(project_fmus["TwoMass.fmu"].path, height_input="height",
                               force_output="F_c")
    with pytest.raises(ValueError, match="valid input names: eta, p"):
        cosimulate(short_line, stranger, speed_kmh=250.0, element_length=2.0)
    with pytest.raises(ValueError, match="coupling gain"):
        cosimulate(MassLine(time_step=0.02), setup, speed_kmh=10.0)
    assert math.isfinite(load_line("en50318-2002").contact_wire.wave_speed)


def test_model_exchange_and_co_simulation_give_the_same_run(setup, short_line):
    runs = [cosimulate(short_line, setup, speed_kmh=250.0, time_step=5e-4, element_length=2.0,
                       stop_position=40.0, interface=interface) for interface in ("CS", "ME")]
    forces = [run.contact_force for run in runs]
    assert np.ptp(forces[0]) > 10.0
    np.testing.assert_allclose(forces[1], forces[0], rtol=0, atol=1e-3 * np.ptp(forces[0]))
