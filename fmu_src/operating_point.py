"""Operating points of the force-excited models, taken from their displacement-excited twins.

A force-excited model (thesis Fig. 2.6: ``PantographForce``, ``TwoMassForce``, ``ThreeMassForce``)
takes the contact force as an input instead of the contact spring to the wire height eta. The rig's
operating point is given as (eta, p), though; :func:`force_model_inputs` turns it into the force
model's inputs: the contact force the displacement model presses with at rest at (eta, p) and, for
the pantograph, the bellow torque ``M_b = k_p p`` that lifts it. At these inputs the force model
rests where its twin does (section 4.4).

Examples
--------
>>> from panto.fmu_src.operating_point import force_model_inputs
>>> inputs = force_model_inputs("PantographForce", eta=2.0, p=4.0)
>>> round(inputs["M_b"]), round(inputs["F_c"])    # [N m], [N]
(1040, 81)
"""
from __future__ import annotations

from typing import Mapping

from panto.fmu_src.models import FORCE_FMU_NAMES, Model, default_parameters
from panto.fmu_src.parameters import ParameterSet


def displacement_twin(name: str) -> str:
    """The displacement-excited model a force-excited one was derived beside.

    Parameters
    ----------
    name : str
        A force-excited model, e.g. ``"PantographForce"``.

    Returns
    -------
    str
        Its displacement-excited twin, e.g. ``"Pantograph"``.
    """
    if name not in FORCE_FMU_NAMES or name.endswith("Linear"):
        raise ValueError(f"{name!r} is no force-excited model; choose one of "
                         f"{[n for n in FORCE_FMU_NAMES if not n.endswith('Linear')]}")
    return name.removesuffix("Force")


def force_model_inputs(name: str, eta: float, p: float,
                       parameters: ParameterSet | Mapping[str, float] | None = None
                       ) -> dict[str, float]:
    """The inputs that hold force-excited model `name` where its twin rests at (eta, p).

    Parameters
    ----------
    name : str
        A force-excited model (``"PantographForce"``, ``"TwoMassForce"``, ``"ThreeMassForce"``).
    eta : float
        Wire height of the displacement-excited twin [m].
    p : float
        Bellow pressure [bar].
    parameters : ParameterSet or mapping, optional
        The force model's parameter values; the twin takes those it shares with it, its defaults
        for the rest (the contact stiffness, and for the pantograph the bellow gain ``k_p``).

    Returns
    -------
    dict of str to float
        The force model's inputs in the order of its ``input_names``: ``M_b`` [N m] and ``F_c``
        [N] for the pantograph, ``F_c`` [N] and ``p`` [bar] for the oscillators.
    """
    twin_name = displacement_twin(name)
    values = dict(parameters.values if isinstance(parameters, ParameterSet) else parameters or {})
    shared = {key: value for key, value in values.items()
              if key in default_parameters(twin_name).names}
    twin = Model(twin_name, shared)
    rest = twin.equilibrium(eta, p)
    contact_force = float(twin.outputs(rest, eta, p)[twin.output_names.index("F_c")])
    known = {"F_c": contact_force, "p": float(p)}
    if "k_p" in twin.parameters.names:  # the pantograph: the bellow's torque instead of p
        known["M_b"] = float(twin.parameters["k_p"] * p)
    return {key: known[key] for key in Model(name, values).input_names}
