"""Design of experiments (thesis chapter 5) and the designed runs of the pantograph rig."""

from panto import lazy_exports

# public names, imported on first use (importing the package stays cheap)
__all__, __getattr__, __dir__ = lazy_exports(__name__, {
    "fisher_information": "fisher",
    "design_line_experiment": "fisher",
    "design_offline": "input_design",
    "design_online": "online_design",
    "run_thesis_example": "thesis_example",
    "RigInputConstraints": "constraints",
    "design_pantograph_experiment": "pantograph",
    "DesignOptions": "pantograph",
    "write_design_profile": "profiles",
    "design_discrimination": "discrimination",
    "closed_loop_experiment": "closed_loop",
})
