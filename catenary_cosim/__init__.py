"""Catenary co-simulation: a finite-difference overhead contact line driven against pantograph FMUs."""
from panto.catenary_cosim.catenary import Catenary
from panto.catenary_cosim.lines import LINE_NAMES, LineDefinition, Wire, load_line

__all__ = ["Catenary", "LINE_NAMES", "LineDefinition", "Wire", "load_line"]
