"""The shared loader of the compiled kernels (:class:`panto.fmu_src.c_kernels.Kernel`)."""
import ctypes

import pytest

from panto.fmu_src import c_kernels

SOURCE = "double square_sum(double a, double b) { return a * a + b * b; }\n"


def _typed(library):
    function = library.square_sum
    function.restype = ctypes.c_double
    function.argtypes = [ctypes.c_double, ctypes.c_double]
    return function


@pytest.mark.skipif(c_kernels.find_compiler() is None, reason="no C compiler")
def test_a_kernel_builds_from_a_file_binds_and_computes(tmp_path, monkeypatch):
    """Built from its source file into the cache folder of the source's hash, typed by `bind`."""
    monkeypatch.setenv(c_kernels.CACHE_VARIABLE, str(tmp_path / "cache"))
    path = tmp_path / "square.c"
    path.write_text(SOURCE)
    kernel = c_kernels.Kernel("square_sum", "PANTO_TEST_KERNEL", ("-O2",), path, _typed)
    function = kernel.load()
    assert function(3.0, 4.0) == 25.0
    assert (c_kernels.cache_folder(SOURCE, ("-O2",)) / "square_sum.so").is_file()
    assert c_kernels.cache_folder(SOURCE, ("-O1",)) != c_kernels.cache_folder(SOURCE, ("-O2",))
    assert c_kernels.Kernel("none", "PANTO_TEST_KERNEL").load() is None  # no source at all
    assert kernel.load(SOURCE + "\n")(1.5, 2.0) == 6.25  # a source given per call
    missing = c_kernels.Kernel("absent", "PANTO_TEST_KERNEL", source=SOURCE,
                               bind=lambda library: library.no_such_function)
    assert missing.load() is None  # not our library: None, not AttributeError


def test_no_source_or_no_compiler_gives_none_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv(c_kernels.CACHE_VARIABLE, str(tmp_path / "cache"))
    unreadable = c_kernels.Kernel("gone", "PANTO_TEST_KERNEL", source=tmp_path / "gone.c")
    assert unreadable.load() is None
    compilerless = c_kernels.Kernel("square_sum", "PANTO_TEST_KERNEL", source=SOURCE + "/**/",
                                    bind=_typed, find=lambda: None)
    assert compilerless.load() is None
    assert not (tmp_path / "cache").exists()


@pytest.mark.parametrize("value, on", [("0", False), ("off", False), (" No ", False),
                                       ("false", False), ("1", True), ("", True), (None, True)])
def test_the_switch_reads_the_environment(monkeypatch, value, on):
    if value is None:
        monkeypatch.delenv("PANTO_TEST_KERNEL", raising=False)
    else:
        monkeypatch.setenv("PANTO_TEST_KERNEL", value)
    assert c_kernels.Kernel("any", "PANTO_TEST_KERNEL").enabled() is on
