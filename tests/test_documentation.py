"""Every public module, class and function is documented, and the examples in the docs run."""
import doctest
import importlib
import inspect
import pkgutil

import pytest

PACKAGES = ("panto.fmu_src", "panto.build_fmu", "panto.catenary_cosim", "panto.rig",
            "panto.video_sync", "panto.identification", "panto")


def _modules():
    for package in PACKAGES:  # subpackages too (identification's trades)
        yield package
        for info in pkgutil.walk_packages(importlib.import_module(package).__path__, package + "."):
            yield info.name


MODULES = sorted(set(_modules()))


def test_every_public_module_class_and_function_has_a_docstring():
    missing = []
    for name in MODULES:
        module = importlib.import_module(name)
        if not (module.__doc__ or "").strip():
            missing.append(name)
        for attribute, value in vars(module).items():
            if attribute.startswith("_") or getattr(value, "__module__", None) != name:
                continue
            if (inspect.isfunction(value) or inspect.isclass(value)) and \
                    not (value.__doc__ or "").strip():
                missing.append(f"{name}.{attribute}")
    assert not missing, f"undocumented: {missing}"


@pytest.mark.parametrize("name", [m for m in MODULES
                                  if ">>>" in (inspect.getsource(importlib.import_module(m)))])
def test_the_examples_in_the_docstrings_run(name):
    result = doctest.testmod(importlib.import_module(name), verbose=False,
                             optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0
