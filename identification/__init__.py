"""Identification from rig data, design of experiments and the sim-to-real diagnosis (thesis ch. 4-5).

One subpackage per trade; ``design`` and ``diagnosis`` build on ``structures`` and ``estimation``,
never on each other:

- :mod:`~panto.identification.data`: recorded runs and plain tables to
  :class:`~panto.identification.estimation.base.IdentificationData`; preprocessing (section 4.2).
- :mod:`~panto.identification.estimation`: the data class, the fit metric and results;
  Levenberg-Marquardt, NSGA-II, uncertainty and identifiability; the comparison of structures (4.8).
- :mod:`~panto.identification.structures`: the model structures (physical pantograph, its
  linearisation, two- and three-mass oscillators, black box, collector head, ...).
- :mod:`~panto.identification.design`: chapter 5 (Fisher information, optimal inputs, online design)
  and the pantograph rig's designed runs and discrimination designs.
- :mod:`~panto.identification.diagnosis`: the sim-to-real gap: residual analysis, effect vocabulary,
  ranking, augmented refits, acceptance on withheld data, report and blind benchmark.
"""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "IdentificationData": "estimation.base",
    "fit_percent": "estimation.base",
    "load_identification_data": "data.loading",
    "LoadOptions": "data.loading",
    "pantograph_data": "data.datasets",
    "fit_least_squares": "estimation.least_squares",
    "identifier": "structures.registry",
    "structure_names": "structures.registry",
    "compare_structures": "estimation.comparison",
    "design_pantograph_experiment": "design.pantograph",
    "diagnose": "diagnosis.pipeline",
    "DiagnosisOptions": "diagnosis.pipeline",
})
