"""The table of model structures: every name ``panto identify --model``, ``panto compare`` and the
diagnosis take, what it is and where its code lives.

:data:`STRUCTURES` is the one list. Each :class:`StructureEntry` names its module and functions as
strings, imported only when the structure is used (as python-can keeps its interfaces), so reading
the table imports no structure. A family with a parameter (``linear-N``, ``blackbox-N``) is one
pattern entry; its listed members are the ones shown and compared, any positive ``N`` is accepted.

- :func:`structure_names`, :func:`structure_info`: the names and their records;
- :func:`identifier`, :func:`all_identifiers`, :func:`comparison_identifiers`: the fitting
  functions as :class:`~panto.identification.estimation.base.Identifier` records;
- :func:`build_structure`: the nominal structure object for the diagnosis;
- :func:`is_pantograph_structure`: whether a structure's data is the rig mapping
  ``eta, p -> F_c, y_cb``; :func:`parameter_set`: the fmu_src model whose parameter file its
  result fills.
"""
from __future__ import annotations

import functools
import importlib
import re
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from panto.identification.estimation.base import (IdentificationData, IdentificationError, Identifier,
                                                  ModelStructure)

_PACKAGE = "panto.identification.structures"


@dataclass(frozen=True)
class StructureEntry:
    """One row of the table of model structures.

    Attributes
    ----------
    name : str
        The structure's name, or for a family a pattern with one ``{keyword}`` field
        (``"linear-{order}"``) that a positive integer fills.
    description : str
        One line for listings (a family's may use its ``{keyword}``).
    module : str
        Module under ``panto.identification.structures`` holding the functions below.
    identify : str
        Function ``identify(data, *, executor=None, progress=None, **arguments, **options)
        -> IdentificationResult`` that fits it.
    build : str or None
        Function ``build(data, **arguments, **options) -> ModelStructure`` giving the nominal
        structure for the diagnosis (start values from the training run); None when the
        diagnosis cannot use it.
    arguments : mapping
        Fixed keyword arguments of both functions (``masses``, ``friction``).
    in_comparison : bool
        Whether ``panto compare`` fits it (the thesis' table of section 4.8).
    pantograph_data : bool
        Whether it is defined on the rig mapping only (inputs ``eta, p``, outputs among ``F_c,
        y_cb, xi``): its data is what :func:`~panto.identification.data.datasets.pantograph_data`
        loads from a run, without naming columns.
    parameter_set : str or None
        The fmu_src model whose parameter file its result fills (``"Pantograph"``); None for
        plain JSON.
    members : tuple of int
        A family's members listed by :func:`structure_names` (and compared when
        ``in_comparison``).
    """

    name: str
    description: str
    module: str
    identify: str
    build: str | None = None
    arguments: Mapping[str, Any] = field(default_factory=dict)
    in_comparison: bool = True
    pantograph_data: bool = False
    parameter_set: str | None = None
    members: tuple[int, ...] = ()

    @property
    def keyword(self) -> str | None:
        """The family's parameter (``"order"``), None for a single structure."""
        match = re.search(r"\{(\w+)\}", self.name)
        return match.group(1) if match else None

    def names(self) -> tuple[str, ...]:
        """The concrete names of this entry (a family's listed members)."""
        if self.keyword is None:
            return (self.name,)
        return tuple(self.name.format(**{self.keyword: n}) for n in self.members)

    def match(self, name: str) -> dict[str, Any] | None:
        """The arguments for `name` if this entry covers it (a family adds its number), else None."""
        if self.keyword is None:
            return dict(self.arguments) if name == self.name else None
        head, tail = self.name.split("{" + self.keyword + "}")
        found = re.fullmatch(re.escape(head) + r"([1-9]\d*)" + re.escape(tail), name)
        return {**self.arguments, self.keyword: int(found.group(1))} if found else None


def _oscillator(masses: int, friction: bool, description: str) -> StructureEntry:
    name = {2: "two", 3: "three"}[masses] + "-mass" + ("-friction" if friction else "")
    return StructureEntry(name, description, "oscillators", "identify_oscillator",
                          "oscillator_from_data", {"masses": masses, "friction": friction},
                          pantograph_data=True)


#: Every model structure, in the order listings and the comparison table show them.
STRUCTURES: tuple[StructureEntry, ...] = (
    StructureEntry("physical-linear", "physical model (Table 4.1), linearised about its equilibrium "
                   "for every candidate (thesis 4.1.3, 4.5)", "physical", "identify_linear",
                   "linear_from_data", pantograph_data=True, parameter_set="Pantograph"),
    StructureEntry("physical", "nonlinear physical model (Table 4.1), the Pantograph FMU in the "
                   "loop", "physical", "identify_nonlinear", "nonlinear_from_data",
                   pantograph_data=True, parameter_set="Pantograph"),
    _oscillator(2, False, "two-mass oscillator (thesis 2.6, 4.6)"),
    _oscillator(2, True, "two-mass oscillator with Coulomb friction on both masses (thesis 2.7, "
                "4.7)"),
    _oscillator(3, False, "three-mass oscillator (thesis 2.6, 4.6)"),
    _oscillator(3, True, "three-mass oscillator with Coulomb friction on every mass (thesis 2.7, "
                "4.7)"),
    StructureEntry("blackbox-{order}", "black-box state-space model, {order} states (thesis 4.8): "
                   "PO-MOESP subspace estimate refined by output error", "blackbox",
                   "identify_state_space", members=(4, 6)),
    StructureEntry("collector-head", "collector head alone (thesis 4.3): PT2 of eqs. 4.15/4.16 "
                   "from the head-cross-bar position difference, the force and the cross-bar "
                   "position", "collector_head", "identify_collector_head_result",
                   in_comparison=False),
    StructureEntry("linear-{order}", "linear output-error model of order {order} per output (any "
                   "data)", "output_error", "identify_linear_output_error",
                   "linear_output_error_from_data", in_comparison=False, members=(2, 4, 6)),
    StructureEntry("rigid-body", "rigid-body inverse dynamics F = M q'' + F_v q' + F_0 from a "
                   "measured position (equation error; EMPS-like axes)", "rigid_body",
                   "identify_rigid_body", "rigid_body_from_data", in_comparison=False),
)


def structure_names() -> list[str]:
    """Every concrete structure name, in table order (a family's listed members)."""
    return [name for entry in STRUCTURES for name in entry.names()]


def _shown(entries: Sequence[StructureEntry]) -> str:
    """The entries' names for a message, a family as ``linear-N``."""
    return ", ".join(e.name.replace("{" + e.keyword + "}", "N") if e.keyword else e.name
                     for e in entries)


def _lookup(name: str) -> tuple[StructureEntry, dict[str, Any]]:
    for entry in STRUCTURES:
        arguments = entry.match(name)
        if arguments is not None:
            return entry, arguments
    raise IdentificationError(f"unknown model structure {name!r}; known: {_shown(STRUCTURES)} "
                              "(N a positive integer)")


def structure_info(name: str) -> StructureEntry:
    """The table's record of `name` (a family's entry for ``linear-8``); a one-line error lists
    the known names."""
    return _lookup(name)[0]


def _function(entry: StructureEntry, attribute: str) -> Any:
    module = importlib.import_module(f"{_PACKAGE}.{entry.module}")
    return getattr(module, attribute)


def identifier(name: str) -> Identifier:
    """The fitting function of structure `name` as an :class:`Identifier` (imports its module)."""
    entry, arguments = _lookup(name)
    fit = _function(entry, entry.identify)
    description = entry.description.format(**{entry.keyword: arguments[entry.keyword]}) \
        if entry.keyword else entry.description
    return Identifier(name, description, functools.partial(fit, **arguments) if arguments else fit,
                      in_comparison=entry.in_comparison)


def all_identifiers() -> dict[str, Identifier]:
    """Every listed structure's identifier by name, in table order."""
    return {name: identifier(name) for name in structure_names()}


def comparison_identifiers(names: Sequence[str] | None = None) -> list[Identifier]:
    """The identifiers for ``panto compare``: those named, else every one with ``in_comparison``
    (the thesis' table)."""
    if names is None:
        return [i for i in all_identifiers().values() if i.in_comparison]
    return [identifier(name) for name in names]


def build_structure(name: str, data: IdentificationData, options: Mapping[str, Any]
                    ) -> ModelStructure:
    """The nominal structure `name` for the diagnosis, start values from `data` (the training
    run); `options` are its constructor options."""
    try:
        entry, arguments = _lookup(name)
    except IdentificationError:
        entry, arguments = None, {}
    if entry is None or entry.build is None:
        buildable = _shown([e for e in STRUCTURES if e.build is not None])
        raise IdentificationError(f"unknown structure {name!r} for the diagnosis: {buildable}")
    return _function(entry, entry.build)(data, **arguments, **dict(options))


def is_pantograph_structure(name: str) -> bool:
    """Whether structure `name` is defined on the rig mapping ``eta, p -> F_c, y_cb`` (its data
    loads from a run without naming columns); False for an unknown name."""
    try:
        return structure_info(name).pantograph_data
    except IdentificationError:
        return False


def parameter_set(name: str) -> str | None:
    """The fmu_src model whose parameter file the result of `name` fills (None: plain JSON, or
    an unknown name)."""
    try:
        return structure_info(name).parameter_set
    except IdentificationError:
        return None


__all__ = ["StructureEntry", "STRUCTURES", "structure_names", "structure_info", "identifier",
           "all_identifiers", "comparison_identifiers", "build_structure",
           "is_pantograph_structure", "parameter_set"]
