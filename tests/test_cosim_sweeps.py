"""Sweeps on executors (panto.catenary_cosim.sweeps): a process pool and a local Dask cluster give
exactly the numbers of the same runs done in this process."""
import dataclasses
import pickle
from concurrent.futures import ProcessPoolExecutor

import pytest

from panto.catenary_cosim.lines import load_line
from panto.catenary_cosim.pantographs import pantograph_setup
from panto.catenary_cosim.sweeps import (CosimulationCase, line_as_data, parameter_study, run_case,
                                   speed_sweep)

OPTIONS = dict(time_step=5e-4, element_length=2.0)


@pytest.fixture(scope="module")
def tiny():
    line = dataclasses.replace(load_line("en50318-2002"), spans=2, analysed_spans=(2, 2))
    return line


@pytest.fixture(scope="module")
def setup(project_fmus):
    return pantograph_setup("en50318-2002").with_fmu(project_fmus["TwoMass.fmu"].path)


def _local(line, setup, speed, changes=()):
    case = CosimulationCase(line_as_data(line), setup, speed, tuple(OPTIONS.items()), changes)
    result = run_case(case)
    assert result.success, result.message
    return result.statistics


def test_cases_are_picklable(tiny, setup):
    case = CosimulationCase(line_as_data(tiny), setup, 250.0, tuple(OPTIONS.items()))
    assert pickle.loads(pickle.dumps(case)) == case


def test_speed_sweep_on_a_process_pool(tiny, setup):
    lines = []
    with ProcessPoolExecutor(max_workers=2) as pool:
        results = speed_sweep(tiny, setup, [200.0, 260.0], executor=pool, progress=lines.append,
                              **OPTIONS)
    assert [r.case.speed_kmh for r in results] == [200.0, 260.0]
    assert len(lines) == 2 and all("km/h" in line for line in lines)
    for r in results:
        assert r.success, r.message
        assert r.statistics == _local(tiny, setup, r.case.speed_kmh)
    assert results[0].statistics != results[1].statistics


def test_parameter_study_on_a_local_dask_cluster(tiny, setup):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        results = parameter_study(tiny, setup, 250.0, line_field="steady_arm_stiffness",
                                  values=[300.0, 2673.58], executor=client, **OPTIONS)
    for r, stiffness in zip(results, (300.0, 2673.58)):
        assert r.success, r.message
        assert r.statistics == _local(tiny, setup, 250.0,
                                      (("steady_arm_stiffness", stiffness),))
    assert results[0].statistics["uplift_max_mm"] != results[1].statistics["uplift_max_mm"]


def test_a_failing_case_does_not_lose_the_others(tiny, setup):
    with ProcessPoolExecutor(max_workers=1) as pool:
        results = speed_sweep(tiny, setup, [250.0, 900.0], executor=pool, **OPTIONS)
    assert results[0].success
    assert not results[1].success and "wave speed" in results[1].message
