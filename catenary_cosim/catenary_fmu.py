"""The catenary as a Co-Simulation FMU (FMI 2.0), built with pythonfmu.

A user who wants to couple the finite-difference catenary with a pantograph FMU in another FMI
tool builds :class:`CatenaryFMU` into an ``.fmu`` with :func:`build_catenary_fmu` (or
``panto cosim --build-catenary-fmu DIR``).

Interface
    =====================  ==========  ===========================================================
    ``contact_force``      input, N    upward force of the pantograph on the wire during the step
    ``contact_position``   input, m    contact point x at the **end** of the step (0 = first
                                       support); within a step the FMU moves the force linearly
                                       from the previous step's position
    ``contact_wire_height`` output, m  absolute contact-wire height at ``contact_position``
    ``contact_wire_uplift`` output, m  the same minus the static height there
    ``support_uplift_max`` output, m   largest uplift at any support so far
    ``line``               parameter   line name (``en50318-2002``, ...) or path of a line file
    ``time_step``          parameter   catenary time step (s); every communication step must be
                                       a whole number of them
    ``element_length``     parameter   element length (m)
    ``damping``            parameter   Rayleigh damping on/off
    =====================  ==========  ===========================================================

    The force is held over a communication step and acts at the end of each catenary time step
    (implicit Newmark), exactly as in the in-process master :func:`.master.cosimulate`, so a
    master that steps this FMU and a pantograph FMU with the same Gauss-Seidel order reproduces
    the in-process results (the tests check it).

Requirement on the importing side
    The FMU contains pythonfmu's binary, which starts a Python interpreter, and this module; the
    catenary itself is imported from the ``catenary_cosim`` package. **The importing tool needs
    Python 3 with this package (``panto``) and its dependencies installed** and visible to the
    interpreter the FMU starts. Tools without that (many commercial importers) cannot run it; the
    pantograph FMUs have no such requirement (native C).
"""
from __future__ import annotations

from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real, String

#: Model name and file stem of the built FMU.
MODEL_NAME = "CatenaryFMU"


class CatenaryFMU(Fmi2Slave):
    """pythonfmu slave wrapping :class:`panto.catenary_cosim.catenary.Catenary` (see module notes)."""

    author = "panto"
    description = ("Finite-difference two-wire simple catenary (contact and messenger wire, "
                   "tension-only droppers) driven by a moving contact force; needs Python with "
                   "the panto package on the importing side")

    def __init__(self, **kwargs) -> None:
        super().__init__(**kwargs)
        self.line = "en50318-2002"
        self.time_step = 1e-4
        self.element_length = 0.25
        self.damping = True
        self.contact_force = 0.0
        self.contact_position = 0.0
        self.contact_wire_height = 0.0
        self.contact_wire_uplift = 0.0
        self.support_uplift_max = 0.0
        self._catenary = None
        self._position = 0.0
        parameter, fixed = Fmi2Causality.parameter, Fmi2Variability.fixed
        self.register_variable(String("line", causality=parameter, variability=fixed,
                                      description="line name or line file (JSON)"))
        for name, text in (("time_step", "catenary time step [s]"),
                           ("element_length", "element length [m]")):
            self.register_variable(Real(name, causality=parameter, variability=fixed,
                                        description=text))
        self.register_variable(Boolean("damping", causality=parameter, variability=fixed,
                                       description="Rayleigh damping of the line"))
        for name, text in (("contact_force", "upward contact force [N]"),
                           ("contact_position", "contact point x at the end of the step [m]")):
            self.register_variable(Real(name, causality=Fmi2Causality.input,
                                        variability=Fmi2Variability.continuous,
                                        description=text))
        for name, text in (("contact_wire_height", "contact-wire height at the contact [m]"),
                           ("contact_wire_uplift", "uplift at the contact point [m]"),
                           ("support_uplift_max", "largest support uplift so far [m]")):
            self.register_variable(Real(name, causality=Fmi2Causality.output,
                                        variability=Fmi2Variability.continuous,
                                        description=text))

    def exit_initialization_mode(self) -> None:
        """Build the catenary (mesh, static pre-state, factorisation) from the parameters."""
        from panto.catenary_cosim.catenary import Catenary
        from panto.catenary_cosim.lines import load_line

        self._catenary = Catenary(load_line(self.line), time_step=float(self.time_step),
                                  element_length=float(self.element_length),
                                  damping=bool(self.damping))
        self._position = float(self.contact_position)
        self.support_uplift_max = 0.0
        self._update_outputs()

    def do_step(self, current_time: float, step_size: float) -> bool:
        """Advance ``step_size / time_step`` catenary steps with the force held (module notes)."""
        catenary = self._catenary
        if catenary is None:
            return False
        ratio = step_size / catenary.time_step
        substeps = int(round(ratio))
        if substeps < 1 or abs(ratio - substeps) > 1e-6 * ratio:
            self.log(f"communication step {step_size} s is not a multiple of the time step "
                     f"{catenary.time_step} s")
            return False
        start, end, force = self._position, float(self.contact_position), self.contact_force
        for j in range(1, substeps + 1):
            catenary.advance(force, start + (end - start) * j / substeps)
        self._position = end
        self._update_outputs()
        return True

    def _update_outputs(self) -> None:
        x = float(self.contact_position)
        catenary = self._catenary
        self.contact_wire_height = catenary.contact_wire_height(x)
        self.contact_wire_uplift = self.contact_wire_height - float(
            catenary.static_contact_wire_height(x))
        self.support_uplift_max = max(self.support_uplift_max,
                                      float(max(catenary.support_uplift())))


def build_catenary_fmu(out_dir: str | Path) -> Path:
    """Build ``CatenaryFMU.fmu`` into `out_dir` (created) and return its path.

    The FMU's parameters choose the line and the discretisation at instantiation, so one FMU
    serves every line. See the module notes for the Python requirement on the importing side.
    """
    import shutil
    import sys
    import tempfile

    from pythonfmu import FmuBuilder

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    saved_path = list(sys.path)
    # pythonfmu puts the script's folder on sys.path (and leaves it there): build from a copy
    # in a scratch folder, so this package's modules never shadow standard ones
    # (``statistics``), and restore sys.path afterwards.
    with tempfile.TemporaryDirectory(prefix="catenary_fmu_") as scratch:
        script = Path(scratch) / Path(__file__).name
        shutil.copy2(__file__, script)
        try:
            path = Path(FmuBuilder.build_FMU(script, dest=out))
        finally:
            sys.path[:] = saved_path
            sys.modules.pop(script.stem, None)
    if not path.is_file() or path.stat().st_size == 0:
        raise RuntimeError(f"pythonfmu did not write {path}")
    return path


__all__ = ["CatenaryFMU", "build_catenary_fmu", "MODEL_NAME"]
