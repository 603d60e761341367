"""Shared fixtures: the project's FMUs, built once per test session."""
import pytest


@pytest.fixture(scope="session")
def project_fmus(tmp_path_factory):
    """All FMUs of ``panto build-fmu`` (FMI 2.0 and 3.0), as {file name: path}."""
    from panto.build_fmu.project import build_project_fmus

    built = build_project_fmus(tmp_path_factory.mktemp("fmus"))
    return {b.path.name: b for b in built}


@pytest.fixture(scope="session", autouse=True)
def fmu_cache(tmp_path_factory):
    """FMUs built on demand by the commands go to a temporary cache, not the user's home."""
    import os

    folder = tmp_path_factory.mktemp("fmu_cache")
    previous = os.environ.get("PANTO_FMU_CACHE")
    os.environ["PANTO_FMU_CACHE"] = str(folder)
    yield folder
    if previous is None:
        os.environ.pop("PANTO_FMU_CACHE", None)
    else:
        os.environ["PANTO_FMU_CACHE"] = previous
