"""The pantograph at rest from the disk cache (identification/structures/linearisation.py,
``load_static_functions``; fmu_src/numeric.py, ``cached_functions``; static_kernel.kernel_source):
functions executed from the stored source must be those derived in SymPy, bit for bit, and still
translate into the same C; a corrupted, stale or unwritable cache is passed over, and a change of
the model sources (or of the code generating the functions) gives another key."""
from __future__ import annotations

import hashlib
import inspect
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from panto.fmu_src import numeric, symbolic
from panto.fmu_src.pantograph import PHI1_SEARCH_RANGE
from panto.identification.structures import linearisation as lin
from panto.identification.structures import static_kernel

FUNCTIONS = ("phi2", "phi3", "reach", "height", "balance", "linear")
SIZES = (len(lin.parameter_defaults()[0]), 3, 2)


def normalised(source: str) -> str:
    """`source` with lambdify's argument placeholders ``_Dummy_<n>`` renamed by their order of
    appearance: ``n`` counts the placeholders the process made before (other tests, other
    models), so only the names differ between processes, never an operation."""
    import re

    names: dict[str, str] = {}
    return re.sub(r"_Dummy_\d+", lambda m: names.setdefault(m.group(0), f"_arg{len(names)}"),
                  source)


def _digest_of_sources(functions) -> str:
    return hashlib.sha256("".join(normalised(inspect.getsource(functions[k]))
                                  for k in FUNCTIONS).encode()).hexdigest()


@pytest.fixture(scope="module")
def fresh():
    return lin.derive_static_functions()


@pytest.fixture(scope="module")
def stored(fresh, tmp_path_factory):
    """A cache folder written from `fresh`, and the functions read back from it."""
    folder = tmp_path_factory.mktemp("static")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lin, "derive_static_functions", lambda: fresh)
        first, origin = lin.load_static_functions(folder)
        assert origin == "compiled" and first is fresh
        cached, origin = lin.load_static_functions(folder)
    assert origin == "cache" and cached is not fresh
    return folder, cached


def _points(functions):
    """(p, q, u) where the linkage closes: parameters moved by 3 %, a spread of phi1, delta."""
    rng = np.random.default_rng(11)
    defaults = lin.parameter_defaults()[1]
    points = []
    for eta, pressure in ((1.2, 3.0), (1.8, 4.0), (2.4, 5.5)):
        p = list(defaults * (1.0 + rng.normal(0.0, 0.03, defaults.size)))
        for phi1 in np.linspace(*PHI1_SEARCH_RANGE, 40):
            q = [float(phi1), float(rng.normal(0.0, 1e-3)), eta + float(rng.normal(0.0, 0.01))]
            if functions["reach"](p, q) >= 0.0:
                points.append((p, q, [eta, pressure]))
    return points[::7]


def _values(functions, p, q, u):
    phi2 = functions["phi2"](p, q)
    angles = [phi2, functions["phi3"](p, q, phi2)]
    return [functions["reach"](p, q), angles, functions["height"](p, q, angles),
            functions["balance"](p, q, u, angles), functions["linear"](p, q, u, angles)]


def test_cached_functions_give_the_derived_values_bit_for_bit(fresh, stored):
    _, cached = stored
    assert cached["static_parameters"] == fresh["static_parameters"]
    for name in FUNCTIONS:
        assert inspect.getsource(cached[name]) == inspect.getsource(fresh[name]), name
    points = _points(fresh)
    assert len(points) >= 6
    for p, q, u in points:
        new, old = _values(cached, p, q, u), _values(fresh, p, q, u)
        # nested lists of Python floats: equal as bytes, so -0.0 and NaN are told apart
        assert len(_flat(new)) == 1 + 2 + 1 + (3 + 9) + (9 + 9 + 6 + 3 + 9 + 9 + 6)  # all of them
        assert np.array(_flat(new), float).tobytes() == np.array(_flat(old), float).tobytes()


def _flat(nested) -> list[float]:
    if isinstance(nested, (list, tuple)):
        return [x for item in nested for x in _flat(item)]
    return [float(nested)]


def test_another_process_derives_the_same_source(fresh):
    """The cache is written by one process and read by others: the derivation must not depend
    on the process (string hashing is randomised per process; the placeholders' numbers count
    what the process did before, see :func:`normalised`)."""
    code = (inspect.getsource(normalised) + "import hashlib, inspect\n"
            "from panto.identification.structures import linearisation as lin\n"
            "f = lin.derive_static_functions()\n"
            f"print(hashlib.sha256(''.join(normalised(inspect.getsource(f[k])) for k in "
            f"{FUNCTIONS!r}).encode()).hexdigest(), f['static_parameters'])")
    env = dict(os.environ, PYTHONHASHSEED="12345", OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True).stdout.split(maxsplit=1)
    assert out[0] == _digest_of_sources(fresh)
    assert out[1].strip() == str(fresh["static_parameters"])


def test_the_kernel_source_from_cached_functions_equals_the_fresh_one(fresh, stored, tmp_path):
    folder, cached = stored
    translated = static_kernel.kernel_source(fresh, SIZES, cache_dir=False)
    assert static_kernel.kernel_source(cached, SIZES, cache_dir=False) == translated
    assert static_kernel.kernel_source(cached, SIZES, cache_dir=tmp_path) == translated
    files = list(tmp_path.glob(f"{static_kernel.SOURCE_CACHE_STEM}-*.c"))
    assert len(files) == 1
    assert static_kernel.kernel_source(fresh, SIZES, cache_dir=tmp_path) == translated
    # a corrupted translation is made again, not compiled
    files[0].write_bytes(files[0].read_bytes()[:-10] + b"garbage!!!")
    assert static_kernel.kernel_source(cached, SIZES, cache_dir=tmp_path) == translated
    # other sizes: another file
    static_kernel.kernel_source(cached, (SIZES[0], 3, 3), cache_dir=tmp_path)
    assert len(list(tmp_path.glob(f"{static_kernel.SOURCE_CACHE_STEM}-*.c"))) == 2


def _counting(fresh, calls):
    def derive():
        calls.append(1)
        return fresh
    return derive


def test_a_corrupt_stale_or_unwritable_cache_is_derived_again(fresh, stored, tmp_path,
                                                              monkeypatch):
    folder, _ = stored
    calls: list = []
    monkeypatch.setattr(lin, "derive_static_functions", _counting(fresh, calls))
    (source,) = folder.glob(f"{lin.CACHE_STEM}-*.bin")
    key = source.name.removeprefix(f"{lin.CACHE_STEM}-").removesuffix(".bin")
    assert numeric.read_cached_functions(source, key) is not None
    assert numeric.read_cached_functions(source, "0" * 24) is None  # another key: stale
    # one flipped byte: the digest fails, nothing is executed, the functions are derived again
    target = tmp_path / "corrupt"
    target.mkdir()
    data = bytearray(source.read_bytes())
    data[len(data) // 2] ^= 0x01
    (target / source.name).write_bytes(bytes(data))
    functions, origin = lin.load_static_functions(target)
    assert origin == "compiled" and functions is fresh and len(calls) == 1
    assert lin.load_static_functions(target)[1] == "cache"  # replaced by a good file
    # a file of the same name written for another key is never taken
    stale = tmp_path / "stale"
    stale.mkdir()
    numeric.write_cached_functions(stale / source.name, "another key", fresh)
    assert lin.load_static_functions(stale)[1] == "compiled" and len(calls) == 2
    # a cache "folder" that is a file: derived, nothing raised
    blocked = tmp_path / "blocked"
    blocked.write_text("not a folder")
    assert lin.load_static_functions(blocked) == (fresh, "compiled") and len(calls) == 3


def test_a_changed_model_or_generator_gives_another_key(monkeypatch):
    """The key is read from the files, not from the derivation: an edit of the pantograph's
    equations (fmu_src/pantograph.py), of the symbolic machinery or of the module generating the
    static functions must change it."""
    generator = Path(lin.__file__)
    here = Path(symbolic.__file__).resolve().parent

    def key():
        symbolic.source_digest.cache_clear()
        numeric._code_digest.cache_clear()
        return numeric.source_cache_key(generator)

    original = key()
    read_bytes = Path.read_bytes
    try:
        for edited in (here / "pantograph.py", here / "symbolic.py", generator.resolve()):
            def patched(path, edited=edited):
                data = read_bytes(path)
                return data + b"\n# edited\n" if Path(path).resolve() == edited else data
            monkeypatch.setattr(Path, "read_bytes", patched)
            assert key() != original, edited.name
            monkeypatch.setattr(Path, "read_bytes", read_bytes)
        assert key() == original
    finally:
        monkeypatch.undo()
        symbolic.source_digest.cache_clear()
        numeric._code_digest.cache_clear()
