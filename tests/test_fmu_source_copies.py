"""The content-addressed copy of an FMU's sources that ``zig cc`` compiles (so that its cache
recognises sources it compiled before): named by the files' names and bytes, written once,
and the FMU's own ``sources/`` folder used where the copy cannot be written."""
from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from panto.build_fmu import compile as compile_module
from panto.build_fmu.build import build_fmu
from panto.build_fmu.compile import content_addressed

from fixtures.toy_model import make_toy_spec


def _write(folder: Path, files: dict[str, str]) -> Path:
    folder.mkdir(parents=True)
    for name, text in files.items():
        (folder / name).write_text(text)
    return folder


def test_the_same_files_share_one_copy_and_a_changed_byte_gets_another(tmp_path, monkeypatch):
    monkeypatch.setattr(compile_module.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    files = {"model.c": "int f(void) { return 1; }\n", "model_config.h": "#define N 2\n"}
    first = content_addressed(_write(tmp_path / "a" / "sources", files))
    second = content_addressed(_write(tmp_path / "b" / "sources", files))
    changed = content_addressed(_write(tmp_path / "c" / "sources",
                                       {**files, "model_config.h": "#define N 3\n"}))
    renamed = content_addressed(_write(tmp_path / "d" / "sources",
                                       {"other.c": files["model.c"],
                                        "model_config.h": files["model_config.h"]}))
    assert first == second and first.parent == tmp_path / "tmp" / compile_module.SOURCE_COPIES
    assert len({first, changed, renamed}) == 3
    assert {p.name: p.read_text() for p in first.iterdir()} == files
    stamp = (first / "model.c").stat().st_mtime_ns
    content_addressed(_write(tmp_path / "e" / "sources", files))
    assert (first / "model.c").stat().st_mtime_ns == stamp  # written once, never touched again
    assert not [p for p in first.parent.iterdir() if p.name.startswith(".part_")]


def test_where_the_copy_cannot_be_written_the_sources_are_compiled_in_place(tmp_path,
                                                                            monkeypatch):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the temporary folder should be")
    monkeypatch.setattr(compile_module.tempfile, "gettempdir", lambda: str(blocker))
    sources = _write(tmp_path / "sources", {"model.c": "int f(void) { return 1; }\n"})
    assert content_addressed(sources) == sources


@pytest.mark.skipif(compile_module.find_zig() is None, reason="needs ziglang")
def test_an_fmu_built_again_from_fresh_sources_has_the_same_library(tmp_path):
    """Two builds of one model into two folders (two fresh ``sources/``): the second takes
    zig's cached library, which must be the first's bytes."""
    libraries = []
    for folder in ("one", "two"):
        path = build_fmu(make_toy_spec(), tmp_path / folder, fmi_version=3)
        with zipfile.ZipFile(path) as archive:
            libraries.append({n: archive.read(n) for n in archive.namelist()
                              if n.startswith("binaries/") and not n.endswith("/")})
    assert libraries[0] and libraries[0] == libraries[1]
