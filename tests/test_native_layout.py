"""The native models' C files as docs/architecture.md (The C half) lays them out: each in one
of the folders of ``NATIVE_FOLDERS`` under cosim/fmu/native/, named without the ``ato_`` prefix
(which marks what the build writes), each name used once (the FMU's ``sources/`` is flat); the
builder finds every file a ``NativeSpec`` names and names the one it cannot find."""

from __future__ import annotations

import pytest

from cosim.build import native as native_build
from cosim.build.native import NATIVE, NATIVE_DIR, NATIVE_FOLDERS, native_file, native_sources


def test_every_file_is_in_a_role_folder_under_one_name_without_the_generated_prefix():
    files = sorted(p for p in NATIVE_DIR.rglob("*") if p.is_file())
    assert files
    assert {p.relative_to(NATIVE_DIR).parts[0] for p in files} == set(NATIVE_FOLDERS)
    assert all(len(p.relative_to(NATIVE_DIR).parts) == 2 for p in files)
    names = [p.name for p in files]
    assert len(names) == len(set(names))
    assert [n for n in names if n.startswith("ato_")] == []


@pytest.mark.parametrize("identifier", sorted(NATIVE))
def test_every_file_a_spec_names_is_found_in_its_folder(identifier):
    spec = NATIVE[identifier]
    for name in (spec.source, *spec.helpers, *spec.shared):
        assert native_file(name).is_file()
        assert native_file(name).name == name
    assert all(p.is_file() for p in native_sources(identifier, 3))


def test_a_missing_file_is_named():
    with pytest.raises(FileNotFoundError, match=r"'no_such_law\.c' not found in .*controllers"):
        native_file("no_such_law.c")


def test_a_name_in_two_folders_is_refused(tmp_path, monkeypatch):
    for folder in ("numerics", "controllers"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "linalg.c").write_text("int x;\n")
    monkeypatch.setattr(native_build, "NATIVE_DIR", tmp_path)
    with pytest.raises(ValueError, match=r"linalg\.c: in .*controllers and .*numerics"):
        native_file("linalg.c")


def test_a_file_outside_the_folders_is_refused(tmp_path, monkeypatch):
    (tmp_path / "runtime").mkdir()
    (tmp_path / "stray.c").write_text("int x;\n")
    monkeypatch.setattr(native_build, "NATIVE_DIR", tmp_path)
    with pytest.raises(ValueError, match=r"stray\.c: a native C file belongs directly in one"):
        native_file("runtime.c")
