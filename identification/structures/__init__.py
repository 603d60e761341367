"""Model structures to identify: physical pantograph, oscillators, black box, collector head."""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "identifier": "registry",
    "structure_names": "registry",
    "build_structure": "registry",
    "PhysicalLinear": "physical",
    "PhysicalNonlinear": "physical",
    "OscillatorStructure": "oscillators",
    "identify_state_space": "blackbox",
    "identify_collector_head": "collector_head",
    "LinearOutputError": "output_error",
    "RigidBody": "rigid_body",
    "eigenvalue_sensitivity": "sensitivity",
})
