"""The distribution installs one import name, ``panto``, and every package folder is in the wheel."""
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETUPTOOLS = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _folder(package: str) -> Path:
    """The folder a dotted package name maps to (longest package-dir prefix)."""
    mapping = SETUPTOOLS["package-dir"]
    parts = package.split(".")
    for cut in range(len(parts), 0, -1):
        prefix = ".".join(parts[:cut])
        if prefix in mapping:
            return ROOT / mapping[prefix] / Path(*parts[cut:])
    raise AssertionError(f"{package} has no package-dir entry")


def test_every_package_is_under_the_one_namespace():
    assert all(p == "panto" or p.startswith("panto.") for p in SETUPTOOLS["packages"])
    assert all(p == "panto" or p.startswith("panto.") for p in SETUPTOOLS["package-dir"])


def test_every_package_folder_is_listed_and_every_listed_package_exists():
    listed = set(SETUPTOOLS["packages"])
    for package in listed:
        assert (_folder(package) / "__init__.py").is_file(), package
    found = set()
    for top, folder in SETUPTOOLS["package-dir"].items():
        for init in (ROOT / folder).rglob("__init__.py"):
            relative = init.parent.relative_to(ROOT / folder).parts
            found.add(".".join((top,) + relative))
    assert found == listed, f"not in pyproject's packages: {sorted(found - listed)}"



def test_every_package_re_exports_its_public_api_and_each_name_resolves():
    import importlib

    for name in SETUPTOOLS["packages"]:
        if name == "panto":  # the command line's folder: lazy_exports itself
            continue
        package = importlib.import_module(name)
        assert package.__all__, f"{name} exports nothing"
        for attribute in package.__all__:
            value = getattr(package, attribute)
            assert not isinstance(value, type(package)), f"{name}.{attribute} is a module"
