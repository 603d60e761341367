"""Data for identification: recorded runs and plain tables to IdentificationData, preprocessing."""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "load_identification_data": "loading",
    "LoadOptions": "loading",
    "read_table": "loading",
    "data_from_dataset": "datasets",
    "pantograph_data": "datasets",
    "resample_dataset": "preprocessing",
    "lowpass_zero_phase": "preprocessing",
    "check_aliasing": "preprocessing",
})
