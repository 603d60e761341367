"""The demo's one-picture overview: six of the report's plots on one page (``overview.png``).

The summary page of ``report.html`` opens with it and the README shows it: the identified model
against the training run, the Pareto front, where the diagnosis locates the gap, the designed
experiment, the synchronisation of the video, and the contact force along the catenary. Panels
whose plot a failed step did not write are left out; the picture is drawn from whatever exists.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

#: (relative path in the demo folder, panel title), in reading order.
PANELS: tuple[tuple[str, str], ...] = (
    ("identification/fit.png", "Identified physical model vs the rig (training, validation)"),
    ("identification/pareto.png", "NSGA-II Pareto front: cross bar vs contact force fit"),
    ("diagnosis/validation.png", "Diagnosis: validation before and after the found effects"),
    ("doe/doe_std.png", "Next rig run: parameter std, APRBS vs designed"),
    ("video/training_sync.png", "Video markers synchronised through the LED"),
    ("cosim/en50318-2002_300kmh_force.png", "Contact force along the EN 50318 line, 300 km/h"),
)


def write_overview(out: str | Path, panels: Sequence[tuple[str, str]] = PANELS,
                   name: str = "overview.png") -> Path | None:
    """Compose the existing panel plots of the demo folder `out` into ``out/name``.

    Parameters
    ----------
    out : str or pathlib.Path
        The demo's output folder.
    panels : sequence of (str, str)
        Relative PNG paths and their titles (default :data:`PANELS`).
    name : str
        File name of the picture.

    Returns
    -------
    pathlib.Path or None
        The picture, or None when none of the panels exists.
    """
    import matplotlib.image as mpimg
    from matplotlib.figure import Figure

    out = Path(out)
    found = [(out / path, title) for path, title in panels if (out / path).is_file()]
    if not found:
        return None
    columns = 2 if len(found) > 1 else 1
    rows = -(-len(found) // columns)
    figure = Figure(figsize=(8 * columns, 4.6 * rows))
    axes = figure.subplots(rows, columns, squeeze=False)
    for axis in axes.ravel():
        axis.axis("off")
    for axis, (path, title) in zip(axes.ravel(), found):
        axis.imshow(mpimg.imread(path))
        axis.set_title(title, fontsize=12)
    figure.tight_layout()
    target = out / name
    figure.savefig(target, dpi=90)
    return target
