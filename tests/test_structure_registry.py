"""The table of model structures (panto.identification.structures.registry)."""
import importlib

import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.structures import registry
from panto.identification.structures.oscillators import OscillatorStructure
from panto.identification.structures.output_error import linear_output_error_from_data
from panto.identification.structures.physical import PhysicalLinear

#: The thesis' comparison (section 4.8) as ``panto compare`` fitted it before the table existed.
THESIS_COMPARISON = ("physical-linear", "physical", "two-mass", "two-mass-friction", "three-mass",
                     "three-mass-friction", "blackbox-4", "blackbox-6")


def _rig_data(n: int = 400) -> IdentificationData:
    """A rig-shaped run: eta, p in; F_c, y_cb out (a lag of the inputs, for shapes only)."""
    rng = np.random.default_rng(3)
    time = np.arange(n) * 0.02
    inputs = np.column_stack([2.0 + 0.01 * rng.standard_normal(n), 4.0 + 0.1 * rng.standard_normal(n)])
    outputs = np.column_stack([100.0 + 5.0 * inputs[:, 1], inputs[:, 0] - 0.01])
    return IdentificationData(time, inputs, outputs, ("eta", "p"), ("F_c", "y_cb"), source="rig")


@pytest.mark.parametrize("entry", registry.STRUCTURES, ids=lambda e: e.name)
def test_every_entry_names_functions_that_exist(entry):
    module = importlib.import_module(f"panto.identification.structures.{entry.module}")
    assert callable(getattr(module, entry.identify))
    if entry.build is not None:
        assert callable(getattr(module, entry.build))


@pytest.mark.parametrize("name", registry.structure_names())
def test_identifier_carries_its_name(name):
    found = registry.identifier(name)
    assert found.name == name
    assert callable(found.identify)
    assert found.description and "{" not in found.description


def test_the_comparison_is_the_thesis_table():
    assert [i.name for i in registry.comparison_identifiers()] == list(THESIS_COMPARISON)
    assert {n for n, i in registry.all_identifiers().items() if i.in_comparison} == \
        set(THESIS_COMPARISON)


def test_listed_names_are_the_ones_known_before():
    assert sorted(registry.structure_names()) == sorted(THESIS_COMPARISON + (
        "collector-head", "linear-2", "linear-4", "linear-6", "rigid-body"))


def test_unknown_name_is_one_line_listing_the_known_ones():
    with pytest.raises(IdentificationError) as error:
        registry.structure_info("no-such")
    message = str(error.value)
    assert "\n" not in message and "'no-such'" in message
    for shown in ("physical-linear", "three-mass-friction", "collector-head", "linear-N",
                  "blackbox-N", "rigid-body"):
        assert shown in message
    with pytest.raises(IdentificationError, match="known"):
        registry.identifier("linear-x")


def test_pantograph_flags():
    assert {n for n in registry.structure_names() if registry.is_pantograph_structure(n)} == {
        "physical", "physical-linear", "two-mass", "two-mass-friction", "three-mass",
        "three-mass-friction"}
    assert not registry.is_pantograph_structure("no-such")
    assert {n for n in registry.structure_names() if registry.parameter_set(n)} == {
        "physical", "physical-linear"}
    assert registry.parameter_set("physical-linear") == "Pantograph"


def test_a_family_takes_any_order():
    info = registry.structure_info("linear-8")
    assert info is registry.structure_info("linear-2")
    assert registry.identifier("linear-8").name == "linear-8"
    assert "order 8" in registry.identifier("linear-8").description


def test_built_structures_agree_with_direct_construction():
    data = _rig_data()
    built = registry.build_structure("three-mass-friction", data, {})
    direct = OscillatorStructure(3, True, outputs=data.output_names)
    assert built.name == direct.name == "three-mass-friction"
    assert built.parameter_names == direct.parameter_names
    np.testing.assert_allclose(built.simulate({}, data), direct.simulate({}, data))
    linear = registry.build_structure("physical-linear", data, {})
    assert isinstance(linear, PhysicalLinear) and linear.output_names == data.output_names
    oe = registry.build_structure("linear-3", data, {"input_delay": 1})
    reference = linear_output_error_from_data(data, 3, input_delay=1)
    assert oe.name == "linear-3" and oe.nominal() == reference.nominal()


def test_structures_the_diagnosis_cannot_build_are_named():
    with pytest.raises(IdentificationError, match="for the diagnosis: .*linear-N"):
        registry.build_structure("blackbox-4", _rig_data(), {})
    with pytest.raises(IdentificationError, match="'no-such' for the diagnosis"):
        registry.build_structure("no-such", _rig_data(), {})
