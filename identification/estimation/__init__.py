"""Estimation: the data class, the fit metric and results, least squares, NSGA-II, uncertainty."""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "IdentificationData": "base",
    "IdentificationResult": "base",
    "IdentificationError": "base",
    "ModelStructure": "base",
    "fit_percent": "base",
    "fit_least_squares": "least_squares",
    "fit_global": "global_fit",
    "fit_pareto": "genetic",
    "compare_structures": "comparison",
    "write_identification": "reporting",
})
