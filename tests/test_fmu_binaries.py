"""The cross-compiled FMU binaries, checked statically from their file headers.

For every platform an FMU carries: the file format and architecture (ELF ``e_machine``, PE
``Machine``, Mach-O ``cputype``), the exported ``fmi2*``/``fmi3*`` functions against the ones the
standard's header declares, the libraries it imports (only the platform's C runtime), and for
Linux the highest glibc symbol version it needs (<= 2.17). The readers below are small pure-Python
parsers of the three formats (no pyelftools/pefile/macholib: a few dozen lines each, and no extra
test dependencies). The FMUs are built once, from the toy model, for both FMI versions.
"""
from __future__ import annotations

import logging
import re
import struct
import zipfile
from pathlib import Path

import pytest
from fmpy import simulate_fmu

from panto.build_fmu import build_fmu
from panto.build_fmu import compile as compile_module
from panto.build_fmu.package import BinaryPlatform, fmu_platforms, host_platform
from panto.fmu_src.spec import RUNTIME_DIR
from fixtures.toy_model import make_toy_spec

pytestmark = pytest.mark.skipif(compile_module.find_zig() is None or host_platform() is None
                                or host_platform().fmi3_tuple != "x86_64-linux",
                                reason="needs ziglang on a linux x86-64 machine")

FMI2_FOLDERS = {"linux64": ("ELF", {"x86_64"}), "win64": ("PE", {"x86_64"}),
                "darwin64": ("Mach-O", {"x86_64", "arm64"})}
FMI3_TUPLES = {"x86_64-linux": ("ELF", {"x86_64"}), "aarch64-linux": ("ELF", {"aarch64"}),
               "x86_64-windows": ("PE", {"x86_64"}), "x86_64-darwin": ("Mach-O", {"x86_64"}),
               "aarch64-darwin": ("Mach-O", {"arm64"})}
ALLOWED_IMPORTS = {"ELF": re.compile(r"^(libc\.so\.6|libm\.so\.6)$"),
                   "PE": re.compile(r"^(kernel32|msvcrt|ucrtbase|api-ms-win-crt-[a-z0-9-]+)\.dll$",
                                    re.IGNORECASE),
                   "Mach-O": re.compile(r"^/usr/lib/libSystem\.B\.dylib$")}
#: Symbols the macOS linker adds to every dylib's exports (besides those, only fmi* functions).
LINKER_SYMBOLS = {"__dso_handle", "_mh_dylib_header"}


# --- ELF (64-bit little-endian) ---------------------------------------------------------------

def _cstring(data: bytes, offset: int) -> str:
    return data[offset:data.index(b"\0", offset)].decode()


def read_elf(data: bytes) -> dict:
    """Architecture, exported symbols, needed libraries and needed symbol versions of an ELF."""
    assert data[:4] == b"\x7fELF" and data[4] == 2 and data[5] == 1, "not a 64-bit LE ELF"
    machine = {62: "x86_64", 183: "aarch64"}.get(struct.unpack_from("<H", data, 0x12)[0], "?")
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize)
                for i in range(shnum)]
    exports, needed, versions = set(), set(), set()
    for _, kind, _, _, offset, size, link, info, _, _ in sections:
        strings = sections[link][4]
        if kind == 11:  # SHT_DYNSYM
            for start in range(offset + 24, offset + size, 24):
                name, info_byte, other, shndx = struct.unpack_from("<IBBH", data, start)
                if shndx != 0 and info_byte >> 4 in (1, 2) and other & 3 == 0:
                    exports.add(_cstring(data, strings + name))
        elif kind == 6:  # SHT_DYNAMIC
            for start in range(offset, offset + size, 16):
                tag, value = struct.unpack_from("<qQ", data, start)
                if tag == 1:  # DT_NEEDED
                    needed.add(_cstring(data, strings + value))
        elif kind == 0x6FFFFFFE:  # SHT_GNU_verneed
            entry = offset
            for _ in range(info):
                _, count, _, aux, next_entry = struct.unpack_from("<HHIII", data, entry)
                position = entry + aux
                for _ in range(count):
                    _, _, _, name, next_aux = struct.unpack_from("<IHHII", data, position)
                    versions.add(_cstring(data, strings + name))
                    position += next_aux
                entry += next_entry
    return {"format": "ELF", "arch": {machine}, "exports": exports, "imports": needed,
            "versions": versions}


# --- PE32+ ------------------------------------------------------------------------------------

def read_pe(data: bytes) -> dict:
    """Architecture, exported names and imported DLLs of a PE32+ DLL."""
    assert data[:2] == b"MZ"
    pe, = struct.unpack_from("<I", data, 0x3C)
    assert data[pe:pe + 4] == b"PE\0\0"
    machine, nsections, _, _, _, optional_size, characteristics = struct.unpack_from(
        "<HHIIIHH", data, pe + 4)
    optional = pe + 24
    assert struct.unpack_from("<H", data, optional)[0] == 0x20B, "not PE32+"
    assert characteristics & 0x2000, "not a DLL"
    export_rva, _, import_rva, _ = struct.unpack_from("<IIII", data, optional + 112)
    table = optional + optional_size
    sections = [struct.unpack_from("<8sIIII", data, table + 40 * i) for i in range(nsections)]

    def offset(rva: int) -> int:
        for _, virtual_size, address, raw_size, raw in sections:
            if address <= rva < address + max(virtual_size, raw_size):
                return raw + rva - address
        raise ValueError(f"RVA {rva:#x} in no section")

    exports = set()
    if export_rva:
        count, = struct.unpack_from("<I", data, offset(export_rva) + 24)
        names, = struct.unpack_from("<I", data, offset(export_rva) + 32)
        exports = {_cstring(data, offset(struct.unpack_from("<I", data, offset(names) + 4 * i)[0]))
                   for i in range(count)}
    imports, position = set(), offset(import_rva) if import_rva else None
    while position is not None:
        descriptor = struct.unpack_from("<IIIII", data, position)
        if not any(descriptor):
            break
        imports.add(_cstring(data, offset(descriptor[3])))
        position += 20
    return {"format": "PE", "arch": {"x86_64"} if machine == 0x8664 else {hex(machine)},
            "exports": exports, "imports": imports}


# --- Mach-O (64-bit, thin or universal) -------------------------------------------------------

def _uleb(data: bytes, position: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[position]
        position += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, position


def _trie_names(trie: bytes, node: int = 0, prefix: str = "") -> set[str]:
    """Every symbol of a dyld export trie (depth first)."""
    terminal, position = _uleb(trie, node)
    names = {prefix} if terminal else set()
    position += terminal
    children = trie[position]
    position += 1
    for _ in range(children):
        end = trie.index(b"\0", position)
        edge = trie[position:end].decode()
        child, position = _uleb(trie, end + 1)
        names |= _trie_names(trie, child, prefix + edge)
    return names


def read_thin_macho(data: bytes) -> dict:
    """Architecture, exports (from the export trie), linked dylibs and signature of a Mach-O."""
    magic, cputype, _, filetype, ncmds = struct.unpack_from("<IiIII", data)
    assert magic == 0xFEEDFACF and filetype == 6, "not a 64-bit Mach-O dylib"
    position, exports, imports, signed = 32, set(), set(), False
    for _ in range(ncmds):
        command, size = struct.unpack_from("<II", data, position)
        if command in (0xC, 0x80000018, 0x8000001F):  # LC_LOAD/_WEAK/REEXPORT_DYLIB
            name, = struct.unpack_from("<I", data, position + 8)
            imports.add(_cstring(data, position + name))
        elif command in (0x80000022, 0x22, 0x80000033):  # DYLD_INFO(_ONLY), EXPORTS_TRIE
            field = 8 + 4 * 8 if command != 0x80000033 else 8
            start, length = struct.unpack_from("<II", data, position + field)
            if length:
                exports |= _trie_names(data[start:start + length])
        elif command == 0x1D:  # LC_CODE_SIGNATURE
            signed = True
        position += size
    arch = {0x01000007: "x86_64", 0x0100000C: "arm64"}.get(cputype, hex(cputype))
    return {"format": "Mach-O", "arch": {arch}, "imports": imports, "signed": signed,
            "exports": {name[1:] for name in exports if name.startswith("_")}}


def read_macho(data: bytes) -> dict:
    """A thin Mach-O, or a universal one: then every slice, which must agree on exports."""
    if struct.unpack_from(">I", data)[0] != 0xCAFEBABE:
        slices = [read_thin_macho(data)]
    else:
        count, = struct.unpack_from(">I", data, 4)
        slices = []
        for i in range(count):
            _, _, offset, size, align = struct.unpack_from(">iIIII", data, 8 + 20 * i)
            assert offset % 2 ** align == 0
            slices.append(read_thin_macho(data[offset:offset + size]))
    assert all(s["exports"] == slices[0]["exports"] for s in slices)
    return {"format": "Mach-O", "arch": set().union(*(s["arch"] for s in slices)),
            "exports": slices[0]["exports"],
            "imports": set().union(*(s["imports"] for s in slices)),
            "arm64_signed": all(s["signed"] for s in slices if s["arch"] == {"arm64"})}


def read_binary(data: bytes) -> dict:
    """Dispatch on the magic number."""
    if data[:4] == b"\x7fELF":
        return read_elf(data)
    if data[:2] == b"MZ":
        return read_pe(data)
    return read_macho(data)


# --- the tests --------------------------------------------------------------------------------

def declared_functions(version: int) -> set[str]:
    """The FMI functions the standard's header declares for export (``FMIx_Export``)."""
    header = (RUNTIME_DIR / "include" / f"fmi{version}Functions.h").read_text()
    return set(re.findall(rf"FMI{version}_Export\s+fmi{version}\w+TYPE\s+(fmi{version}\w+)\s*;",
                          header))


@pytest.fixture(scope="module")
def cross_fmus(tmp_path_factory):
    """The toy model's FMI 2.0 and 3.0 FMUs with every platform's binary."""
    folder = tmp_path_factory.mktemp("cross")
    return {version: build_fmu(make_toy_spec(), folder, fmi_version=version, cross=True)
            for version in (2, 3)}


def binaries(path: Path) -> dict[str, bytes]:
    """``{platform folder: library bytes}`` of an FMU."""
    with zipfile.ZipFile(path) as archive:
        return {name.split("/")[1]: archive.read(name) for name in archive.namelist()
                if name.startswith("binaries/") and not name.endswith("/")}


@pytest.mark.parametrize("version", (2, 3))
def test_each_platform_has_its_format_architecture_exports_and_only_the_c_runtime(cross_fmus,
                                                                                   version):
    expected = FMI2_FOLDERS if version == 2 else FMI3_TUPLES
    found = binaries(cross_fmus[version])
    assert set(found) == set(expected)
    declared = declared_functions(version)
    assert len(declared) > 40  # the header parse found the standard's function list
    for folder, (file_format, architectures) in expected.items():
        info = read_binary(found[folder])
        assert (info["format"], info["arch"]) == (file_format, architectures), folder
        assert declared <= info["exports"], (folder, declared - info["exports"])
        assert info["exports"] - declared <= LINKER_SYMBOLS, (folder, info["exports"] - declared)
        assert all(ALLOWED_IMPORTS[file_format].match(name) for name in info["imports"]), \
            (folder, info["imports"])
        assert info["imports"], folder
        if file_format == "Mach-O":
            assert info["arm64_signed"], folder  # arm64 macOS loads only signed code


@pytest.mark.parametrize("version", (2, 3))
def test_linux_binaries_need_at_most_glibc_2_17(cross_fmus, version):
    found = binaries(cross_fmus[version])
    for folder in ("linux64",) if version == 2 else ("x86_64-linux", "aarch64-linux"):
        versions = read_elf(found[folder])["versions"]
        glibc = [tuple(map(int, v.removeprefix("GLIBC_").split("."))) for v in versions
                 if v.startswith("GLIBC_")]
        assert glibc and max(glibc) <= (2, 17), (folder, sorted(versions))


@pytest.mark.parametrize("version", (2, 3))
def test_the_cross_built_fmu_runs_here_and_keeps_its_sources(cross_fmus, version):
    with zipfile.ZipFile(cross_fmus[version]) as archive:
        assert "sources/model.c" in archive.namelist()
    result = simulate_fmu(cross_fmus[version], fmi_type="CoSimulation", stop_time=0.05,
                          output_interval=0.01)
    assert len(result) >= 5


def test_a_failing_target_leaves_the_others_and_is_named_in_one_line(tmp_path, monkeypatch,
                                                                    caplog):
    bogus = BinaryPlatform("nonsense-os", None, ".so", "nonsense-unknown-os", ("None", "none"))
    monkeypatch.setattr(compile_module, "PLATFORMS", (host_platform(), bogus))
    with caplog.at_level(logging.WARNING, logger=compile_module.LOGGER.name):
        path = build_fmu(make_toy_spec(), tmp_path, fmi_version=3, cross=True)
    assert fmu_platforms(path) == ("x86_64-linux",)
    lines = [r.getMessage() for r in caplog.records if "no binary for" in r.getMessage()]
    assert len(lines) == 1 and "nonsense-os" in lines[0] and "\n" not in lines[0]


def test_without_ziglang_the_native_compiler_builds_the_host_binary(tmp_path, monkeypatch):
    monkeypatch.setattr(compile_module, "find_zig", lambda: None)
    path = build_fmu(make_toy_spec(), tmp_path, fmi_version=2, cross=True)
    assert fmu_platforms(path) == ("linux64",)
    assert read_binary(binaries(path)["linux64"])["arch"] == {"x86_64"}


def test_the_host_only_build_also_targets_glibc_2_17(tmp_path):
    path = build_fmu(make_toy_spec(), tmp_path, fmi_version=2)
    assert fmu_platforms(path) == ("linux64",)
    versions = read_elf(binaries(path)["linux64"])["versions"]
    assert max(tuple(map(int, v.removeprefix("GLIBC_").split("."))) for v in versions
               if v.startswith("GLIBC_")) <= (2, 17)
