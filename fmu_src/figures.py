"""A matplotlib figure that a notebook shows as a picture, with no backend chosen by the library.

A bare :class:`matplotlib.figure.Figure` (what the project's plots draw on, so that no library
code touches pyplot or the global backend) is shown in Jupyter or IPython as text, ``<Figure size
800x460 with 2 Axes>``, until something imports pyplot or runs ``%matplotlib inline``.
:class:`NotebookFigure` adds ``_repr_png_``: the notebook asks for a PNG and gets one drawn by
:meth:`~matplotlib.figure.Figure.savefig` (matplotlib picks the Agg canvas for that one call; the
global backend is left alone). Where the notebook's inline backend is active, its own formatter
for figures wins, so the picture is shown once.
"""
from __future__ import annotations

from io import BytesIO

from matplotlib.figure import Figure


class NotebookFigure(Figure):
    """A :class:`matplotlib.figure.Figure` with a PNG representation for notebooks.

    Examples
    --------
    >>> figure = NotebookFigure(figsize=(2.0, 1.0))
    >>> figure.subplots().plot([0, 1], [0, 1])[0].get_xydata().shape
    (2, 2)
    >>> figure._repr_png_()[:4]
    b'\\x89PNG'
    """

    #: Resolution [dots per inch] of the notebook's picture.
    notebook_dpi = 100.0

    def _repr_png_(self) -> bytes:
        """The figure as PNG bytes (what IPython's display machinery asks for)."""
        buffer = BytesIO()
        self.savefig(buffer, format="png", dpi=self.notebook_dpi)
        return buffer.getvalue()


__all__ = ["NotebookFigure"]
