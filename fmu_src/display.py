"""Small HTML tables for notebooks: what every result's ``_repr_html_`` draws.

Jupyter shows an object by its ``_repr_html_()`` when it has one. The project's results (a
:class:`~panto.fmu_src.response.TimeResponse`, an identification result, a diagnosis, a
co-simulation result) draw a caption and one or two small tables with :func:`html_table`;
every cell goes through :func:`format_cell`, so no Python repr (``np.float64(...)``, ``True``,
``[...]``, ``None``) reaches the page and every text is HTML-escaped.
"""
from __future__ import annotations

import html
import math
from collections.abc import Iterable, Mapping, Sequence
from numbers import Integral, Real
from typing import Any

import numpy as np

#: What an unavailable number (NaN, None) shows as.
MISSING = "—"


def format_cell(value: Any, *, digits: int = 4) -> str:
    """A value as plain, escaped text for a table cell.

    Parameters
    ----------
    value : Any
        Booleans become ``yes``/``no``; integers are written in full; other real numbers with
        `digits` significant digits (``%g``); NaN and None become :data:`MISSING`; sequences are
        joined with commas; mappings as ``key: value`` pairs; anything else by ``str``.
    digits : int, optional
        Significant digits of non-integer numbers (default 4).

    Returns
    -------
    str
        HTML-escaped text.

    Examples
    --------
    >>> import numpy as np
    >>> format_cell(np.float64(0.123456)), format_cell(True), format_cell(float("nan"))
    ('0.1235', 'yes', '—')
    >>> format_cell("<b>")
    '&lt;b&gt;'
    """
    return html.escape(_plain_text(value, digits), quote=True)


def _plain_text(value: Any, digits: int) -> str:
    """`value` as unescaped text (see :func:`format_cell`)."""
    if value is None:
        return MISSING
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, Integral):
        return str(int(value))
    if isinstance(value, Real):
        number = float(value)
        return MISSING if math.isnan(number) else f"{number:.{digits}g}"
    if isinstance(value, str):
        return value
    if isinstance(value, Mapping):
        return ", ".join(f"{_plain_text(k, digits)}: {_plain_text(v, digits)}"
                         for k, v in value.items())
    if isinstance(value, Iterable):
        return ", ".join(_plain_text(item, digits) for item in value) or MISSING
    return str(value)


def html_table(headers: Sequence[str], rows: Iterable[Sequence[Any]], *,
               caption: str | None = None, digits: int = 4) -> str:
    """An HTML table, every header and cell escaped (cells through :func:`format_cell`).

    Parameters
    ----------
    headers : sequence of str
        Column headings.
    rows : iterable of sequences
        One sequence of cell values per row, as long as `headers`.
    caption : str, optional
        Caption above the table.
    digits : int, optional
        Significant digits of numbers (default 4).

    Returns
    -------
    str
        ``<table>...</table>``.

    Raises
    ------
    ValueError
        If a row has another number of cells than `headers`.

    Examples
    --------
    >>> html_table(["name", "value"], [["k", 5000.0]])
    '<table><thead><tr><th>name</th><th>value</th></tr></thead><tbody><tr><td>k</td><td>5000</td></tr></tbody></table>'
    """
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in headers)
    body = []
    for index, row in enumerate(rows):
        cells = list(row)
        if len(cells) != len(headers):
            raise ValueError(f"row {index} has {len(cells)} cells for {len(headers)} headers")
        body.append("<tr>" + "".join(f"<td>{format_cell(c, digits=digits)}</td>" for c in cells)
                    + "</tr>")
    title = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    return (f"<table>{title}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody>"
            "</table>")


def html_block(title: str, *parts: str, lines: Iterable[str] = ()) -> str:
    """A titled ``<div>``: the escaped `title` in bold, escaped `lines` as paragraphs, then the
    already-built HTML `parts` (tables from :func:`html_table`)."""
    text = "".join(f"<p>{html.escape(line)}</p>" for line in lines if line)
    return f"<div><strong>{html.escape(title)}</strong>{text}{''.join(parts)}</div>"


__all__ = ["format_cell", "html_table", "html_block", "MISSING"]
