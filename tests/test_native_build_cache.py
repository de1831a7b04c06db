"""The native builder is a function of its sources: the GUID is derived from them, and the
compiled binaries come from the build cache when the same sources were compiled before
(cosim/build/native.py, ``_compile_cached``)."""

from __future__ import annotations

import re
import shutil
import zipfile
from pathlib import Path

import pytest

from cosim.build import native as native_build

IDENT = "StopPid"  # the smallest native model: its compile is the cheapest


@pytest.fixture
def counted_compiles(monkeypatch, tmp_path):
    """A private build cache, and the list of compile batches run (their output names)."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    monkeypatch.setenv("ATO_COSIM_CACHE", str(tmp_path / "cache"))
    calls: list[list[str]] = []
    real = native_build._compile_side_by_side

    def counting(jobs):
        calls.append([job[2].name for job in jobs])
        real(jobs)

    monkeypatch.setattr(native_build, "_compile_side_by_side", counting)
    return calls


def _members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as z:
        return {name: z.read(name) for name in z.namelist()}


def _guid(members: dict[str, bytes]) -> str:
    return re.search(r'(?:guid|instantiationToken)="([^"]+)"',
                     members["modelDescription.xml"].decode()).group(1)


def test_a_rebuild_of_the_same_sources_compiles_nothing_and_gives_the_same_fmu(
        counted_compiles, tmp_path):
    first = _members(native_build.build_native(IDENT, dest=tmp_path / "a", windows=False))
    assert counted_compiles == [[f"{IDENT}.so"]]
    second = _members(native_build.build_native(IDENT, dest=tmp_path / "b", windows=False))
    assert counted_compiles == [[f"{IDENT}.so"]]  # the binary came from the cache
    assert second == first  # every file, binaries included, byte for byte
    guid = _guid(first)
    assert re.fullmatch(r"\{[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}\}",
                        guid)
    assert f'"{guid}"'.encode() in first[f"sources/{IDENT}_decl.h"]
    assert native_build.GUID_PLACEHOLDER.encode() not in b"".join(first.values())


def test_the_fmi3_build_is_cached_and_keeps_the_fmi2_guid(counted_compiles, tmp_path):
    paths = native_build.build_natives(IDENT, (2, 3), dest=tmp_path / "a", windows=False)
    assert len(counted_compiles) == 2
    again = native_build.build_natives(IDENT, (2, 3), dest=tmp_path / "b", windows=False)
    assert len(counted_compiles) == 2
    for old, new in zip(paths, again):
        assert _members(old) == _members(new)
    assert _guid(_members(paths[0])) == _guid(_members(paths[1]))


def test_a_changed_source_gives_a_new_guid_and_a_new_compile(counted_compiles, tmp_path,
                                                             monkeypatch):
    before = _members(native_build.build_native(IDENT, dest=tmp_path / "a", windows=False))
    native = tmp_path / "native"
    shutil.copytree(native_build.NATIVE_DIR, native)
    law = native / native_build.native_file(native_build.NATIVE[IDENT].source).relative_to(
        native_build.NATIVE_DIR)
    law.write_text(law.read_text() + "\n/* one more line */\n")
    monkeypatch.setattr(native_build, "NATIVE_DIR", native)
    after = _members(native_build.build_native(IDENT, dest=tmp_path / "b", windows=False))
    assert len(counted_compiles) == 2
    assert _guid(after) != _guid(before)


def test_with_the_cache_off_every_build_compiles(counted_compiles, tmp_path, monkeypatch):
    monkeypatch.setenv("ATO_COSIM_CACHE", "off")
    for folder in ("a", "b"):
        native_build.build_native(IDENT, dest=tmp_path / folder, windows=False)
    assert len(counted_compiles) == 2


def test_a_cache_that_cannot_be_written_still_builds(counted_compiles, tmp_path, monkeypatch):
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv("ATO_COSIM_CACHE", str(blocker))
    path = native_build.build_native(IDENT, dest=tmp_path / "a", windows=False)
    assert f"binaries/linux64/{IDENT}.so" in _members(path)
    assert len(counted_compiles) == 1
