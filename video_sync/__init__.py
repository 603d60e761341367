"""Video sidecar: marker tracking and PRBS synchronisation (issue 5): not implemented yet."""
