"""Check a built FMU with fmpy's validator (and its build description, for FMI 3.0)."""
from __future__ import annotations

import logging
import zipfile
from pathlib import Path

LOGGER = logging.getLogger(__name__)


def validate_fmu(path: str | Path) -> list[str]:
    """Problems fmpy finds in an FMU; an empty list means it is valid.

    Runs :func:`fmpy.validation.validate_fmu` (schema, variable names, model structure, start
    values, causality/variability combinations, units) and, when the FMU carries a
    ``sources/buildDescription.xml``, validates it against the FMI 3.0 schema.

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file.

    Returns
    -------
    list of str
        One line per problem, each naming the FMU file.
    """
    from fmpy.model_description import read_build_description
    from fmpy.validation import validate_fmu as fmpy_validate_fmu

    path = Path(path)
    if not path.is_file():
        return [f"{path}: no such file"]
    problems = [f"{path.name}: {problem}" for problem in fmpy_validate_fmu(str(path))]
    with zipfile.ZipFile(path) as archive:
        has_build_description = "sources/buildDescription.xml" in archive.namelist()
    if has_build_description:
        try:
            read_build_description(str(path), validate=True)
        except Exception as error:  # fmpy raises a bare Exception with the schema errors
            problems.append(f"{path.name}: sources/buildDescription.xml: {error}")
    for problem in problems:
        LOGGER.warning("%s", problem)
    return problems
