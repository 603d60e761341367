"""The main job's scheduling (panto.demo): a step beside the others, the FMUs built in parts."""
from __future__ import annotations

import os

import pytest

import panto.demo as demo


def _gives_its_pid(state, progress):
    state["gift"] = os.getpid()
    progress("worked")
    return {"pid": os.getpid()}


def _plain(state, progress):
    return {"pid": os.getpid()}


def _needs_the_gift(state, progress):
    return {"gift": state["gift"]}


def _fails(state, progress):
    raise ValueError("the camera lens is cracked")


def _three_steps(first):
    return lambda: (demo.Step("one", "beside", first, gives=("gift",)),
                    demo.Step("two", "plain", _plain),
                    demo.Step("three", "needs the gift", _needs_the_gift, ("gift",)))


@pytest.mark.parametrize("workers", [1, 2])
def test_a_step_beside_the_others_hands_on_what_it_gives_in_order(tmp_path, monkeypatch,
                                                                   workers):
    monkeypatch.setattr(demo, "_steps", _three_steps(_gives_its_pid))
    lines: list[str] = []
    summary = demo.run_demo(tmp_path, progress=lines.append,
                            settings=demo.DemoSettings(workers=workers))
    assert [(s["name"], s["status"]) for s in summary["steps"]] == [
        ("one", "ok"), ("two", "ok"), ("three", "ok")]
    # in a worker process only when there are workers; the main job's own steps stay here
    assert (summary["one"]["pid"] != os.getpid()) == (workers > 1)
    assert summary["two"]["pid"] == os.getpid()
    # what it gave reached the step that needs it, and its lines came before that step's
    assert summary["three"]["gift"] == summary["one"]["pid"]
    assert lines.index("      worked") < lines.index("[3/3] needs the gift")
    assert summary["steps"][0]["seconds"] > 0.0


def test_a_failing_step_beside_the_others_is_recorded_and_its_followers_skipped(tmp_path,
                                                                               monkeypatch):
    monkeypatch.setattr(demo, "_steps", _three_steps(_fails))
    with pytest.raises(demo.DemoError):
        demo.run_demo(tmp_path, progress=lambda line: None,
                      settings=demo.DemoSettings(workers=2))
    import json

    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [s["status"] for s in summary["steps"]] == ["failed", "ok", "skipped"]
    assert "lens is cracked" in summary["steps"][0]["message"]


def _fake_build(folder, *, names, fmi_versions, progress):
    from panto.build_fmu.project import BuiltFmu

    built = []
    for name in names:
        for version in fmi_versions:
            progress(f"{name} {version} in {os.getpid()}")
            built.append(BuiltFmu(name, version, folder / f"{name}_{version}.fmu", (), 0.0))
    return built


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_the_fmus_built_in_parts_come_back_in_order_with_their_lines(tmp_path, monkeypatch,
                                                                     workers):
    import panto.build_fmu.project as project
    from panto.demo_steps import build_fmus
    from panto.fmu_src.models import FMU_NAMES

    monkeypatch.setattr(project, "build_project_fmus", _fake_build)
    lines: list[str] = []
    state = {"out": tmp_path, "settings": demo.DemoSettings(workers=workers)}
    result = build_fmus(state, lines.append)
    expected = [(name, version) for name in FMU_NAMES for version in (2, 3)]
    assert [(f["file"].split("_")[0], f["fmi_version"]) for f in result["fmus"]] == expected
    assert [line.split(" in ")[0] for line in lines] == [f"{n} {v}" for n, v in expected]
    # the first part is built here, the others in worker processes (at most workers in all)
    pids = [int(line.split(" in ")[1]) for line in lines]
    assert pids[0] == os.getpid()
    assert (len(set(pids)) > 1) == (workers > 1) and len(set(pids)) <= workers
    assert state["fmus"] == tmp_path / "fmus"
