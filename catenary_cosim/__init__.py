"""Catenary co-simulation (issue 3): not implemented yet."""
