"""The finite-difference catenary: line files, pre-state, statics, waves, energy, droppers, convergence.

Every check is against physics or an independent computation: the analytic beam-string sag, the
wave speed and impedance of a string, static solutions of the same mesh, the discrete energy
identity of the average-acceleration rule, a direct sparse solve with a dropper removed, and
published dropper lengths of the 2015 benchmark.
"""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import scipy.sparse as sparse
from scipy.sparse.linalg import spsolve

from panto.catenary_cosim.catenary import Catenary
from panto.catenary_cosim.lines import LINE_DIRECTORY, LINE_NAMES, LineDefinition, load_line
from panto.catenary_cosim.mesh import GRAVITY


@pytest.fixture(scope="module")
def reference_line() -> LineDefinition:
    return load_line("en50318-2002")


def short_line(line: LineDefinition, spans: int = 3, **changes) -> LineDefinition:
    """The same line with fewer spans (the middle span analysed)."""
    middle = (spans + 1) // 2
    return dataclasses.replace(line, spans=spans, analysed_spans=(middle, middle), **changes)


def single_wire(line: LineDefinition, span_length: float, **changes) -> LineDefinition:
    """One span without droppers: the contact wire alone, pinned at both supports."""
    return dataclasses.replace(line, spans=1, span_length=span_length, dropper_positions=(),
                               dropper_presag=(), dropper_nominal_lengths=None,
                               analysed_spans=(1, 1), **changes)


# --- line files ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", LINE_NAMES)
def test_every_line_loads_with_provenance_for_every_item(name):
    line = load_line(name)
    assert line.name == name
    assert line.spans >= 1 and line.span_length > 0
    data = json.loads((LINE_DIRECTORY / f"{name}.json").read_text())
    assert set(line.provenance) == set(data["items"])
    assert all(tag.strip() for tag in line.provenance.values())
    for item, tag in line.provenance.items():
        if tag == "project choice":
            assert line.notes.get(item), f"{name}: project choice {item!r} without a reason"


def test_reference_values_of_the_2002_line(reference_line):
    line = reference_line
    assert (line.spans, line.span_length, len(line.dropper_positions)) == (10, 60.0, 9)
    assert line.contact_wire.tension == 20000.0 and line.messenger_wire.tension == 16000.0
    assert line.contact_wire.wave_speed == pytest.approx(121.7, abs=0.05)  # 438 km/h
    assert line.analysed_section == (240.0, 360.0)
    assert set(line.dropper_presag) == {0.0}


def _write(tmp_path, data) -> str:
    path = tmp_path / "line.json"
    path.write_text(json.dumps(data))
    return str(path)


def _reference_data() -> dict:
    return json.loads((LINE_DIRECTORY / "en50318-2002.json").read_text())


@pytest.mark.parametrize("change, words", [
    (lambda d: d["items"].pop("contact_wire_tension"), ["missing", "contact_wire_tension"]),
    (lambda d: d["items"].update(stagger={"value": 0.2, "unit": "m", "provenance": "x"}),
     ["unknown", "stagger"]),
    (lambda d: d["items"]["contact_wire_tension"].update(value=-20000.0),
     ["contact_wire_tension", "-20000"]),
    (lambda d: d["items"]["contact_wire_tension"].update(unit="kN"),
     ["contact_wire_tension", "kN"]),
    (lambda d: d["items"]["messenger_wire_mass_per_length"].update(value=0.0),
     ["messenger_wire_mass_per_length", "0.0"]),
    (lambda d: d["items"]["dropper_positions"]["value"].__setitem__(8, 61.0),
     ["dropper_positions", "61.0", "outside"]),
    (lambda d: d["items"]["dropper_presag"]["value"].pop(),
     ["dropper_presag", "one value per dropper"]),
    (lambda d: d["items"]["spans"].update(value=2.5), ["spans", "2.5"]),
    (lambda d: d["items"]["analysed_spans"].update(value=[5, 11]), ["analysed_spans", "11"]),
    (lambda d: d["items"]["span_length"].pop("provenance"), ["span_length", "provenance"]),
    (lambda d: d["items"]["end_treatment"].update(value="free"), ["end_treatment", "free"]),
    (lambda d: d["items"]["rayleigh_beta"].update(value="small"), ["rayleigh_beta", "small"]),
], ids=["missing", "unknown", "negative-tension", "wrong-unit", "zero-mass", "dropper-outside",
        "presag-count", "fractional-spans", "analysed-outside", "no-provenance", "bad-end",
        "not-a-number"])
def test_malformed_line_files_are_refused_naming_file_item_and_value(tmp_path, change, words):
    data = _reference_data()
    change(data)
    path = _write(tmp_path, data)
    with pytest.raises(ValueError) as error:
        load_line(path)
    message = str(error.value)
    assert path in message
    for word in words:
        assert word in message


def test_unreadable_and_unknown_lines_are_refused(tmp_path):
    bad = tmp_path / "broken.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="broken.json.*JSON"):
        load_line(bad)
    with pytest.raises(ValueError, match="unknown line 'no-such-line'.*en50318-2002"):
        load_line("no-such-line")
    with pytest.raises(ValueError, match="missing.json"):
        load_line(tmp_path / "missing.json")


# --- pre-state ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["en50318-2002", "benchmark-2015"])
def test_prestate_holds_the_contact_wire_at_its_design_height_or_presag(name):
    line = load_line(name)
    catenary = Catenary(line, time_step=1e-3, element_length=0.5)
    state = catenary.static_state
    presag = np.tile(line.dropper_presag, line.spans)
    heights = catenary.static_contact_wire_height(state.dropper_positions)
    np.testing.assert_allclose(heights, line.contact_wire_height - presag, atol=1e-9)
    np.testing.assert_allclose(catenary.static_contact_wire_height(catenary.support_positions),
                               line.contact_wire_height, atol=1e-9)
    assert np.all(state.dropper_forces > 0.0) and np.all(catenary.dropper_lengths() > 0.0)
    # the lengths are the gaps minus the stretch of a spring carrying the dropper force
    np.testing.assert_allclose(state.dropper_distances - state.dropper_lengths,
                               state.dropper_forces / line.dropper_stiffness, rtol=1e-12)
    # before any step the dynamic state is the pre-state: every dropper taut at its static force
    np.testing.assert_allclose(catenary.dropper_forces(), state.dropper_forces, rtol=1e-12)
    assert catenary.contact_wire_height(123.4) == pytest.approx(
        catenary.static_contact_wire_height(123.4), abs=1e-12)


def test_benchmark_dropper_lengths_follow_the_published_profile():
    """Our dropper lengths against the published nominal ones of the 2015 benchmark.

    The published lengths come from another code's static solution. We compare the profile along
    the span (each length minus the span's mean), which does not depend on how the encumbrance is
    measured (wire axes or clamps); 5 mm allows for modelling differences (clamp and dropper
    masses, support flexibility) on a profile that varies by 276 mm.
    """
    line = load_line("benchmark-2015")
    catenary = Catenary(line, time_step=1e-3)
    per_span = len(line.dropper_positions)
    middle = line.spans // 2
    ours = catenary.dropper_lengths()[middle * per_span:(middle + 1) * per_span]
    published = np.asarray(line.dropper_nominal_lengths)
    np.testing.assert_allclose(ours - ours.mean(), published - published.mean(), atol=5e-3)


# --- statics ------------------------------------------------------------------------------------
def beam_string_sag(x, length, weight, tension, bending):
    """Exact deflection of a pinned-pinned beam under tension T with uniform load q (downwards).

    Solves EI w'''' - T w'' = -q, w = w'' = 0 at both ends: a parabola plus the bending correction
    (q / (T mu^2)) (1 - cosh(mu (x - L/2)) / cosh(mu L / 2)), mu^2 = T / EI.
    """
    parabola = -weight / (2.0 * tension) * x * (length - x)
    if bending == 0.0:
        return parabola
    mu = math.sqrt(tension / bending)
    a, b = mu * np.abs(x - length / 2), mu * length / 2
    cosh_ratio = (np.exp(a - b) + np.exp(-a - b)) / (1.0 + math.exp(-2 * b))  # no overflow
    return parabola - weight / (tension * mu**2) * (cosh_ratio - 1.0)


def test_static_sag_of_a_single_span_matches_the_cable_solution(reference_line):
    line = single_wire(reference_line, 60.0)
    catenary = Catenary(line, time_step=1e-3, element_length=0.25)
    wire = line.contact_wire
    x = catenary.nodes
    exact = beam_string_sag(x, 60.0, wire.mass_per_length * GRAVITY, wire.tension,
                            wire.bending_stiffness)
    sag = catenary.static_state.contact_wire_heights - line.contact_wire_height
    assert -sag.min() == pytest.approx(wire.mass_per_length * GRAVITY * 60.0**2
                                       / (8 * wire.tension), rel=1e-3)  # q L^2 / (8 T) = 0.298 m
    # the bending correction q EI / T^2 is 6.5 um here, the difference must be far below it
    np.testing.assert_allclose(sag, exact, atol=2e-6)


def test_static_sag_of_a_stiff_beam_converges_at_second_order(reference_line):
    """With EI large enough that the bending boundary layer (width sqrt(EI/T) = 3 m) is resolved,
    the finite differences converge to the beam-string solution at O(h^2)."""
    line = single_wire(reference_line, 60.0)
    line = dataclasses.replace(line, contact_wire=dataclasses.replace(
        line.contact_wire, bending_stiffness=2.0e5))
    wire = line.contact_wire
    errors = []
    for h in (1.0, 0.5):
        catenary = Catenary(line, time_step=1e-3, element_length=h)
        exact = beam_string_sag(catenary.nodes, 60.0, wire.mass_per_length * GRAVITY,
                                wire.tension, wire.bending_stiffness)
        sag = catenary.static_state.contact_wire_heights - line.contact_wire_height
        errors.append(np.abs(sag - exact).max())
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.25)


def test_a_slowly_moving_force_reproduces_the_static_uplift(reference_line):
    """Force ramped up at a support, then moved at 2 m/s across a span: v/c = 0.016, so the
    dynamic amplification 1/(1 - (v/c)^2) - 1 is 3e-4; damping is raised (alpha = 2/s) so that the
    ramp's transients die out. The uplift must match static solutions of the same mesh within 2 %
    of the largest uplift."""
    line = short_line(reference_line, rayleigh_alpha=2.0, rayleigh_beta=1e-3)
    dt, force, ramp, speed = 2e-3, 100.0, 10.0, 2.0
    catenary = Catenary(line, time_step=dt, element_length=0.5)
    for i in range(int(ramp / dt)):
        catenary.advance(force * 0.5 * (1 - math.cos(math.pi * (i + 1) * dt / ramp)), 60.0)
    positions, dynamic = [], []
    for i in range(int(60.0 / speed / dt)):
        x = 60.0 + speed * (i + 1) * dt
        catenary.advance(force, x)
        if (i + 1) % 500 == 0:
            positions.append(x)
            dynamic.append(catenary.contact_wire_height(x) - catenary.static_contact_wire_height(x))
    static = [np.interp(x, catenary.nodes, catenary.static_uplift(force, x)) for x in positions]
    np.testing.assert_allclose(dynamic, static, atol=0.02 * max(static))


def test_elasticity_is_largest_at_mid_span_and_smallest_near_the_supports(reference_line):
    catenary = Catenary(reference_line, time_step=1e-3)
    span = reference_line.span_length
    x = 4 * span + np.arange(0.0, span + 0.01, 0.5)  # span 5 of 10
    elasticity = catenary.elasticity(x)
    assert np.all(elasticity > 0)
    assert abs(x[np.argmax(elasticity)] - 4.5 * span) <= span / 6
    near_support = np.minimum(x - 4 * span, 5 * span - x) <= 6.0  # up to the first droppers
    assert elasticity.min() == elasticity[near_support].min()
    assert elasticity[0] < elasticity.mean()


# --- dynamics -----------------------------------------------------------------------------------
def test_waves_travel_at_sqrt_tension_over_mass_with_the_string_impedance(reference_line):
    """A smooth force pulse (80 ms, Hann) on a single wire: the displacement a distance away is
    the delayed integral of the force, rising to I / (2 sqrt(T rho A)). The half-level crossing
    times at two probes give the speed. Expected errors at the pulse's 12.5 Hz: finite
    differences (kh)^2/24 = 0.1 %, Newmark (w dt)^2/12 = 0.01 %, bending EI k^2/(2T) = 0.2 %;
    tolerance 1 %."""
    line = single_wire(reference_line, 200.0)
    dt, duration, amplitude, source = 5e-4, 0.08, 100.0, 50.0
    catenary = Catenary(line, time_step=dt, damping=False, element_length=0.25)
    probes = (80.0, 140.0)
    history = []
    for i in range(int(1.0 / dt)):
        t = (i + 1) * dt
        catenary.advance(amplitude * math.sin(math.pi * t / duration)**2 if t < duration else 0.0,
                         source)
        history.append([catenary.contact_wire_height(p) - catenary.static_contact_wire_height(p)
                        for p in probes])
    history = np.array(history)
    wire = line.contact_wire
    plateau = amplitude * duration / 2 / (2 * math.sqrt(wire.tension * wire.mass_per_length))
    np.testing.assert_allclose(history[-1], plateau, rtol=1e-3)

    def crossing(y):
        i = np.flatnonzero(y >= plateau / 2)[0]
        return dt * (i + (plateau / 2 - y[i - 1]) / (y[i] - y[i - 1]))

    speed = (probes[1] - probes[0]) / (crossing(history[:, 1]) - crossing(history[:, 0]))
    assert speed == pytest.approx(wire.wave_speed, rel=0.01)


def _drive(catenary, force_of, steps, start, speed, watch=None):
    for i in range(steps):
        catenary.advance(force_of(i), start + speed * (i + 1) * catenary.time_step)
        if watch is not None:
            watch(catenary)


def test_energy_is_conserved_exactly_without_damping_while_droppers_stay_taut(reference_line):
    catenary = Catenary(short_line(reference_line), time_step=1e-3, damping=False,
                        element_length=0.5)
    slack = []
    _drive(catenary, lambda i: 20.0 * (1 + 0.5 * math.sin(0.04 * i)), 1500, 30.0, 70.0,
           lambda c: slack.append(np.any(c.dropper_forces() == 0.0)))
    energy = catenary.energy()
    assert not any(slack)
    assert energy["work"] > 0.1 and energy["kinetic"] > 0.01
    assert abs(energy["balance"]) < 1e-9 * energy["work"]
    assert energy["dropper_defect"] == 0.0


@pytest.mark.parametrize("damping", [False, True], ids=["undamped", "damped"])
def test_energy_balance_with_slack_droppers_is_off_only_by_the_trapezoidal_defect(
        reference_line, damping):
    """Dropper forces are piecewise linear: in a step in which one goes slack the trapezoidal
    rule misses part of its energy. The balance must equal that defect (computed separately
    from the dropper stretches) to round-off, and the defect stay small against the work."""
    catenary = Catenary(short_line(reference_line), time_step=1e-3, damping=damping,
                        element_length=0.5)
    slack = []
    _drive(catenary, lambda i: 300.0 * (1 + 0.5 * math.sin(0.04 * i)), 1500, 30.0, 70.0,
           lambda c: slack.append(np.count_nonzero(c.dropper_forces() == 0.0)))
    energy = catenary.energy()
    assert max(slack) >= 3
    assert energy["balance"] == pytest.approx(energy["dropper_defect"], abs=1e-9 * energy["work"])
    assert abs(energy["dropper_defect"]) < 0.01 * energy["work"]
    assert (energy["dissipated"] > 0.0) == damping


def test_a_strong_upward_force_at_a_dropper_slackens_it_without_compression(reference_line):
    line = short_line(reference_line)
    catenary = Catenary(line, time_step=1e-3, element_length=0.5)
    target = line.span_length + line.dropper_positions[4]  # mid-span dropper of span 2
    index = int(np.argmin(np.abs(catenary.static_state.dropper_positions - target)))
    forces = []
    for i in range(300):
        catenary.advance(min(1.0, (i + 1) / 50) * 400.0, target)
        forces.append(catenary.dropper_forces())
    forces = np.array(forces)
    assert forces.min() >= 0.0
    assert forces[-1, index] == 0.0  # exactly zero, not a small negative number
    assert catenary.dropper_stretches()[index] < 0.0  # it is really shorter than its length
    # the equation of motion holds with the tension-only law k max(e, 0), not with k e
    mesh, motion = catenary.mesh, catenary.motion()
    u, v, a = motion["displacement"], motion["velocity"], motion["acceleration"]
    e0 = catenary.static_state.dropper_elongations
    stretch = e0 + mesh.dropper_matrix @ u
    damping = line.rayleigh_alpha * mesh.mass * v + line.rayleigh_beta * (
        mesh.stiffness_structure @ v)
    load = np.zeros(mesh.unknowns)
    load[2 * (int(round(target / mesh.element_length)) - 1)] = 400.0

    def residual(dropper_force):
        return (mesh.mass * a + damping + mesh.stiffness_structure @ u
                + mesh.dropper_matrix.T @ (dropper_force - mesh.dropper_stiffness * e0) - load)

    tension_only = mesh.dropper_stiffness * np.maximum(stretch, 0.0)
    assert np.abs(residual(tension_only)).max() < 1e-8 * 400.0
    assert np.abs(residual(mesh.dropper_stiffness * stretch)).max() > 1.0


def test_static_slack_solution_matches_a_direct_solve_without_that_dropper(reference_line):
    """Active-set/Woodbury path against a plain sparse solve of K with the slack dropper taken out
    (its preload then also disappears from the load)."""
    line = short_line(reference_line)
    catenary = Catenary(line, time_step=1e-3, element_length=0.5)
    mesh = catenary.mesh
    target = line.span_length + line.dropper_positions[4]
    force = 400.0
    uplift = catenary.static_uplift(force, target)
    index = int(np.argmin(np.abs(catenary.static_state.dropper_positions - target)))
    b = mesh.dropper_matrix[index]
    k, e0 = mesh.dropper_stiffness[index], catenary.static_state.dropper_elongations[index]
    stiffness = (mesh.stiffness_linear() - k * (b.T @ b)).tocsc()
    load = np.zeros(mesh.unknowns)
    j = int(round(target / mesh.element_length))
    load[2 * (j - 1)] = force
    load += k * e0 * b.toarray().ravel()  # the slack dropper no longer pulls the wires together
    direct = spsolve(stiffness, load)
    np.testing.assert_allclose(uplift[1:-1], direct[0::2], atol=1e-9)
    assert e0 + (b @ direct)[0] < 0.0  # consistent: that dropper is indeed compressed
    others = np.delete(np.arange(mesh.dropper_matrix.shape[0]), index)
    stretch = catenary.static_state.dropper_elongations + mesh.dropper_matrix @ direct
    assert np.all(stretch[others] >= 0.0)


# --- interface and convergence ------------------------------------------------------------------
def test_reset_restores_the_prestate_and_runs_repeat_exactly(reference_line):
    catenary = Catenary(short_line(reference_line), time_step=1e-3, element_length=0.5)
    runs = []
    for _ in range(2):
        catenary.reset()
        assert catenary.time == 0.0
        _drive(catenary, lambda i: 120.0, 300, 50.0, 69.4)
        runs.append((catenary.time, catenary.contact_wire_height(75.0),
                     catenary.support_uplift().copy()))
    assert runs[0][0] == pytest.approx(0.3)
    assert runs[0][1] == runs[1][1] and np.array_equal(runs[0][2], runs[1][2])
    assert catenary.support_uplift()[[0, -1]].tolist() == [0.0, 0.0]  # pinned ends
    with pytest.raises(ValueError, match="outside the line"):
        catenary.advance(120.0, catenary.length + 1.0)
    with pytest.raises(ValueError, match="time_step"):
        Catenary(reference_line, time_step=0.0)


def _moving_force_history(line, element_length, time_step):
    """Contact-wire uplift under 120 N moving at 250 km/h over a three-span line, every 2 ms."""
    catenary = Catenary(line, time_step=time_step, element_length=element_length)
    speed = 250 / 3.6
    steps = int(round(0.002 / time_step))
    out = []
    for i in range(int(round(2.4 / time_step))):
        x = 5.0 + speed * (i + 1) * time_step
        catenary.advance(120.0, x)
        if (i + 1) % steps == 0:
            out.append(catenary.contact_wire_height(x) - catenary.static_contact_wire_height(x))
    return np.array(out)


def test_mesh_and_time_step_refinement_reduce_the_error(reference_line):
    line = short_line(reference_line)
    finest = _moving_force_history(line, 0.25, 5e-4)
    mesh_errors = [np.abs(_moving_force_history(line, h, 5e-4) - finest).max() for h in (1.0, 0.5)]
    step_errors = [np.abs(_moving_force_history(line, 0.25, dt) - finest).max()
                   for dt in (2e-3, 1e-3)]
    assert mesh_errors[1] < mesh_errors[0]
    assert step_errors[1] < step_errors[0]


# --- the step against the textbook formulation -------------------------------------------------
class _TextbookNewmark:
    """The average-acceleration step written out as in the textbook, with a dense LU solve:
    (K + 2/dt C + 4/dt^2 M) u' = f + M (4/dt^2 u + 4/dt v + a) + C (2/dt u + v)."""

    def __init__(self, mesh, line, dt):
        from scipy.linalg import lu_factor

        self.dt, self.mass = dt, mesh.mass
        self.damping = (line.rayleigh_alpha * sparse.diags(mesh.mass)
                        + line.rayleigh_beta * mesh.stiffness_structure).tocsr()
        matrix = (mesh.stiffness_linear() + 2 / dt * self.damping
                  + 4 / dt**2 * sparse.diags(mesh.mass)).toarray()
        self.factor = lu_factor(matrix)

    def step(self, state, load):
        from scipy.linalg import lu_solve

        (u, v, a), dt = state, self.dt
        rhs = (load + self.mass * (4 / dt**2 * u + 4 / dt * v + a)
               + self.damping @ (2 / dt * u + v))
        new = lu_solve(self.factor, rhs)
        velocity = 2 / dt * (new - u) - v
        return new, velocity, 2 / dt * (velocity - v) - a


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_each_step_equals_the_dense_textbook_step(reference_line, compiled, monkeypatch):
    """Every step of the integrator, from its own current state, against a dense solve of the
    textbook Newmark equations (droppers taut throughout, so the system is linear)."""
    from panto.catenary_cosim import kernel

    monkeypatch.setenv(kernel.SWITCH_VARIABLE, "1" if compiled else "0")
    line = short_line(reference_line)
    dt = 1e-3
    catenary = Catenary(line, time_step=dt, element_length=1.0)
    if compiled and kernel.load_library() is None:
        pytest.skip("no C compiler: the compiled kernel is not available")
    assert catenary._integrator.backend == ("compiled" if compiled else "numpy")
    mesh = catenary.mesh
    textbook = _TextbookNewmark(mesh, line, dt)
    worst = {"displacement": 0.0, "velocity": 0.0, "acceleration": 0.0}
    for i in range(300):
        motion = catenary.motion()
        state = (motion["displacement"], motion["velocity"], motion["acceleration"])
        force, x = 50.0 * (1 + 0.5 * math.sin(0.05 * i)), 20.0 + 69.4 * (i + 1) * dt
        index, value = catenary._load(force, x)
        load = np.zeros(mesh.unknowns)
        load[index] = value
        expected = textbook.step(state, load)
        catenary.advance(force, x)
        assert catenary.dropper_forces().min() > 0.0
        got = catenary.motion()
        for name, reference in zip(worst, expected):
            error = np.abs(got[name] - reference).max() / np.abs(reference).max()
            worst[name] = max(worst[name], error)
    assert worst["displacement"] < 1e-12
    # v and a are differences of displacements (divided by dt): a few more digits cancel
    assert worst["velocity"] < 1e-10 and worst["acceleration"] < 1e-8


def test_compiled_and_numpy_steps_agree_with_slack_droppers(reference_line, monkeypatch):
    """The two implementations of the step over 400 steps in which droppers go slack and taut
    again: the same motion, forces and energies to round-off."""
    from panto.catenary_cosim import kernel

    if kernel.load_library() is None:
        pytest.skip("no C compiler: the compiled kernel is not available")
    runs = []
    for switch in ("1", "0"):
        monkeypatch.setenv(kernel.SWITCH_VARIABLE, switch)
        catenary = Catenary(short_line(reference_line), time_step=1e-3, element_length=0.5)
        slack = []
        _drive(catenary, lambda i: 300.0 * (1 + 0.5 * math.sin(0.04 * i)), 400, 30.0, 70.0,
               lambda c: slack.append(np.count_nonzero(c.dropper_forces() == 0.0)))
        runs.append((catenary._integrator.backend, max(slack), catenary.motion(),
                     catenary.dropper_forces(), catenary.energy()))
    (first, slack_a, motion_a, forces_a, energy_a), (second, slack_b, motion_b, forces_b,
                                                      energy_b) = runs
    assert (first, second) == ("compiled", "numpy") and slack_a >= 3 and slack_b >= 3
    u = motion_b["displacement"]
    assert np.abs(motion_a["displacement"] - u).max() < 1e-10 * np.abs(u).max()
    np.testing.assert_allclose(forces_a, forces_b, rtol=0, atol=1e-8 * forces_b.max())
    for key in ("kinetic", "potential", "dissipated", "work"):
        assert energy_a[key] == pytest.approx(energy_b[key], rel=1e-9)
