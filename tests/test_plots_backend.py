"""Library code never chooses the plotting backend: no ``matplotlib.use``, no pyplot; plots are
drawn on bare :class:`matplotlib.figure.Figure` objects, so they work in notebooks and servers."""
import ast
import importlib
import importlib.util
import pkgutil
import subprocess
import sys
import textwrap
from pathlib import Path

PACKAGES = ("panto.fmu_src", "panto.build_fmu", "panto.catenary_cosim", "panto.rig",
            "panto.video_sync", "panto.identification", "panto")


def _module_names():
    for package in PACKAGES:
        yield package
        for info in pkgutil.walk_packages(importlib.import_module(package).__path__, package + "."):
            yield info.name


MODULES = sorted(set(_module_names()))
#: The modules whose job is drawing: the packages' plot modules and the picture writers.
PLOT_MODULES = sorted(name for name in MODULES if name.rsplit(".", 1)[-1].endswith("plots")) + [
    "panto.rig.profile_preview", "panto.overview"]


def _source(name: str) -> tuple[Path, str]:
    path = Path(importlib.util.find_spec(name).origin)
    return path, path.read_text(encoding="utf-8")


def _backend_choices(tree: ast.AST) -> list[str]:
    """Lines of `tree` that import pyplot or call ``matplotlib.use``."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [f"{node.lineno}: import {a.name}" for a in node.names
                      if a.name.startswith("matplotlib.pyplot")]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if module.startswith("matplotlib.pyplot") or (
                    module == "matplotlib" and any(a.name == "pyplot" for a in node.names)):
                found.append(f"{node.lineno}: from {module} import ...")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                node.func.attr == "use" and isinstance(node.func.value, ast.Name) and \
                node.func.value.id == "matplotlib":
            found.append(f"{node.lineno}: matplotlib.use(...)")
    return found


def test_no_library_module_imports_pyplot_or_chooses_a_backend():
    offenders = []
    for name in MODULES:
        path, text = _source(name)
        lines = _backend_choices(ast.parse(text, filename=str(path)))
        if "matplotlib.use(" in text and not any("matplotlib.use" in line for line in lines):
            lines.append("matplotlib.use( in the text")
        offenders += [f"{path.name} ({name}) line {line}" for line in lines]
    assert not offenders, f"library code must draw on matplotlib.figure.Figure: {offenders}"


def test_the_scan_finds_both_ways_of_choosing_a_backend():
    source = textwrap.dedent("""
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib import pyplot
        """)
    assert len(_backend_choices(ast.parse(source))) == 3
    assert _backend_choices(ast.parse("from matplotlib.figure import Figure")) == []


def test_plot_modules_found():
    assert {"panto.catenary_cosim.plots", "panto.video_sync.plots",
            "panto.identification.data.plots", "panto.identification.estimation.plots",
            "panto.identification.structures.plots", "panto.identification.design.plots",
            "panto.identification.diagnosis.residual_plots"} <= set(PLOT_MODULES)


def test_importing_and_drawing_keeps_the_users_backend(tmp_path):
    """A fresh interpreter picks the SVG backend, imports every plot module and draws three
    plots; the backend stays SVG and pyplot (with its global figure registry) is never loaded."""
    script = textwrap.dedent(f"""
        import importlib, sys
        import matplotlib
        matplotlib.use("svg")
        import numpy as np
        for name in {PLOT_MODULES!r}:
            importlib.import_module(name)
        assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
        from panto.catenary_cosim.plots import plot_rig_sequence
        from panto.identification.design.plots import plot_line_designs
        from panto.identification.diagnosis.benchmark_report import plot_confusion
        folder = {str(tmp_path)!r}
        time = np.linspace(0.0, 1.0, 50, endpoint=False)
        plot_rig_sequence(folder + "/rig.png", time, 0.01 * np.sin(2 * np.pi * time), 1.0)
        plot_line_designs(folder + "/line.png")
        plot_confusion({{"friction": {{"friction": 3, "none": 1}}, "none": {{"none": 4}}}},
                       folder + "/confusion.png")
        print(matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules)
        """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["svg", "False"]
    for name in ("rig.png", "line.png", "confusion.png"):
        assert (tmp_path / name).read_bytes().startswith(b"\x89PNG")
