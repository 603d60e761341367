"""Rig sidecar and virtual test bed (issue 4): not implemented yet."""
