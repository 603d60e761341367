"""The pantograph side of the co-simulation as data: which FMU, which parameters, which inputs.

A :class:`PantographSetup` names an FMU (one of the project's, built on demand into a cache
folder, or a user's file), its input for the contact-wire height and its output for the contact
force, the parameters to set and how the line's absolute wire height maps to the FMU's input:

.. math:: \\eta = h_w(x) + \\Delta, \\qquad \\Delta = h_\\text{ref} - h_d

with the design contact-wire height :math:`h_d` of the line and the FMU's reference height
:math:`h_\\text{ref}`:

* the two- and three-mass oscillators (``TwoMass``, ``ThreeMass``) take the absolute height
  (:math:`\\Delta = 0`) and their relaxed height ``y_0`` is **set to the design wire height**, so
  the frame and head springs are relaxed when the head is at the design height and the contact
  force there is the uplift force minus the small frame-spring force (EN 50318 reference
  pantograph: 118.5 N static with F_0 = 120 N);
* the physical pantograph (``Pantograph``, ``PantographLinear``) works around
  :math:`\\eta = 2` m (its linkage geometry, thesis chapter 2): :math:`h_\\text{ref} = 2` m,
  so the wire's design height is mapped to 2 m and the wire's deviations are passed on unchanged;
* a user's FMU: :math:`\\Delta` as the user gives it (default 0).

Unilateral contact is switched on (parameter ``unilateral_contact`` of the project's FMUs): the
force is zero while the head is below the wire, and the master counts those samples as contact
loss. The master also clips a negative force of a user's FMU to zero (a contact cannot pull).

Named setups (:data:`PANTOGRAPH_NAMES`):

``en50318-2002``
    ``TwoMass`` with its defaults = the EN 50318:2002 reference pantograph (head 7.2 kg, frame
    15 kg, k 4200/50 N/m, c 10/90 N s/m, F_0 = 120 N, contact 50 kN/m; reference file [2nd]).
``benchmark-2015``
    ``ThreeMass`` with the 2015 benchmark values (Bruni et al., Vehicle System Dynamics 53(3),
    2015; reference file [2nd/recall]): m 6.0/9.0/7.5 kg, k 160/15500/7000 N/m base to head,
    frame damping 100 N s/m, the other dampers 0. The constant uplift force is not in the
    reference file: it is set to the EN 50367 target mean force for AC lines,
    :math:`F_0 = 0.00097 v^2 + 70` N (v in km/h; 130.6 N at 250, 169.3 N at 320 km/h)
    [project choice from a 2nd-tagged target, not a benchmark input].
``physical``
    The nonlinear ``Pantograph`` FMU (thesis model) at a bellow pressure chosen by the user
    (default 4 bar: static contact force 81 N at eta = 2 m).
``physical-linear``
    ``PantographLinear``, linearised about (eta0 = 2 m, p0 = the chosen pressure).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The named pantograph setups.
PANTOGRAPH_NAMES = ("en50318-2002", "benchmark-2015", "physical", "physical-linear")
#: Height around which the physical pantograph works (m); the wire's design height maps to it.
PHYSICAL_REFERENCE_HEIGHT = 2.0
#: Default bellow pressure of the physical pantograph (bar).
DEFAULT_PRESSURE_BAR = 4.0


def en50367_mean_force(speed_kmh: float) -> float:
    """Target mean contact force of EN 50367 for AC lines above 200 km/h (N).

    :math:`F_m = 0.00097 v^2 + 70` with v in km/h (reference file, section 3 [2nd]).
    """
    return 0.00097 * speed_kmh**2 + 70.0


@dataclass(frozen=True)
class PantographSetup:
    """One pantograph for the co-simulation (see module notes).

    Parameters
    ----------
    name : str
        Identifier (a name of :data:`PANTOGRAPH_NAMES`, or the user's).
    description : str
        One line for reports.
    fmu_name : str or None
        A project FMU (``"TwoMass"``, ...) built on demand when `fmu_path` is not given.
    fmu_path : str or None
        An ``.fmu`` file (the user's, or an already built project FMU).
    height_input : str
        FMU input receiving the wire height (m).
    force_output : str
        FMU output giving the contact force (N, positive pressing up on the wire).
    head_output : str or None
        FMU output giving the head height (m), recorded when given.
    parameters : tuple of (str, value)
        Parameters set in the FMU.
    constant_inputs : tuple of (str, float)
        Other inputs held constant (e.g. the bellow pressure ``p`` in bar).
    relaxed_height_parameter : str or None
        Parameter set to the line's design wire height (``y_0`` of the oscillators).
    reference_height : float or None
        :math:`h_\\text{ref}` (m): the design height maps to it (None: :math:`\\Delta` =
        `height_offset`).
    height_offset : float
        :math:`\\Delta` (m) when `reference_height` is None.
    uplift_parameter : str or None
        Parameter set to :func:`en50367_mean_force` of the running speed (benchmark-2015).
    unilateral_parameter : str or None
        Boolean parameter switched on for unilateral contact (None for a user FMU without it).
    provenance : str
        Where the values come from.
    """

    name: str
    description: str
    fmu_name: str | None = None
    fmu_path: str | None = None
    height_input: str = "eta"
    force_output: str = "F_c"
    head_output: str | None = "xi"
    parameters: tuple[tuple[str, Any], ...] = ()
    constant_inputs: tuple[tuple[str, float], ...] = ()
    relaxed_height_parameter: str | None = None
    reference_height: float | None = None
    height_offset: float = 0.0
    uplift_parameter: str | None = None
    unilateral_parameter: str | None = "unilateral_contact"
    provenance: str = ""

    def __post_init__(self) -> None:
        if self.fmu_name is None and self.fmu_path is None:
            raise ValueError(f"pantograph {self.name!r}: give an FMU file (fmu_path) or a "
                             "project FMU name (fmu_name)")
        object.__setattr__(self, "parameters", tuple((str(k), v) for k, v in
                                                     dict(self.parameters).items()))
        object.__setattr__(self, "constant_inputs", tuple(
            (str(k), float(v)) for k, v in dict(self.constant_inputs).items()))

    # --- derived values ------------------------------------------------------------------------

    def eta_offset(self, design_height: float) -> float:
        """:math:`\\Delta` (m) added to the absolute wire height to give the FMU's input."""
        if self.reference_height is None:
            return float(self.height_offset)
        return float(self.reference_height) - float(design_height)

    def fmu_parameters(self, design_height: float, speed_kmh: float) -> dict[str, Any]:
        """The parameters to set for a line of this design height at this speed.

        Unilateral contact, the relaxed height and the speed-dependent uplift come first;
        a value given explicitly in `parameters` wins over them.
        """
        values: dict[str, Any] = {}
        if self.unilateral_parameter:
            values[self.unilateral_parameter] = True
        if self.relaxed_height_parameter:
            values[self.relaxed_height_parameter] = float(design_height)
        if self.uplift_parameter:
            values[self.uplift_parameter] = en50367_mean_force(speed_kmh)
        values.update(self.parameters)
        return values

    def input_names(self) -> tuple[str, ...]:
        """FMU inputs set at every step: the height input first, then the constant ones."""
        return (self.height_input,) + tuple(name for name, _ in self.constant_inputs)

    def output_names(self) -> tuple[str, ...]:
        """FMU outputs read at every step: the force first, then the head height if any."""
        return (self.force_output,) + ((self.head_output,) if self.head_output else ())

    def with_fmu(self, path: str | Path) -> "PantographSetup":
        """The same setup on a given FMU file."""
        return dataclasses.replace(self, fmu_path=str(path))

    def with_parameters(self, source: Any = None, /, **values: Any) -> "PantographSetup":
        """The same setup with some parameters changed or added.

        Parameters
        ----------
        source : mapping, parameter file or identification result, optional
            Values read against this setup's FMU by
            :func:`panto.build_fmu.parameter_sources.fmu_parameter_values` (a parameter file:
            units converted, model checked; a result: its values of the FMU's parameters). What
            the setup itself sets for the line (unilateral contact, the relaxed height, the
            speed's uplift force) is not taken from a file or a result, which hold the model's
            defaults for them.
        **values
            Parameter name -> value; these win over `source` and the setup's own values.

        Returns
        -------
        PantographSetup
        """
        given = {} if source is None else self._values_from(source)
        return dataclasses.replace(self, parameters=tuple({**dict(self.parameters), **given,
                                                           **values}.items()))

    def _values_from(self, source: Any) -> dict[str, Any]:
        """Parameter values of `source` (see :meth:`with_parameters`) for this setup's FMU."""
        if isinstance(source, Mapping):
            return dict(source)
        from fmpy import read_model_description

        from panto.build_fmu.parameter_sources import fmu_parameter_values

        description = read_model_description(str(self.resolve_fmu()), validate=False)
        parameters = [v for v in description.modelVariables if v.causality == "parameter"]
        values = fmu_parameter_values(source, model=description.modelName,
                                      parameter_names=[v.name for v in parameters],
                                      units={v.name: v.unit or "" for v in parameters})
        own = {self.unilateral_parameter, self.relaxed_height_parameter, self.uplift_parameter}
        return {name: value for name, value in values.items() if name not in own}

    def resolve_fmu(self, cache_dir: str | Path | None = None,
                    progress: Callable[[str], None] | None = None) -> Path:
        """The FMU file: `fmu_path`, or the project FMU built on demand (see :func:`project_fmu`)."""
        if self.fmu_path is not None:
            path = Path(self.fmu_path).expanduser()
            if not path.exists():
                raise FileNotFoundError(f"pantograph {self.name!r}: FMU file {path} not found")
            return path
        return project_fmu(self.fmu_name, cache_dir=cache_dir, progress=progress)

    def to_dict(self) -> dict[str, Any]:
        """The setup as plain data (for result files)."""
        data = dataclasses.asdict(self)
        data["parameters"] = dict(self.parameters)
        data["constant_inputs"] = dict(self.constant_inputs)
        return data


def pantograph_setup(name: str, *, pressure_bar: float | None = None) -> PantographSetup:
    """A named setup (:data:`PANTOGRAPH_NAMES`).

    Parameters
    ----------
    name : str
        ``"en50318-2002"``, ``"benchmark-2015"``, ``"physical"`` or ``"physical-linear"``.
    pressure_bar : float, optional
        Bellow pressure of the physical setups (default 4 bar); refused for the others.

    Raises
    ------
    ValueError
        For an unknown name or a pressure given to an oscillator setup.
    """
    if name not in PANTOGRAPH_NAMES:
        raise ValueError(f"unknown pantograph {name!r}; choose one of {list(PANTOGRAPH_NAMES)} "
                         "or give an FMU file")
    if name in ("en50318-2002", "benchmark-2015"):
        if pressure_bar is not None:
            raise ValueError(f"pantograph {name!r} has a constant uplift force, not a bellow "
                             "pressure")
        return _oscillator_setup(name)
    pressure = DEFAULT_PRESSURE_BAR if pressure_bar is None else float(pressure_bar)
    if not 0.0 < pressure < 10.0:
        raise ValueError(f"bellow pressure must be in (0, 10) bar, got {pressure_bar!r}")
    linear = name == "physical-linear"
    return PantographSetup(
        name=name, fmu_name="PantographLinear" if linear else "Pantograph",
        description=(f"thesis pantograph{' linearised' if linear else ''}, bellow "
                     f"{pressure:g} bar"),
        parameters=(("eta0", PHYSICAL_REFERENCE_HEIGHT), ("p0", pressure)) if linear else (),
        constant_inputs=(("p", pressure),), reference_height=PHYSICAL_REFERENCE_HEIGHT,
        provenance="thesis Table 4.1 parameters (panto.fmu_src.pantograph); pressure: user")


def _oscillator_setup(name: str) -> PantographSetup:
    if name == "en50318-2002":
        return PantographSetup(
            name=name, fmu_name="TwoMass", relaxed_height_parameter="y_0",
            description="EN 50318:2002 reference pantograph (two masses, F_0 = 120 N)",
            parameters=(("m1", 15.0), ("k1", 50.0), ("c1", 90.0), ("m2", 7.2), ("k2", 4200.0),
                        ("c2", 10.0), ("F_0", 120.0), ("k_E", 50000.0)),
            provenance="EN 50318:2002 reference pantograph [2nd], reference/catenary_en50318.md")
    return PantographSetup(
        name=name, fmu_name="ThreeMass", relaxed_height_parameter="y_0", uplift_parameter="F_0",
        description="2015 benchmark pantograph (three masses, F_0 = EN 50367 target)",
        parameters=(("m1", 6.0), ("k1", 160.0), ("c1", 100.0), ("m2", 9.0), ("k2", 15500.0),
                    ("c2", 0.0), ("m3", 7.5), ("k3", 7000.0), ("c3", 0.0), ("k_E", 50000.0)),
        provenance="Bruni et al. 2015 benchmark [2nd/recall]; F_0 = 0.00097 v^2 + 70 N "
                   "(EN 50367 target) and zero head dampers: project choice")


def user_pantograph(fmu_path: str | Path, *, height_input: str, force_output: str,
                    head_output: str | None = None, height_offset: float = 0.0,
                    parameters: Mapping[str, Any] | None = None,
                    constant_inputs: Mapping[str, float] | None = None,
                    unilateral_parameter: str | None = None,
                    name: str | None = None) -> PantographSetup:
    """A user's FMU with an input for the wire height and an output for the contact force.

    The names are checked against the FMU when the co-simulation opens it (an unknown name is
    refused with the list of valid ones).
    """
    path = Path(fmu_path)
    return PantographSetup(
        name=name or path.stem, description=f"user FMU {path.name}", fmu_path=str(path),
        height_input=height_input, force_output=force_output, head_output=head_output,
        parameters=tuple(dict(parameters or {}).items()),
        constant_inputs=tuple(dict(constant_inputs or {}).items()), height_offset=height_offset,
        unilateral_parameter=unilateral_parameter, provenance="user")


# --- project FMUs built on demand (shared with the rig: panto.build_fmu.project) ---------------------

def project_fmu(name: str, *, cache_dir: str | Path | None = None,
                progress: Callable[[str], None] | None = None) -> Path:
    """The FMI 2.0 FMU of a project model, built on demand into the cache folder.

    See :func:`panto.build_fmu.project.project_fmu` (``$PANTO_FMU_CACHE`` or ``~/.cache/panto/fmus``,
    a sub-folder per source version; built in a scratch folder and moved into place).
    """
    from panto.build_fmu.project import project_fmu as build_or_find

    return build_or_find(name, cache_dir=cache_dir, progress=progress)


__all__ = ["PantographSetup", "pantograph_setup", "user_pantograph", "project_fmu",
           "en50367_mean_force", "PANTOGRAPH_NAMES"]
