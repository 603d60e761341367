"""The project's models by name: symbolic form, parameters, Python evaluation and FMU specs.

Examples
--------
>>> from panto.fmu_src.models import Model
>>> pantograph = Model("Pantograph")
>>> x0 = pantograph.equilibrium(eta=2.0, p=4.0)
>>> round(float(pantograph.outputs(x0, eta=2.0, p=4.0)[2]))   # contact force [N]
81
"""
from __future__ import annotations

import pickle
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import sympy as sp

from panto.fmu_src.codegen import generate_c_code
from panto.fmu_src.numeric import LinearisedModel, ModelEvaluationError, NumericModel
from panto.fmu_src.oscillators import derive_oscillator, derive_oscillator_force
from panto.fmu_src.pantograph import PHI1_SEARCH_RANGE, derive_pantograph, derive_pantograph_force
from panto.fmu_src.parameters import ParameterError, ParameterSet
from panto.fmu_src.sparsity import jacobian_structure
from panto.fmu_src.spec import ModelSpec, Variable
from panto.fmu_src.symbolic import (MechanicalModel, cached_derivation, default_cache_dir, prune,
                                    read_verified, source_digest, write_atomic)

#: Models by name, each with the function that derives it.
DERIVATIONS = {
    "Pantograph": derive_pantograph,
    "TwoMass": lambda: derive_oscillator(2),
    "ThreeMass": lambda: derive_oscillator(3),
    "PantographForce": derive_pantograph_force,
    "TwoMassForce": lambda: derive_oscillator_force(2),
    "ThreeMassForce": lambda: derive_oscillator_force(3),
}
MODEL_NAMES = tuple(DERIVATIONS)
#: The displacement-excited FMUs (inputs eta and p; thesis sections 2.5-2.7).
DISPLACEMENT_FMU_NAMES = ("Pantograph", "PantographLinear", "TwoMass", "ThreeMass")
#: The force-excited FMUs (contact force in, head motion out; thesis Fig. 2.6 and section 4.8).
FORCE_FMU_NAMES = ("PantographForce", "PantographForceLinear", "TwoMassForce", "ThreeMassForce")
#: The FMUs that ``panto build-fmu`` builds (each as FMI 2.0 and FMI 3.0).
FMU_NAMES = DISPLACEMENT_FMU_NAMES + FORCE_FMU_NAMES

#: Force-excited models: a contact force within 10 kN either way (static contact forces are
#: 70-120 N, EN 50318 limits the dynamic one to a few hundred N); pantograph bellow torque 0 to
#: 10 kN m (10 bar at the Table 4.1 gain of 260 N m/bar gives 2.6 kN m).
FORCE_INPUT_RANGES = {"F_c": (-1e4, 1e4), "p": (0.0, 10.0)}
#: Admissible input ranges (minimum, maximum) declared by the FMUs; the setters refuse values
#: outside. Bellow pressure: 0 bar to the 10 bar the train's supply provides (thesis section
#: 2.1). Pantograph eta: heights above the frame hinge, from 0 (the head cannot go below it) to
#: 10 m (no pantograph reaches that far); the reach of the tunable geometry is checked at the
#: equilibrium (default geometry: cross bar 0.55 m to 3.24 m). Oscillators: eta within 100 m of
#: any admissible relaxed height y_0 (itself in [-100, 100] m). Force-excited models: above.
INPUT_RANGES = {
    "Pantograph": {"eta": (0.0, 10.0), "p": (0.0, 10.0)},
    "TwoMass": {"eta": (-200.0, 200.0), "p": (0.0, 10.0)},
    "ThreeMass": {"eta": (-200.0, 200.0), "p": (0.0, 10.0)},
    **{name: FORCE_INPUT_RANGES for name in ("TwoMassForce", "ThreeMassForce")},
    "PantographForce": {"M_b": (0.0, 1e4), "F_c": FORCE_INPUT_RANGES["F_c"]},
}
#: State nominals: for a coordinate the power of ten nearest its default static equilibrium
#: (Pantograph at eta = 2 m, p = 4 bar; oscillators at eta = y_0 = 0), for a velocity ten times
#: that per second (the lowest natural angular frequencies are 16-20 rad/s), at most 1.
STATE_NOMINALS = {
    "Pantograph": {"phi1": 1.0, "delta": 1e-3, "xi": 1.0, "dphi1": 1.0, "ddelta": 1e-2,
                   "dxi": 1.0},
    "TwoMass": {"x1": 1e-2, "x2": 1e-3, "v1": 1e-1, "v2": 1e-2},
    "ThreeMass": {"x1": 1e-2, "x2": 1e-2, "x3": 1e-3, "v1": 1e-1, "v2": 1e-1, "v3": 1e-2},
    "PantographForce": {"phi1": 1.0, "delta": 1e-3, "xi": 1.0, "dphi1": 1.0, "ddelta": 1e-2,
                        "dxi": 1.0},
    "TwoMassForce": {"x1": 1e-2, "x2": 1e-2, "v1": 1e-1, "v2": 1e-1},
    "ThreeMassForce": {"x1": 1e-2, "x2": 1e-2, "x3": 1e-2, "v1": 1e-1, "v2": 1e-1, "v3": 1e-1},
}


def symbolic_model(name: str) -> MechanicalModel:
    """The symbolic model called ``name`` (one of :data:`MODEL_NAMES`)."""
    try:
        return cached_derivation(name, DERIVATIONS[name])
    except KeyError:
        raise ValueError(f"unknown model {name!r}; choose one of {list(MODEL_NAMES)}") from None


@lru_cache(maxsize=None)
def numeric_model(name: str) -> NumericModel:
    """The compiled Python evaluation of a model (cached)."""
    return NumericModel(symbolic_model(name))


def default_parameters(name: str) -> ParameterSet:
    """The default parameter set of a model, with units, bounds and provenance."""
    return ParameterSet(name, symbolic_model(name).parameters)


def load_parameters(path: str | Path, name: str | None = None) -> ParameterSet:
    """Read a parameter file; the model is taken from the file unless ``name`` is given."""
    if name is None:
        import json

        try:
            name = json.loads(Path(path).read_text()).get("model")
        except (OSError, ValueError, AttributeError) as error:
            raise ParameterError(f"{path}: cannot read parameter file ({error})") from error
        if name is None:
            raise ParameterError(f"{path}: the file does not say which model it is for ('model')")
    params = ParameterSet.load(path, symbolic_model(name).parameters, name)
    check_parameters(params)
    return params


def check_parameters(params: ParameterSet) -> None:
    """Model-specific admissibility beyond the bounds; raises :class:`ParameterError`.

    For the pantograph (displacement- or force-excited), the linkage must close somewhere in the
    working range of phi1.
    """
    if params.model not in ("Pantograph", "PantographForce"):
        return
    numeric = numeric_model(params.model)
    low, high = PHI1_SEARCH_RANGE
    for phi1 in np.linspace(low, high, 28):
        try:
            numeric.dependents(params.vector(), [phi1, 0.0, 0.0])
            return
        except ModelEvaluationError:
            continue
    raise ParameterError(
        f"{params.source}: with l1={params['l1']}, l2={params['l2']}, l3={params['l3']}, "
        f"c={params['c']}, d={params['d']} the linkage cannot close for any phi1 in "
        f"[{low}, {high}] rad")


def model_spec(name: str) -> ModelSpec:
    """The :class:`ModelSpec` (variables, parameters, generated C code) of one FMU.

    ``"PantographLinear"`` is the pantograph's C code compiled in linearised mode. Generating the
    C code and the Jacobian's sparsity takes 10-20 s for the pantograph, so the spec is pickled
    in the cache folder of the derived models (:func:`panto.fmu_src.symbolic.default_cache_dir`),
    keyed by :func:`panto.fmu_src.symbolic.source_digest` (every ``fmu_src/*.py``, SymPy's and
    Python's versions) and checked by its SHA-256 like them.
    """
    path = default_cache_dir() / f"{name}-{source_digest()}.spec.pickle"
    payload = read_verified(path)
    try:
        spec = pickle.loads(payload) if payload is not None else None  # noqa: S301 - own file
    except Exception:  # noqa: BLE001 - a bad pickle is generated again, whatever it raises
        spec = None
    if not isinstance(spec, ModelSpec) or spec.identifier != name:
        spec = _generate_model_spec(name)
        if write_atomic(path, pickle.dumps(spec, protocol=pickle.HIGHEST_PROTOCOL)):
            prune(path.parent, f"{name}-*.spec.pickle")
    return spec


def _generate_model_spec(name: str) -> ModelSpec:
    """The spec of :func:`model_spec`, derived and generated in this process."""
    linearised = name.endswith("Linear")
    model = symbolic_model(name.removesuffix("Linear"))
    if linearised:
        description = (f"{model.description}, linearised about the static equilibrium for the "
                       "operating point (eta0, p0) (thesis section 2.4)")
    else:
        description = model.description
    ranges, nominals = INPUT_RANGES[model.name], STATE_NOMINALS[model.name]

    def state(variable: Variable) -> Variable:
        return replace(variable, nominal=nominals[variable.name])

    return ModelSpec(
        identifier=name, description=description,
        coordinates=tuple(_distinct_from_outputs(state(c), model) for c in model.coordinates),
        velocities=tuple(state(v) for v in model.velocities),
        inputs=tuple(replace(u, minimum=ranges[u.name][0], maximum=ranges[u.name][1])
                     for u in model.inputs),
        outputs=model.outputs, parameters=model.parameters, c_code=_c_code(model.name),
        linearised=linearised, dependencies=jacobian_structure(model, linearised=linearised),
        event_indicators=CONTACT_EVENT_INDICATORS if _has_contact(model) else (),
    )


#: The event indicator of every model with a contact spring: the contact gap (head height minus
#: eta) while the contact is unilateral, so that Model Exchange importers locate contact loss and
#: re-contact; 1 (no event) while it is bilateral. The force-excited models have none.
CONTACT_EVENT_INDICATORS = (Variable("contact_gap", "m", "head height minus eta while the "
                                     "contact is unilateral (zero at contact loss and "
                                     "re-contact), 1 while it is bilateral"),)


def contact_gap(model: MechanicalModel) -> sp.Expr:
    """The contact event indicator: head (last coordinate) minus eta if unilateral, else 1."""
    unilateral = sp.Symbol("unilateral_contact", real=True)
    head, eta = model.q[-1], sp.Symbol("eta", real=True)
    return sp.Piecewise((head - eta, unilateral > sp.Rational(1, 2)), (1, True))


def _has_contact(model: MechanicalModel) -> bool:
    """Whether the model has the contact spring to the input eta (the force-excited ones not)."""
    return any(u.name == "eta" for u in model.inputs)


def _distinct_from_outputs(variable, model: MechanicalModel):
    """FMI variables need unique names: a coordinate that is also an output (the pantograph's
    head height ``xi``) is exposed as the state ``<name>_state``; the output keeps the name."""
    if any(o.name == variable.name for o in model.outputs):
        return replace(variable, name=f"{variable.name}_state")
    return variable


@lru_cache(maxsize=None)
def _c_code(name: str) -> str:
    model = symbolic_model(name)
    indicators = (contact_gap(model),) if _has_contact(model) else ()
    return generate_c_code(model, event_indicators=indicators)


class Model:
    """A model with one parameter set, evaluated in Python (the FMUs' twin for fitting scripts).

    Parameters
    ----------
    name : str
        ``"Pantograph"``, ``"TwoMass"`` or ``"ThreeMass"``, or a force-excited model
        (``"PantographForce"``, ``"TwoMassForce"``, ``"ThreeMassForce"``).
    parameters : ParameterSet or mapping, optional
        Parameter values (defaults where missing).

    Notes
    -----
    The methods name the inputs ``eta, p`` of the displacement-excited models; a force-excited
    model takes its own two inputs in the same places, in the order of :attr:`input_names`
    (``M_b, F_c`` for the pantograph, ``F_c, p`` for the oscillators).
    """

    def __init__(self, name: str, parameters: ParameterSet | dict | None = None):
        self.name = name
        self.numeric = numeric_model(name)
        if isinstance(parameters, ParameterSet):
            self.parameters = parameters
        else:
            self.parameters = default_parameters(name).with_values(parameters or {})
        check_parameters(self.parameters)
        self._p = self.parameters.vector()

    @property
    def state_names(self) -> tuple[str, ...]:
        m = self.numeric.model
        return tuple(s.name for s in m.coordinates + m.velocities)

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.numeric.model.inputs)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.numeric.model.outputs)

    def derivatives(self, x, eta: float, p: float) -> np.ndarray:
        """Right-hand side dx/dt = f(x, u)."""
        return self.numeric.derivatives(self._p, np.asarray(x, float), (eta, p))

    def outputs(self, x, eta: float, p: float) -> np.ndarray:
        """Outputs (y_cb, xi, F_c)."""
        return self.numeric.outputs(self._p, np.asarray(x, float), (eta, p))

    def equilibrium(self, eta: float, p: float) -> np.ndarray:
        """Static equilibrium state x0 for constant inputs (Levenberg-Marquardt solve)."""
        return self.numeric.equilibrium(self._p, (eta, p))

    def linearise(self, eta: float, p: float) -> LinearisedModel:
        """Exact linearisation about the static equilibrium for (eta, p)."""
        x0 = self.equilibrium(eta, p)
        return self.numeric.linearise(self._p, x0, (eta, p))

    def energy(self, x, eta: float, p: float) -> float:
        """Total energy incl. the work potential of constant inputs (conserved without damping)."""
        return self.numeric.energy(self._p, np.asarray(x, float), (eta, p))
