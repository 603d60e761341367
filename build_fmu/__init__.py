"""Model → C code → modelDescription.xml → compiled binary → .fmu → validation.

Public entry points:

- :func:`build_fmu` — build one FMU (FMI 2.0 or 3.0, Model Exchange and Co-Simulation) from a
  :class:`panto.fmu_src.spec.ModelSpec`;
- :func:`validate_fmu` — the problems fmpy's validator finds in an FMU.
"""
from .build import build_fmu, derive_instantiation_token, make_fmu_file_name
from .compile import CompilationError
from .units import UnitDefinition, divide_unit_by_time, parse_unit
from .validate import validate_fmu
from .simulate import FmuSimulator, SimulationError, UnknownVariableError, simulate_fmu_with_inputs
from .variables import FmuVariable, layout_variables

__all__ = [
    "CompilationError",
    "FmuSimulator",
    "FmuVariable",
    "SimulationError",
    "UnknownVariableError",
    "simulate_fmu_with_inputs",
    "UnitDefinition",
    "build_fmu",
    "derive_instantiation_token",
    "divide_unit_by_time",
    "layout_variables",
    "make_fmu_file_name",
    "parse_unit",
    "validate_fmu",
]
