"""The cache of compiled (and derived) models: same numbers as a fresh compile, safe keys.

The pantograph takes ~20 s to compile, so these tests use the two-mass oscillator and a small
slider model with a dependent quantity and a guard (the features the pantograph adds).
"""
import dataclasses
import subprocess
import sys

import numpy as np
import pytest
import sympy as sp

from panto.fmu_src.models import default_parameters, symbolic_model
from panto.fmu_src.numeric import ModelEvaluationError, NumericModel, cache_key, read_cached_functions
from panto.fmu_src.spec import ParameterSpec, Variable
from panto.fmu_src.symbolic import (Dependent, Guard, MechanicalModel, cached_derivation,
                                    lagrangian_forces, source_digest)


def slider_model() -> MechanicalModel:
    """A mass on a spring carrying a rod of length L whose end height s = sqrt(L^2 - x^2)."""
    x, v, u, s = (sp.Symbol(n, real=True) for n in ("x", "v", "u", "s"))
    m, m_r, k, c, g, length = (sp.Symbol(n, real=True) for n in ("m", "m_r", "k", "c", "g", "L"))
    ds = -x / s
    dependents = (Dependent(s, sp.sqrt(length**2 - x**2), {x: ds}),)
    mass = sp.Matrix([[m + m_r * ds**2]])
    d_mass = [mass.applyfunc(lambda e: e.diff(x) + e.diff(s) * ds)]
    generalised = sp.Matrix([-k * x - c * v + u - m_r * g * ds])
    forces = lagrangian_forces(mass, generalised, [v], d_mass)
    energy = (mass[0, 0] * v**2 / 2 + k * x**2 / 2 + m_r * g * s - u * x)
    params = tuple(ParameterSpec(n, val, "1", n) for n, val in
                   (("m", 2.0), ("m_r", 0.5), ("k", 400.0), ("c", 3.0), ("g", 9.81), ("L", 1.0)))
    return MechanicalModel(
        name="CacheSlider", description="test model", coordinates=(Variable("x", "m", "x"),),
        velocities=(Variable("v", "m/s", "v"),), inputs=(Variable("u", "N", "force"),),
        outputs=(Variable("s", "m", "rod end"), Variable("x_out", "m", "x")), parameters=params,
        mass_matrix=mass, forces=forces, output_expressions=sp.Matrix([s, x]),
        dependents=dependents, guards=(Guard(length**2 - x**2, "rod too short at x = {x}"),),
        energy=energy)


def _evaluations(numeric: NumericModel, p, x, u):
    """Everything a user evaluates: derivatives, Jacobians, outputs, energy, equilibrium."""
    x0 = numeric.equilibrium(p, u)
    return [numeric.derivatives(p, x, u), *numeric.jacobians(p, x, u), numeric.outputs(p, x, u),
            np.array([numeric.energy(p, x, u)]), x0, numeric.linearise(p, x0, u).A]


@pytest.mark.parametrize("make", [slider_model, lambda: symbolic_model("TwoMass")],
                         ids=["slider", "TwoMass"])
def test_cached_model_matches_fresh_compile(tmp_path, make):
    model = make()
    rng = np.random.default_rng(7)
    if model.name == "TwoMass":
        p = default_parameters("TwoMass").vector()
        x, u = rng.normal(0, 1e-2, 4), (0.01, 3.0)
    else:
        p = [par.value for par in model.parameters]
        x, u = rng.uniform(-0.5, 0.5, 2), (rng.uniform(-20, 20),)
    fresh = NumericModel(model, cache_dir=False)
    first = NumericModel(model, cache_dir=tmp_path)
    reference = _evaluations(fresh, p, x, u)
    assert len(_evaluations(first, p, x, u)) == len(reference) and first.source == "compiled"
    cached = NumericModel(model, cache_dir=tmp_path)
    values = _evaluations(cached, p, x, u)
    assert cached.source == "cache"
    for got, want in zip(values, reference):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)


def test_slider_physics_through_the_cache(tmp_path):
    """Equilibrium k x = u + m_r g x / s, and the guard still refuses |x| > L."""
    model = slider_model()
    NumericModel(model, cache_dir=tmp_path)._functions
    numeric = NumericModel(model, cache_dir=tmp_path)
    p = [par.value for par in model.parameters]
    x0 = numeric.equilibrium(p, (10.0,))[0]
    s0 = np.sqrt(1.0 - x0**2)
    assert numeric.source == "cache"
    assert 400.0 * x0 == pytest.approx(10.0 + 0.5 * 9.81 * x0 / s0, rel=1e-10)
    with pytest.raises(ModelEvaluationError, match="rod too short"):
        numeric.dependents(p, [1.5])


def test_changed_expression_changes_the_key():
    model = slider_model()
    k = sp.Symbol("k", real=True)
    same = dataclasses.replace(model, forces=sp.Matrix(model.forces))
    stiffer = dataclasses.replace(model, forces=model.forces.applyfunc(lambda e: e.subs(k, 2 * k)))
    longer = dataclasses.replace(model, dependents=(dataclasses.replace(
        model.dependents[0], expression=model.dependents[0].expression + sp.Rational(1, 10**6)),))
    keys = {cache_key(model), cache_key(stiffer), cache_key(longer)}
    assert cache_key(same) == cache_key(model)
    assert len(keys) == 3


def test_key_is_the_same_in_another_process():
    code = ("from panto.fmu_src.models import symbolic_model; "
            "from panto.fmu_src.numeric import cache_key; print(cache_key(symbolic_model('TwoMass')))")
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert other.stdout.strip() == cache_key(symbolic_model("TwoMass"))


def test_corrupted_cache_file_is_rebuilt(tmp_path):
    model = slider_model()
    NumericModel(model, cache_dir=tmp_path)._functions
    (path,) = tmp_path.glob("CacheSlider-*.bin")
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one flipped byte in the payload
    path.write_bytes(bytes(data))
    assert read_cached_functions(path, cache_key(model)) is None
    rebuilt = NumericModel(model, cache_dir=tmp_path)
    p = [par.value for par in model.parameters]
    np.testing.assert_allclose(rebuilt.derivatives(p, [0.1, 0.2], (1.0,)),
                               NumericModel(model, cache_dir=False).derivatives(p, [0.1, 0.2], (1.0,)),
                               rtol=1e-12)
    assert rebuilt.source == "compiled"
    assert read_cached_functions(path, cache_key(model)) is not None
    path.write_bytes(path.read_bytes()[:100])  # truncated
    assert NumericModel(model, cache_dir=tmp_path)._functions and read_cached_functions(
        path, cache_key(model)) is not None


def test_corrupted_derivation_cache_is_derived_again(tmp_path):
    calls = []

    def derive():
        calls.append(1)
        return slider_model()

    first = cached_derivation("CacheSlider", derive, tmp_path)
    path = tmp_path / f"CacheSlider-{source_digest()}.model.pickle"
    assert path.exists() and len(calls) == 1
    path.write_bytes(path.read_bytes()[:-5] + b"xxxxx")
    from panto.fmu_src import symbolic
    symbolic._DERIVED.clear()
    again = cached_derivation("CacheSlider", derive, tmp_path)
    assert len(calls) == 2 and again == first
    symbolic._DERIVED.clear()
    third = cached_derivation("CacheSlider", derive, tmp_path)
    assert len(calls) == 2 and third == first and cache_key(third) == cache_key(first)


def test_prune_keeps_the_newest_files_of_one_model(tmp_path):
    import os

    from panto.fmu_src.symbolic import prune
    for age in range(6):
        path = tmp_path / f"Model-{age}.bin"
        path.write_bytes(b"x")
        os.utime(path, (1e9 - age * 100, 1e9 - age * 100))
    (tmp_path / "Other-9.bin").write_bytes(b"x")
    prune(tmp_path, "Model-*.bin", keep=4)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "Model-0.bin", "Model-1.bin", "Model-2.bin", "Model-3.bin", "Other-9.bin"]
