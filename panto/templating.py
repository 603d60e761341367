"""HTML reports from templates: one base template and one stylesheet for every report.

The demo's report (:mod:`panto.report`), the identification report
(:mod:`panto.identification.estimation.reporting`) and the diagnosis report
(:mod:`panto.identification.diagnosis.report`) are rendered from the jinja2 templates in
``panto/templates`` (``base.html.j2``, ``report.css``, ``blocks.html.j2`` and one template per
report), with autoescape on: the Python side hands over plain data, never HTML.

A report's body is a list of *blocks*, small dictionaries the templates draw
(``blocks.html.j2``): ``{"kind": "p", "text": ...}``, ``{"kind": "table", "header": [...],
"rows": [[cell, ...], ...]}`` (a cell is a value or ``{"text": ..., "class": ...}``),
``{"kind": "figure", "src": ..., "caption": ...}``, ``{"kind": "h3", "text": ...}``,
``{"kind": "pre", "text": ...}``, ``{"kind": "link", "text": ..., "href": ...}``. Every value
passes through :func:`plain_text`, so no Python representation (lists, True/False, None,
``np.float64(...)``) reaches a page.
"""
from __future__ import annotations

import base64
import functools
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

#: MIME type of the image files a report embeds, by suffix.
IMAGE_TYPES = {".png": "image/png", ".svg": "image/svg+xml", ".jpg": "image/jpeg"}


@functools.lru_cache(maxsize=1)
def environment() -> Any:
    """The jinja2 environment of the package's templates (autoescape on, strict undefined)."""
    from jinja2 import Environment, PackageLoader, StrictUndefined

    env = Environment(loader=PackageLoader("panto", "templates"), autoescape=True,
                      undefined=StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.filters["text"] = plain_text
    env.filters["number"] = format_number
    return env


def render(template: str, **context: Any) -> str:
    """Render the template named `template` (in ``panto/templates``) with `context`."""
    return environment().get_template(template).render(**context)


def format_number(value: Any, digits: int = 4) -> str:
    """A number as a person reads it: `digits` significant digits, ``–`` for None or NaN.

    Parameters
    ----------
    value : int, float, numpy scalar or None
        The number (anything else is passed to :func:`plain_text`).
    digits : int
        Significant digits of a non-integer.
    """
    if value is None:
        return "–"
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        value = value.item()  # numpy scalar
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return f"{value:.{digits}g}" if math.isfinite(value) else "–"
    return plain_text(value)


def plain_text(value: Any) -> str:
    """Any value as text without Python representations.

    None and NaN become ``–``, booleans ``yes``/``no``, numbers :func:`format_number`, sequences
    their items joined by commas, mappings ``key value`` pairs joined by semicolons.
    """
    if value is None or isinstance(value, (bool, int, float)) or (
            hasattr(value, "item") and getattr(value, "shape", None) == ()):
        return format_number(value)
    if isinstance(value, str):
        return value
    if isinstance(value, Mapping):
        return "; ".join(f"{plain_text(k)} {plain_text(v)}" for k, v in value.items()) or "–"
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, (list, tuple, set, frozenset)):
        return ", ".join(plain_text(v) for v in value) or "–"
    return str(value)


def image_source(path: str | Path, embed: bool = True, relative_to: str | Path | None = None
                 ) -> str | None:
    """What an ``<img src>`` takes for `path`: a data URI (`embed`) or the path relative to
    `relative_to`; None when the file does not exist."""
    path = Path(path)
    if not path.is_file():
        return None
    if not embed:
        return str(path.relative_to(relative_to)) if relative_to else path.name
    kind = IMAGE_TYPES.get(path.suffix.lower(), "application/octet-stream")
    return f"data:{kind};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def paragraph(text: str, css: str = "") -> dict[str, str]:
    """A paragraph block (module notes)."""
    return {"kind": "p", "text": text, "class": css}


def heading(text: str) -> dict[str, str]:
    """A third-level heading block."""
    return {"kind": "h3", "text": text}


def table(header: list[str] | tuple[str, ...], rows: Any, css: str = "") -> dict[str, Any]:
    """A table block: `header` and `rows` of cells (values, or ``{"text", "class"}``)."""
    return {"kind": "table", "header": list(header), "rows": [list(r) for r in rows],
            "class": css}


def cell(text: Any, css: str = "") -> dict[str, Any]:
    """A table cell with a CSS class (``ok``, ``failed``, ``outside``, ``mark``, ...)."""
    return {"text": text, "class": css}


def figure(path: str | Path, caption: str = "", *, embed: bool = True,
           relative_to: str | Path | None = None) -> dict[str, Any]:
    """A figure block for the image at `path` (a note when it does not exist)."""
    source = image_source(path, embed, relative_to)
    if source is None:
        return paragraph(f"(no plot {Path(path).name})", "note")
    return {"kind": "figure", "src": source, "alt": Path(path).name,
            "caption": caption or Path(path).name}
