"""The ``panto`` command line: one entry point for building FMUs and running the main job."""
