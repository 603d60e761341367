"""The library's import structure: no import cycles, and the layers (``docs/architecture.md``).

The module graph is read from the source with :mod:`ast`, imports inside functions included (an import
moved into a function still closes a circle, it only hides it until run time). Run this file as a
script to print the graph's cycles and layer violations.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

# installed name -> folder (the pyproject package-dir mapping)
PACKAGES = {"panto": "panto", "panto.fmu_src": "fmu_src", "panto.build_fmu": "build_fmu",
            "panto.catenary_cosim": "catenary_cosim", "panto.rig": "rig",
            "panto.video_sync": "video_sync", "panto.identification": "identification"}

# (importing package, imported package, why not): prefixes of module names
LAYER_RULES = [
    ("panto.identification.estimation", "panto.identification.structures",
     "estimation is the lowest layer of identification"),
    ("panto.identification.estimation", "panto.identification.design",
     "estimation is the lowest layer of identification"),
    ("panto.identification.estimation", "panto.identification.diagnosis",
     "estimation is the lowest layer of identification"),
    ("panto.identification.estimation", "panto.identification.data",
     "estimation is the lowest layer of identification"),
    *[("panto.identification.data", f"panto.identification.{trade}",
       "data sits below the structures and their uses") for trade in
      ("structures", "design", "diagnosis")],
    ("panto.identification.structures", "panto.identification.design",
     "structures sit below design"),
    ("panto.identification.structures", "panto.identification.diagnosis",
     "structures sit below diagnosis"),
    ("panto.identification.design", "panto.identification.diagnosis",
     "design and diagnosis do not build on each other"),
    ("panto.identification.diagnosis", "panto.identification.design",
     "design and diagnosis do not build on each other"),
    *[("panto.fmu_src", other, "fmu_src is the single source of the models; it imports no other package")
      for other in PACKAGES if other not in ("panto", "panto.fmu_src")],
    # the flow of docs/architecture.md: fmu_src -> build_fmu -> {catenary_cosim, rig} -> video_sync
    # -> identification; no package imports one later in the flow, nor its sibling
    *[(source, later, "data flows one way (docs/architecture.md)")
      for source, laters in {
          "panto.build_fmu": ("panto.catenary_cosim", "panto.rig", "panto.video_sync",
                              "panto.identification"),
          "panto.catenary_cosim": ("panto.rig", "panto.video_sync", "panto.identification"),
          "panto.rig": ("panto.catenary_cosim", "panto.video_sync", "panto.identification"),
          "panto.video_sync": ("panto.catenary_cosim", "panto.identification"),
      }.items() for later in laters],
]
COMMAND_LINE = ("panto.cli", "panto.commands_", "panto.demo")


def library_modules() -> dict[str, Path]:
    """Every module of the library by its installed name (packages by their ``__init__``)."""
    modules = {}
    for package, folder in PACKAGES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            if package == "panto" and len(parts) > 1:
                continue  # only panto/*.py; the other folders are packages of their own
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join((package, *parts))] = path
    return modules


def _imported_names(tree: ast.AST, module: str, is_package: bool) -> list[tuple[str, int]]:
    """Absolute names imported anywhere in `tree` (function bodies included), with line numbers."""
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".")
                anchor = anchor[:len(anchor) - node.level + (1 if is_package else 0)]
                base = ".".join(anchor + ([base] if base else []))
            names += [(f"{base}.{alias.name}", node.lineno) for alias in node.names]
            names.append((base, node.lineno))
    return names


def import_graph() -> dict[str, dict[str, int]]:
    """Module -> {imported library module: first line}; ``from a import b`` counts as importing
    ``a.b`` when that is a module, else ``a``."""
    modules = library_modules()
    graph: dict[str, dict[str, int]] = {}
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        edges: dict[str, int] = {}
        for name, line in _imported_names(tree, module, path.name == "__init__.py"):
            if name in modules and name != module:
                edges.setdefault(name, line)
        # ``from a import b`` adds both ``a.b`` and ``a``; keep ``a`` only when b is not a module
        for name in list(edges):
            children = [other for other in edges if other.startswith(name + ".")]
            if children and not _imports_names_from(tree, name, modules):
                del edges[name]
        graph[module] = edges
    return graph


def _imports_names_from(tree: ast.AST, package: str, modules: dict[str, Path]) -> bool:
    """Whether `tree` imports from `package` a name that is not one of its modules (or imports
    the package itself)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name == package for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and node.module == package and any(
                f"{package}.{a.name}" not in modules for a in node.names):
            return True
    return False


def find_cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph.get(node, {}):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for node in sorted(graph):
            if node not in index:
                visit(node)
    finally:
        sys.setrecursionlimit(limit)
    return components


def _within(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def _in_command_line(module: str) -> bool:
    """Whether `module` is one of ``panto/*.py`` (not a module of a mapped package)."""
    return not any(_within(module, package) for package in PACKAGES if package != "panto")


def layer_violations(graph: dict[str, dict[str, int]]) -> list[str]:
    """Every import that breaks a layer rule, as ``importer:line -> imported (reason)``."""
    found = []
    for module, edges in sorted(graph.items()):
        for target, line in sorted(edges.items()):
            for source, forbidden, reason in LAYER_RULES:
                if _within(module, source) and _within(target, forbidden):
                    found.append(f"{module}:{line} -> {target} ({reason})")
            if target.startswith(COMMAND_LINE) and not _in_command_line(module):
                found.append(f"{module}:{line} -> {target} (only the command line imports it)")
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, dict[str, int]]:
    return import_graph()


def test_the_graph_sees_function_level_imports() -> None:
    """A circle closed by an import inside a function is found."""
    tree = ast.parse("import os\n\ndef f():\n    from panto.rig import profiles\n")
    assert ("panto.rig.profiles", 4) in _imported_names(tree, "panto.x", False)
    assert find_cycles({"a": {"b": 1}, "b": {"c": 1}, "c": {"a": 3}, "d": {"a": 1}}) == [["a", "b", "c"]]


def test_relative_imports_resolve() -> None:
    tree = ast.parse("from .units import parse_unit\nfrom . import simulate\n")
    names = {name for name, _ in _imported_names(tree, "panto.build_fmu", True)}
    assert {"panto.build_fmu.units", "panto.build_fmu.simulate"} <= names
    names = {name for name, _ in _imported_names(tree, "panto.build_fmu.xml_writing", False)}
    assert "panto.build_fmu.units" in names


def test_layer_rules_catch_what_they_forbid() -> None:
    """A lower layer importing a higher one, and a package importing the command line, are
    found; the command line importing itself is not."""
    found = layer_violations({
        "panto.identification.estimation.base": {"panto.identification.design.fisher": 3},
        "panto.identification.diagnosis.pipeline": {"panto.identification.structures.physical": 5},
        "panto.rig.virtual": {"panto.commands_rig": 7},
        "panto.fmu_src.models": {"panto.build_fmu.project": 9},
        "panto.cli": {"panto.commands_rig": 1, "panto.demo": 2}})
    assert [line.split(" ->")[0] for line in found] == [
        "panto.fmu_src.models:9", "panto.identification.estimation.base:3", "panto.rig.virtual:7"]


def test_graph_covers_the_library(graph) -> None:
    assert "panto.identification.design.pantograph" in graph
    assert "panto.cli" in graph and "panto.fmu_src" in graph
    assert "panto.identification.design.fisher" in graph["panto.identification.design.pantograph"]


def test_no_import_cycles(graph) -> None:
    cycles = find_cycles(graph)
    assert not cycles, "import cycles among the library's modules: " + "; ".join(
        " <-> ".join(c) for c in cycles)


def test_layers(graph) -> None:
    found = layer_violations(graph)
    assert not found, "layer violations:\n" + "\n".join(found)


if __name__ == "__main__":
    edges = import_graph()
    print(f"{len(edges)} modules, {sum(map(len, edges.values()))} imports between them")
    cycles = find_cycles(edges)
    print(f"cycles: {len(cycles)}")
    for cycle in cycles:
        print("  " + " <-> ".join(cycle))
    violations = layer_violations(edges)
    print(f"layer violations: {len(violations)}")
    for violation in violations:
        print("  " + violation)
