"""Shared fixtures: the project's FMUs, built once per test session."""
import pytest


@pytest.fixture(scope="session")
def project_fmus(tmp_path_factory):
    """All FMUs of ``panto build-fmu`` (FMI 2.0 and 3.0), as {file name: path}."""
    from build_fmu.project import build_project_fmus

    built = build_project_fmus(tmp_path_factory.mktemp("fmus"))
    return {b.path.name: b for b in built}
