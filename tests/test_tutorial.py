"""docs/tutorial.md: its Python blocks run in order, in one namespace (as a notebook runs its cells),
under the Agg backend chosen here by the test (the library chooses none), and its figures exist."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "tutorial.md"
BLOCKS = re.findall(r"```python\n# step: ([\w.-]+)\n(.*?)```", PAGE.read_text(), flags=re.S)


def test_the_page_walks_from_a_rig_run_to_a_cosimulation_and_is_linked():
    assert [name for name, _ in BLOCKS] == ["fmu", "rig-run", "identify", "plot", "simulate",
                                            "cosimulate"]
    assert all("FAST = True" in code for name, code in BLOCKS if name == "fmu")
    assert "docs/tutorial.md" in (ROOT / "README.md").read_text()


def test_blocks_run_and_draw_their_figures(tmp_path):
    import matplotlib

    matplotlib.use("Agg")  # the test's choice; nothing in the library sets a backend
    from matplotlib.figure import Figure

    namespace = {"__name__": "tutorial"}
    figures = {}
    for name, code in BLOCKS:
        exec(compile(code, f"docs/tutorial.md#{name}", "exec"), namespace)
        if isinstance(namespace.get("figure"), Figure):
            figures.setdefault(name, namespace["figure"])
    assert namespace["FAST"] is True
    # step 4: measured and identified overlaid, one subplot per output, units on the axes
    overlay = figures["plot"]
    assert [axis.get_ylabel() for axis in overlay.axes] == ["F_c [N]", "y_cb [m]"]
    assert all(len(axis.get_lines()) == 2 for axis in overlay.axes)
    # step 6: the co-simulation's contact force, positive pressing on the wire
    contact = figures["cosimulate"]
    assert contact.axes[0].get_ylabel() == "contact_force [N]"
    assert contact.axes[0].get_lines()[0].get_ydata().mean() > 0.0
    for name, figure in figures.items():
        path = figure.savefig(tmp_path / f"{name}.png") or tmp_path / f"{name}.png"
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the result objects show themselves as escaped HTML tables, without Python reprs
    for key in ("result", "cosimulation", "recorded"):
        page = namespace[key]._repr_html_()
        assert "<table>" in page and "np.float64" not in page and "True" not in page


@pytest.mark.parametrize("name", ["fmu", "rig-run"])
def test_each_block_says_what_it_shows(name):
    text = PAGE.read_text()
    block = dict(BLOCKS)[name]
    after = text[text.index(block) + len(block):].lstrip("`\n")
    assert after.split("\n\n")[0].strip(), f"block {name} has no explanation after it"
