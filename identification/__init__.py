"""Identification, design of experiments and sim-to-real diagnosis (issues 6-8): not implemented yet."""
