"""The sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far it shrinks."""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "diagnose": "pipeline",
    "DiagnosisOptions": "pipeline",
    "Diagnosis": "pipeline",
    "write_report": "report",
    "analyse_residuals": "residual_analysis",
    "EFFECTS": "effects",
    "SignalRoles": "effects",
    "run_diagnosis_benchmark": "benchmark",
})
