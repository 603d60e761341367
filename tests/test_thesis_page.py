"""docs/thesis.md: every Python block on the page runs and its checks hold (fast variants)."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "thesis.md"
BLOCKS = re.findall(r"```python\n# check: ([\w.-]+)\n(.*?)```", PAGE.read_text(), flags=re.S)


def test_the_page_has_its_checks_and_its_to_do_rows():
    text = PAGE.read_text()
    assert {name for name, _ in BLOCKS} == {"eq-2.22", "video-step-3", "fig-4.9", "chapter-5"}
    assert "tests/test_force_excitation.py" in text  # the force-excitation rows, done
    assert "identification/section_4_8.md" in text
    assert "docs/thesis.md" in (ROOT / "README.md").read_text()


@pytest.mark.parametrize("name, code", BLOCKS, ids=[name for name, _ in BLOCKS])
def test_block_runs_and_its_checks_hold(name, code, monkeypatch):
    monkeypatch.chdir(ROOT)                       # blocks read docs/doe/ relative to the checkout
    exec(compile(code, f"docs/thesis.md#{name}", "exec"), {"FAST": True, "__name__": "thesis"})
