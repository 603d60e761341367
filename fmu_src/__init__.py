"""The models, the single source of truth (thesis chapter 2): symbolic derivations, parameters, C runtime.

- :mod:`~panto.fmu_src.symbolic`, :mod:`~panto.fmu_src.pantograph`, :mod:`~panto.fmu_src.oscillators`:
  the mechanical models in generalised coordinates (SymPy): the nonlinear multibody pantograph and the
  two- and three-mass oscillators.
- :mod:`~panto.fmu_src.parameters`: parameter sets with units, bounds and provenance (Tables 2.1, 4.1).
- :mod:`~panto.fmu_src.models`: the models by name (:class:`~panto.fmu_src.models.Model`: equilibrium,
  linearisation, Python evaluation); :mod:`~panto.fmu_src.numeric` their fast numeric form.
- :mod:`~panto.fmu_src.simulation`: simulation on the Python path (SciPy's ``solve_ivp``).
- :mod:`~panto.fmu_src.response`: :class:`~panto.fmu_src.response.TimeResponse`, named signals with units.
- :mod:`~panto.fmu_src.spec`, :mod:`~panto.fmu_src.codegen`: what a model hands to the FMU builder, and
  its generated C code; ``runtime/`` holds the hand-written FMI 2.0/3.0 C runtime and solver.
"""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "Model": "models",
    "default_parameters": "models",
    "load_parameters": "models",
    "ParameterSet": "parameters",
    "ParameterError": "parameters",
    "simulate_model": "simulation",
    "SolverOptions": "simulation",
    "TimeResponse": "response",
    "DataFormatError": "dataformat",
})
