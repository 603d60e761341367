"""The warm paths from the symbolic model import neither SymPy nor scipy.signal (issue 23):
what replaces them must agree with them. Cached functions run in the namespace lambdify would
give them (fmu_src/numeric.py ``_namespace``); the pantograph's default parameters read from the
cache of the static functions are the model's (linearisation.default_parameter_set); the
compiled first-order filter of every mode (static_kernel.first_order_filter) gives
scipy.signal.lfilter's values bit for bit, its accumulation into the states NumPy's, on random
filters and on the physical-linear structure's runs; and a process reading a warm cache runs the structure without either import."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy import signal

from panto.fmu_src import numeric
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures import linearisation as lin
from panto.identification.structures import registry, static_kernel


def test_cached_functions_run_in_the_namespace_lambdify_gives():
    import sympy as sp

    lambdified = dict(sp.lambdify((), 0.0, modules="math").__globals__)
    lambdified.pop("__builtins__")
    written = numeric._namespace()
    assert written.keys() == lambdified.keys()
    assert all(written[name] is lambdified[name] or written[name] == lambdified[name]
               for name in written)


def test_the_cached_default_parameters_are_the_models():
    from panto.fmu_src.models import default_parameters
    from panto.fmu_src.pantograph import PHI1_SEARCH_RANGE

    model = default_parameters("Pantograph")
    cached = lin.default_parameter_set()
    assert cached.specs == model.specs and cached.model == model.model
    names, vector = lin.parameter_defaults()
    assert names == model.names and np.array_equal(vector, model.vector())
    assert lin.static_functions()["phi1_search_range"] == PHI1_SEARCH_RANGE


def _lfilter(lam, drive, z0):
    z = np.empty(len(drive) + 1, complex)
    z[0] = z0
    z[1:], _ = signal.lfilter([1.0], [1.0, -lam], drive, zi=[lam * z0])
    return z


def _compiled_filter():
    if static_kernel.first_order_filter(0.5, np.zeros(1, complex), 0j) is None:
        pytest.skip("no C compiler (or PANTO_STATIC_KERNEL=0): lfilter runs")


def test_the_compiled_filter_is_lfilter_bit_for_bit():
    _compiled_filter()
    rng = np.random.default_rng(5)
    for trial in range(60):
        radius = rng.uniform(0.3, 0.99999)
        angle = 0.0 if trial % 3 == 0 else rng.uniform(-np.pi, np.pi)  # real modes too
        lam = radius * np.exp(1j * angle)
        n = 50_000 if trial == 1 else int(rng.integers(2, 3000))
        drive = (rng.normal(size=n) + 1j * rng.normal(size=n)) * 10.0 ** rng.uniform(-6, 3)
        z0 = complex(rng.normal(), rng.normal())
        assert np.array_equal(static_kernel.first_order_filter(lam, drive, z0),
                              _lfilter(lam, drive, z0)), trial


def test_the_compiled_accumulation_is_numpys_bit_for_bit():
    """``states += w (outer(Re z, Re v) - outer(Im z, Im v))`` by the compiled loop and by
    NumPy, on random modes of every scale, onto states that already hold other modes."""
    _compiled_filter()
    rng = np.random.default_rng(6)
    for trial in range(40):
        rows, cols = int(rng.integers(1, 4000)), int(rng.integers(1, 25))
        z = (rng.normal(size=rows) + 1j * rng.normal(size=rows)) * 10.0 ** rng.uniform(-8, 4)
        v = rng.normal(size=cols) + 1j * rng.normal(size=cols)
        if trial % 4 == 0:  # a real mode: eig's vectors then come as a real array
            v = v.real.copy()
        weight = 2.0 if trial % 2 else 1.0
        start = rng.normal(size=(rows, cols)) * 10.0 ** rng.uniform(-6, 3)
        compiled, expected = start.copy(), start.copy()
        assert static_kernel.accumulate_mode(compiled, z, v, weight)
        expected += weight * (np.outer(z.real, v.real) - np.outer(z.imag, v.imag))
        assert np.array_equal(compiled, expected), trial
    assert not static_kernel.accumulate_mode(np.zeros((3, 2), order="F"), np.zeros(3, complex),
                                             np.zeros(2, complex), 1.0)


def _run(n: int, seed: int) -> IdentificationData:
    """A rig-shaped run: a wandering wire height, a pressure with a slow sine and noise."""
    rng = np.random.default_rng(seed)
    time = np.arange(n) * 0.02
    eta = 2.0 + 0.01 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n)
    pressure = 4.0 + 0.5 * np.sin(2 * np.pi * 0.3 * time) + 0.1 * rng.standard_normal(n)
    inputs = np.column_stack([eta, pressure])
    outputs = np.column_stack([100.0 + 5.0 * pressure, eta - 0.01])
    return IdentificationData(time, inputs, outputs, ("eta", "p"), ("F_c", "y_cb"), source="rig")


def test_the_physical_linear_runs_are_those_of_lfilter(monkeypatch):
    _compiled_filter()
    for n, seed in ((400, 3), (30_000, 4)):
        data = _run(n, seed)
        model = registry.build_structure("physical-linear", data, {})
        for scale in (1.0, 1.3):
            values = {k: v * scale for k, v in model.nominal().items()}
            compiled = model.simulate(values, data)
            with monkeypatch.context() as patch:  # the fallbacks: lfilter, NumPy's outer
                patch.setattr(static_kernel, "first_order_filter", lambda *args: None)
                patch.setattr(static_kernel, "accumulate_mode", lambda *args: False)
                assert np.array_equal(model.simulate(values, data), compiled), (n, scale)


_WARM_RUN = """
import json, sys
import numpy as np
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures import linearisation as lin, registry
n = 200
time = np.arange(n) * 0.02
inputs = np.column_stack([np.full(n, 2.0), 4.0 + 0.1 * np.sin(time)])
data = IdentificationData(time, inputs, np.column_stack([inputs[:, 1], inputs[:, 0]]),
                          ("eta", "p"), ("F_c", "y_cb"), source="rig")
model = registry.build_structure("physical-linear", data, {})
y = model.simulate(model.nominal(), data)
lin.linearise(lin.parameter_defaults()[1], (1.8, 4.0))
print(json.dumps({"origin": lin.load_static_functions()[1], "finite": bool(np.isfinite(y).all()),
                  "modules": sorted(m for m in sys.modules if m.split(".")[0] == "sympy"
                                    or m.startswith("scipy.signal"))}))
"""


def test_a_warm_process_imports_neither_sympy_nor_scipy_signal():
    if lin.load_static_functions()[1] != "cache":  # this process derived them: now stored?
        if lin.load_static_functions()[1] != "cache":
            pytest.skip("the cache folder cannot be written")
    lin.compiled()  # the libraries built, as a warm process finds them
    filter_compiled = static_kernel.first_order_filter(0.5, np.zeros(1, complex), 0j) is not None
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    out = json.loads(subprocess.run([sys.executable, "-c", _WARM_RUN], capture_output=True,
                                    text=True, env=env, check=True).stdout)
    assert out["origin"] == "cache" and out["finite"]
    assert not [m for m in out["modules"] if m.split(".")[0] == "sympy"]
    if filter_compiled:
        assert not [m for m in out["modules"] if m.startswith("scipy.signal")]
