"""Shared fixtures: the project's FMUs, built once per test run.

The suite runs in several processes (pytest-xdist, ``scripts/test``). A session fixture then runs
once per worker process; the expensive ones below build into a folder shared by the workers of
this run (the run's temporary base folder) under a file lock, so the first worker builds and the
others read what it built. Without xdist they use the session's own temporary folder.
"""
import contextlib
import os
import pickle
from pathlib import Path

import pytest

from panto.fmu_src.frame_stack import keep_stack_chunks

if os.environ.get("PYTEST_XDIST_WORKER") is not None:
    # each xdist worker already takes one core: a diagnosis' default process pool of every CPU
    # (panto.identification.diagnosis.parallel.resolve_workers) would oversubscribe them; tests
    # that ask for workers explicitly still get their pool
    os.environ.setdefault("PANTO_WORKERS", "1")

# every test's loops without CPython 3.11's frame-stack chunk thrashing, as the command line runs
# (panto.fmu_src.frame_stack: where a hot loop meets a chunk boundary depends on the stack's depth,
# which differs between a test and a user's run)
keep_stack_chunks()


def _shared_folder(tmp_path_factory: pytest.TempPathFactory, name: str) -> Path:
    """A folder shared by every xdist worker of this run, or this session's own without xdist."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        return tmp_path_factory.mktemp(name)
    folder = tmp_path_factory.getbasetemp().parent / name  # the run's folder, above popen-gwN
    folder.mkdir(exist_ok=True)
    return folder


@contextlib.contextmanager
def _exclusive(lock_file: Path):
    """Hold an exclusive lock on ``lock_file`` (POSIX ``flock``; no lock where it is missing)."""
    try:
        import fcntl
    except ImportError:  # Windows: the builds below are still correct, only repeated
        yield
        return
    with open(lock_file, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def project_fmus(tmp_path_factory):
    """The displacement-excited FMUs of ``panto build-fmu`` (FMI 2.0 and 3.0), as {file name: BuiltFmu}.

    The force-excited ones are :func:`force_fmus` (a separate fixture: they would add about
    20 s to every run that needs only these).

    Built once per run: the first worker builds them and records the result; the others wait on
    the lock and read the record.
    """
    from panto.fmu_src.models import DISPLACEMENT_FMU_NAMES

    return _built_once(tmp_path_factory, "fmus", DISPLACEMENT_FMU_NAMES)


@pytest.fixture(scope="session")
def force_fmus(tmp_path_factory):
    """The force-excited FMUs of ``panto build-fmu`` (FMI 2.0 and 3.0), as {file name: BuiltFmu}.

    Built once per run like :func:`project_fmus`.
    """
    from panto.fmu_src.models import FORCE_FMU_NAMES

    return _built_once(tmp_path_factory, "force_fmus", FORCE_FMU_NAMES)


def _built_once(tmp_path_factory, name: str, models) -> dict:
    """`models` built by ``panto build-fmu`` once per run into the shared folder `name`: the first
    worker builds them and records the result; the others wait on the lock and read the record.
    {file name: BuiltFmu}."""
    from panto.build_fmu.project import build_project_fmus

    folder = _shared_folder(tmp_path_factory, name)
    record = folder / "built.pickle"
    with _exclusive(folder / "build.lock"):
        if record.exists():
            built = pickle.loads(record.read_bytes())
        else:
            built = build_project_fmus(folder, names=models)
            record.write_bytes(pickle.dumps(built))
    return {b.path.name: b for b in built}


@pytest.fixture(scope="session", autouse=True)
def fmu_cache(tmp_path_factory):
    """FMUs built on demand by the commands go to a temporary cache, not the user's home.

    One cache for all workers of a run: ``project_fmu`` builds in a scratch folder and moves the
    file into place, so a worker never sees half an FMU (two workers may build the same one).
    """
    folder = _shared_folder(tmp_path_factory, "fmu_cache")
    previous = os.environ.get("PANTO_FMU_CACHE")
    os.environ["PANTO_FMU_CACHE"] = str(folder)
    yield folder
    if previous is None:
        os.environ.pop("PANTO_FMU_CACHE", None)
    else:
        os.environ["PANTO_FMU_CACHE"] = previous


#: The test files that take longest (seconds summed over their tests under the suite's two
#: workers, ``--junitxml``, measured 2026-11-28: the challenge's three seen cases 50 s, the sensor
#: mass 35 s, the rig story 33 s, the next ones 4-22 s), longest first. ``--dist loadfile`` hands
#: out files with the most tests first, so these few-test files came last and one worker ran
#: them alone at the end; started first, the other files fill the second worker meanwhile.
#: Only the order changes: a file missing here runs after these, a stale entry costs nothing.
LONGEST_FILES = (
    "test_diagnosis_challenge.py", "test_diagnosis_sensor_mass_global.py",
    "test_diagnosis_rig_story.py", "test_diagnosis_lag_global.py",
    "test_diagnosis_linear_shortfall.py", "test_diagnosis_pantograph.py",
    "test_parameters_and_cli.py", "test_diagnosis_effects.py", "test_global_fit.py",
    "test_adequacy.py", "test_fmu_finite.py", "test_diagnosis_real_data.py",
    "test_contact_in_contact_start.py", "test_video_tracking.py", "test_diagnosis.py",
    "test_diagnosis_calibration.py", "test_oscillator_mode.py", "test_fmu_binaries.py",
    "test_identification_physical.py", "test_crosscheck_fmus.py", "test_fmu_runtime.py",
    "test_video_sync.py", "test_effect_plants.py", "test_doe_virtual.py",
)


def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` with :data:`LONGEST_FILES` handed out first (longest first)."""
    if config.getoption("dist", None) != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class LongestFirst(LoadFileScheduling):
        """xdist's file-by-file scheduling, the queue reordered once before the first file."""

        ordered = False

        def _assign_work_unit(self, node):
            if not self.ordered:
                self.ordered = True
                rank = {name: i for i, name in enumerate(LONGEST_FILES)}
                queue = list(self.workqueue)
                for scope in sorted(queue, key=lambda s: (rank.get(_file_name(s), len(rank)),
                                                          queue.index(s))):
                    self.workqueue.move_to_end(scope)
            super()._assign_work_unit(node)

    return LongestFirst(config, log)


def _file_name(scope: str) -> str:
    """The file name of an xdist scope (``tests/test_x.py``)."""
    return scope.split("::")[0].rsplit("/", 1)[-1]
