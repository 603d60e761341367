"""Overhead contact lines as data: the reference lines of EN 50318 and the thesis, read from JSON.

A line file (``catenary_cosim/lines/<name>.json``) is a JSON object a person can read and edit::

    {"name": "en50318-2002",
     "description": "...",
     "items": {"span_length": {"value": 60.0, "unit": "m", "provenance": "2nd",
                               "note": "optional reason or source"},
               ...}}

Every item carries its value, its unit (checked, so that a value typed in kN is refused rather than
read as N) and a provenance tag as in ``shared/reference/catenary_en50318.md``: ``2nd`` (read in a
secondary source), ``2nd x2`` (two independent secondary sources agree), ``recall`` (from memory of
the literature, unverified) or ``project choice`` (a value this project picked where the reference is
silent or unsure; the note gives the reason). All values are SI except ``suggested_speeds_kmh``.

References
----------
EN 50318:2002, *Railway applications - Current collection systems - Validation of simulation of the
dynamic interaction between pantograph and overhead contact line*, CENELEC.

S. Bruni et al., "The results of the pantograph-catenary interaction benchmark", *Vehicle System
Dynamics* 53(3), 2015, pp. 412-435.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

LINE_DIRECTORY = Path(__file__).parent / "lines"
LINE_NAMES: tuple[str, ...] = ("en50318-2002", "benchmark-2015", "thesis-60m")
END_TREATMENTS: tuple[str, ...] = ("pinned",)


@dataclass(frozen=True)
class Wire:
    """A tensioned wire modelled as an Euler-Bernoulli beam.

    Parameters
    ----------
    mass_per_length : float
        Mass per unit length rho A [kg/m].
    tension : float
        Axial tension T [N].
    bending_stiffness : float
        Bending stiffness EI [N m^2].
    """

    mass_per_length: float
    tension: float
    bending_stiffness: float

    @property
    def wave_speed(self) -> float:
        """Transverse wave speed of the string part, c = sqrt(T / (rho A)) [m/s]."""
        return math.sqrt(self.tension / self.mass_per_length)


@dataclass(frozen=True)
class LineDefinition:
    """One simple catenary (contact wire hung by droppers from a messenger wire), all SI.

    Parameters
    ----------
    name, description : str
        Identifier (e.g. ``"en50318-2002"``) and a sentence on what the line is.
    spans : int
        Number of spans modelled.
    span_length : float
        Distance between supports [m].
    contact_wire_height : float
        Design height of the contact wire at the supports [m].
    system_height : float
        Messenger height above the contact wire at the supports (encumbrance) [m].
    contact_wire, messenger_wire : Wire
        Properties of the two wires.
    dropper_positions : tuple of float
        Dropper positions within a span, measured from the span's first support [m]; the same in
        every span.
    dropper_presag : tuple of float
        Design sag of the contact wire below its support height at each dropper [m] (0 = level).
    dropper_stiffness : float
        Axial stiffness of a taut dropper [N/m]; a slack dropper carries no force.
    dropper_mass_per_length : float
        Dropper mass per unit length [kg/m] (lumped half to each clamp).
    dropper_clamp_mass_contact, dropper_clamp_mass_messenger : float
        Clamp masses at the contact-wire and the messenger ends [kg].
    steady_arm_stiffness, steady_arm_mass : float
        Vertical stiffness [N/m] and lumped mass [kg] of a steady arm (contact-wire support).
    messenger_support_stiffness, messenger_support_mass : float
        Vertical stiffness [N/m] and lumped mass [kg] of a messenger support.
    rayleigh_alpha, rayleigh_beta : float
        Structural damping C = alpha M + beta K [1/s, s].
    end_treatment : str
        What happens at the outermost supports (``"pinned"``: both wires held at their support
        heights, free to rotate).
    analysed_spans : tuple of int
        First and last analysed span, 1-based and inclusive (``(5, 6)`` = the two central spans of
        ten).
    suggested_speeds_kmh : tuple of float
        Train speeds the line is meant to be run at [km/h].
    dropper_nominal_lengths : tuple of float or None
        Published dropper lengths for comparison with the computed ones [m], if any.
    provenance : mapping
        Item name -> provenance tag (``"2nd"``, ``"2nd x2"``, ``"recall"``, ``"project choice"``).
    notes : mapping
        Item name -> reason or source, where the file gives one.
    source : str
        The file the line was read from.
    """

    name: str
    description: str
    spans: int
    span_length: float
    contact_wire_height: float
    system_height: float
    contact_wire: Wire
    messenger_wire: Wire
    dropper_positions: tuple[float, ...]
    dropper_presag: tuple[float, ...]
    dropper_stiffness: float
    dropper_mass_per_length: float
    dropper_clamp_mass_contact: float
    dropper_clamp_mass_messenger: float
    steady_arm_stiffness: float
    steady_arm_mass: float
    messenger_support_stiffness: float
    messenger_support_mass: float
    rayleigh_alpha: float
    rayleigh_beta: float
    end_treatment: str
    analysed_spans: tuple[int, int]
    suggested_speeds_kmh: tuple[float, ...]
    dropper_nominal_lengths: tuple[float, ...] | None = None
    provenance: Mapping[str, str] = field(default_factory=dict)
    notes: Mapping[str, str] = field(default_factory=dict)
    source: str = "in memory"

    def __post_init__(self):
        for item in ("dropper_positions", "dropper_presag", "suggested_speeds_kmh", "analysed_spans"):
            object.__setattr__(self, item, tuple(getattr(self, item)))
        if self.dropper_nominal_lengths is not None:
            object.__setattr__(self, "dropper_nominal_lengths", tuple(self.dropper_nominal_lengths))
        _validate(self, self.source)
        object.__setattr__(self, "provenance", MappingProxyType(dict(self.provenance)))
        object.__setattr__(self, "notes", MappingProxyType(dict(self.notes)))

    @property
    def length(self) -> float:
        """Total modelled length, first to last support [m]."""
        return self.spans * self.span_length

    @property
    def analysed_section(self) -> tuple[float, float]:
        """Start and end of the analysed spans [m] (x = 0 at the first support)."""
        first, last = self.analysed_spans
        return ((first - 1) * self.span_length, last * self.span_length)

    @property
    def suggested_speeds(self) -> tuple[float, ...]:
        """Suggested train speeds [m/s]."""
        return tuple(v / 3.6 for v in self.suggested_speeds_kmh)


# --- the file format ----------------------------------------------------------------------------
# item -> (unit, kind); kinds: "count", "positive", "nonnegative", "number", "positions", "sags",
# "lengths", "span_pair", "speeds", "end"
_ITEMS: dict[str, tuple[str, str]] = {
    "spans": ("1", "count"),
    "span_length": ("m", "positive"),
    "contact_wire_height": ("m", "positive"),
    "system_height": ("m", "positive"),
    "contact_wire_mass_per_length": ("kg/m", "positive"),
    "contact_wire_tension": ("N", "positive"),
    "contact_wire_bending_stiffness": ("N m^2", "nonnegative"),
    "messenger_wire_mass_per_length": ("kg/m", "positive"),
    "messenger_wire_tension": ("N", "positive"),
    "messenger_wire_bending_stiffness": ("N m^2", "nonnegative"),
    "dropper_positions": ("m", "positions"),
    "dropper_presag": ("m", "sags"),
    "dropper_nominal_lengths": ("m", "lengths"),
    "dropper_stiffness": ("N/m", "positive"),
    "dropper_mass_per_length": ("kg/m", "nonnegative"),
    "dropper_clamp_mass_contact": ("kg", "nonnegative"),
    "dropper_clamp_mass_messenger": ("kg", "nonnegative"),
    "steady_arm_stiffness": ("N/m", "nonnegative"),
    "steady_arm_mass": ("kg", "nonnegative"),
    "messenger_support_stiffness": ("N/m", "positive"),
    "messenger_support_mass": ("kg", "nonnegative"),
    "rayleigh_alpha": ("1/s", "nonnegative"),
    "rayleigh_beta": ("s", "nonnegative"),
    "end_treatment": ("-", "end"),
    "analysed_spans": ("1", "span_pair"),
    "suggested_speeds_kmh": ("km/h", "speeds"),
}
_OPTIONAL = frozenset({"dropper_nominal_lengths"})


def load_line(name_or_path: str | Path) -> LineDefinition:
    """Read a line definition by name (one of `LINE_NAMES`) or from a JSON file.

    Parameters
    ----------
    name_or_path : str or Path
        A line name such as ``"en50318-2002"`` or the path of a line file.

    Returns
    -------
    LineDefinition

    Raises
    ------
    ValueError
        If the file is missing, not JSON, or an item is missing, unknown, of the wrong unit or
        out of its admissible range; the message names the file, the item and the value.
    """
    path = _resolve(name_or_path)
    try:
        data = json.loads(path.read_text())
    except OSError as error:
        raise ValueError(f"{path}: cannot read line file ({error})") from error
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON ({error})") from error
    return line_from_dict(data, source=str(path))


def line_from_dict(data: Any, *, source: str = "in memory") -> LineDefinition:
    """Build a `LineDefinition` from the parsed JSON object of a line file (see `load_line`)."""
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a JSON object, got {type(data).__name__}")
    unknown_top = sorted(set(data) - {"name", "description", "items"})
    if unknown_top:
        raise ValueError(f"{source}: unknown top-level field(s) {unknown_top}")
    for key in ("name", "description"):
        if not isinstance(data.get(key), str) or not data[key].strip():
            raise ValueError(f"{source}: field {key!r} must be a non-empty string, got "
                             f"{data.get(key)!r}")
    items = data.get("items")
    if not isinstance(items, dict):
        raise ValueError(f"{source}: field 'items' must be an object, got {items!r}")
    unknown = sorted(set(items) - set(_ITEMS))
    missing = sorted(set(_ITEMS) - set(items) - _OPTIONAL)
    if unknown:
        raise ValueError(f"{source}: unknown item(s) {unknown}; known: {sorted(_ITEMS)}")
    if missing:
        raise ValueError(f"{source}: missing item(s) {missing}")
    values, provenance, notes = {}, {}, {}
    for key, entry in items.items():
        values[key], provenance[key], note = _read_item(key, entry, source)
        if note:
            notes[key] = note
    wires = {}
    for wire in ("contact_wire", "messenger_wire"):
        wires[wire] = Wire(values.pop(f"{wire}_mass_per_length"), values.pop(f"{wire}_tension"),
                           values.pop(f"{wire}_bending_stiffness"))
    return LineDefinition(name=data["name"], description=data["description"], **wires, **values,
                          provenance=provenance, notes=notes, source=source)


def _resolve(name_or_path: str | Path) -> Path:
    text = str(name_or_path)
    if text in LINE_NAMES or (not text.endswith(".json") and "/" not in text and "\\" not in text):
        path = LINE_DIRECTORY / f"{text}.json"
        if not path.exists():
            raise ValueError(f"unknown line {text!r}; known lines: {', '.join(LINE_NAMES)} "
                             "(or give the path of a .json line file)")
        return path
    return Path(name_or_path)


def _read_item(key: str, entry: Any, source: str) -> tuple[Any, str, str]:
    unit, kind = _ITEMS[key]
    where = f"{source}: item {key!r}"
    if not isinstance(entry, dict) or "value" not in entry:
        raise ValueError(f"{where}: expected an object with 'value', 'unit' and 'provenance', "
                         f"got {entry!r}")
    extra = sorted(set(entry) - {"value", "unit", "provenance", "note"})
    if extra:
        raise ValueError(f"{where}: unknown field(s) {extra}")
    if entry.get("unit") != unit:
        raise ValueError(f"{where}: unit {entry.get('unit')!r} is not the expected {unit!r}")
    tag = entry.get("provenance")
    if not isinstance(tag, str) or not tag.strip():
        raise ValueError(f"{where}: needs a non-empty 'provenance' tag, got {tag!r}")
    note = entry.get("note", "")
    if not isinstance(note, str):
        raise ValueError(f"{where}: 'note' must be a string, got {note!r}")
    return _convert(kind, entry["value"], where), tag.strip(), note.strip()


def _convert(kind: str, value: Any, where: str) -> Any:
    if kind == "end":
        if value not in END_TREATMENTS:
            raise ValueError(f"{where}: value {value!r} is not one of {list(END_TREATMENTS)}")
        return value
    if kind == "count":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{where}: value {value!r} is not an integer")
        return value
    if kind in ("positive", "nonnegative", "number"):
        return _number(value, where)
    if kind == "lengths" and value is None:
        return None
    if not isinstance(value, list):
        raise ValueError(f"{where}: value {value!r} is not a list")
    if kind == "span_pair":
        if len(value) != 2 or any(isinstance(v, bool) or not isinstance(v, int) for v in value):
            raise ValueError(f"{where}: value {value!r} is not a pair of integers [first, last]")
        return tuple(value)
    return tuple(_number(v, where) for v in value)


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where}: value {value!r} is not a number")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{where}: value {number!r} is not finite")
    return number


# --- physical admissibility (also applied to lines built in code) --------------------------------
def _validate(line: LineDefinition, source: str) -> None:
    def fail(item: str, value: Any, problem: str) -> None:
        raise ValueError(f"{source}: item {item!r} = {value!r} {problem}")

    if isinstance(line.spans, bool) or not isinstance(line.spans, int) or line.spans < 1:
        fail("spans", line.spans, "must be a positive integer")
    positive = {"span_length": line.span_length, "contact_wire_height": line.contact_wire_height,
                "system_height": line.system_height, "dropper_stiffness": line.dropper_stiffness,
                "messenger_support_stiffness": line.messenger_support_stiffness}
    for prefix, wire in (("contact_wire", line.contact_wire), ("messenger_wire", line.messenger_wire)):
        positive[f"{prefix}_mass_per_length"] = wire.mass_per_length
        positive[f"{prefix}_tension"] = wire.tension
        if not wire.bending_stiffness >= 0.0:
            fail(f"{prefix}_bending_stiffness", wire.bending_stiffness, "must be >= 0")
    for item, value in positive.items():
        if not (math.isfinite(value) and value > 0.0):
            fail(item, value, "must be a positive number")
    for item in ("dropper_mass_per_length", "dropper_clamp_mass_contact",
                 "dropper_clamp_mass_messenger", "steady_arm_stiffness", "steady_arm_mass",
                 "messenger_support_mass", "rayleigh_alpha", "rayleigh_beta"):
        value = getattr(line, item)
        if not (math.isfinite(value) and value >= 0.0):
            fail(item, value, "must be a finite number >= 0")
    _validate_droppers(line, fail)
    if line.end_treatment not in END_TREATMENTS:
        fail("end_treatment", line.end_treatment, f"is not one of {list(END_TREATMENTS)}")
    if len(line.analysed_spans) != 2:
        fail("analysed_spans", list(line.analysed_spans), "must be a pair [first, last]")
    first, last = line.analysed_spans
    if not 1 <= first <= last <= line.spans:
        fail("analysed_spans", list(line.analysed_spans),
             f"must satisfy 1 <= first <= last <= spans ({line.spans})")
    if not line.suggested_speeds_kmh or any(not v > 0.0 for v in line.suggested_speeds_kmh):
        fail("suggested_speeds_kmh", list(line.suggested_speeds_kmh),
             "must be a non-empty list of positive speeds")


def _validate_droppers(line: LineDefinition, fail) -> None:
    positions = line.dropper_positions
    for x in positions:
        if not 0.0 < x < line.span_length:
            fail("dropper_positions", x, f"lies outside the span (0, {line.span_length}) m")
    if any(b <= a for a, b in zip(positions, positions[1:])):
        fail("dropper_positions", list(positions), "must be strictly increasing")
    if len(line.dropper_presag) != len(positions):
        fail("dropper_presag", list(line.dropper_presag),
             f"needs one value per dropper ({len(positions)})")
    for sag in line.dropper_presag:
        if not abs(sag) < line.system_height:
            fail("dropper_presag", sag, f"exceeds the system height {line.system_height} m")
    nominal = line.dropper_nominal_lengths
    if nominal is not None:
        if len(nominal) != len(positions):
            fail("dropper_nominal_lengths", list(nominal),
                 f"needs one value per dropper ({len(positions)})")
        if any(not v > 0.0 for v in nominal):
            fail("dropper_nominal_lengths", list(nominal), "must all be positive")
