"""``cosim validate`` bounds an untrusted FMU archive before any work: a zip bomb (1 MB
expanding to 1 GiB), too many files or a huge modelDescription.xml are refused with their
sizes and the flag that raises the limit; unsafe entries are refused; a failed extraction
leaves no folder behind. The archives are written byte by byte here."""

from __future__ import annotations

import struct
import subprocess
import sys
import tempfile
import zipfile
import zlib
from pathlib import Path

import pytest

from cosim.interop.compliance import ALL_CHECKS, ERROR, SKIPPED, Options, check_fmu
from cosim.run.archive import (
    MB,
    ArchiveLimits,
    ArchiveRefused,
    extract,
    inspect,
)

MODEL_DESCRIPTION = (b'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription '
                     b'fmiVersion="2.0" modelName="m" guid="{0}"><CoSimulation '
                     b'modelIdentifier="m"/><ModelVariables/><ModelStructure/>'
                     b'</fmiModelDescription>\n')


def raw_zip(path: Path, entries: list[tuple[str, int, int, bytes, int]]) -> Path:
    """A zip archive of ``(name, method, crc32, stored bytes, size)`` entries, written field by
    field (method 0: stored, 8: deflated)."""
    out, central = bytearray(), bytearray()
    for name, method, crc, data, size in entries:
        encoded = name.encode()
        offset = len(out)
        out += struct.pack("<IHHHHHIIIHH", 0x04034B50, 20, 0, method, 0, 0x21, crc, len(data),
                           size, len(encoded), 0) + encoded + data
        central += struct.pack("<IHHHHHHIIIHHHHHII", 0x02014B50, 20, 20, 0, method, 0, 0x21,
                               crc, len(data), size, len(encoded), 0, 0, 0, 0, 0,
                               offset) + encoded
    end = struct.pack("<IHHHHIIH", 0x06054B50, 0, 0, len(entries), len(entries), len(central),
                      len(out), 0)
    path.write_bytes(bytes(out + central + end))
    return path


def stored(name: str, data: bytes) -> tuple[str, int, int, bytes, int]:
    return name, 0, zlib.crc32(data), data, len(data)


def zeros(name: str, size: int, chunk: int = MB) -> tuple[str, int, int, bytes, int]:
    """``size`` zero bytes deflated: one flushed block per ``chunk`` repeated (a full flush
    makes each block independent of the data before it), so 1 GiB takes about 1 MB."""
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = c.compress(bytes(chunk)) + c.flush(zlib.Z_FULL_FLUSH)
    crc = 0
    for _ in range(size // chunk):
        crc = zlib.crc32(bytes(chunk), crc)
    return name, 8, crc, block * (size // chunk) + c.flush(zlib.Z_FINISH), size


@pytest.fixture
def no_leftovers(tmp_path, monkeypatch):
    """Temporary folders of this process and its workers go to a fresh folder; returns a
    function listing what is left there."""
    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.setenv("TMPDIR", str(temp))
    return lambda: sorted(p.name for p in temp.iterdir())


def refused(problems: list) -> str:
    """The refusal message; every other check is skipped."""
    errors = [p for p in problems if p.severity == ERROR]
    assert len(errors) == 1 and errors[0].check == "fmpy-validation", problems
    assert {p.check for p in problems if p.severity == SKIPPED} == set(ALL_CHECKS) - {
        "fmpy-validation"}
    return errors[0].message


def test_zip_bomb_is_refused_with_its_sizes(tmp_path, no_leftovers):
    bomb = raw_zip(tmp_path / "bomb.fmu", [stored("modelDescription.xml", MODEL_DESCRIPTION),
                                           zeros("resources/zeros.bin", 1 << 30)])
    assert bomb.stat().st_size < 2 * MB
    with zipfile.ZipFile(bomb) as z:  # a well-formed archive: zipfile reads its directory
        assert sum(e.file_size for e in z.infolist()) > 1 << 30
    message = refused(check_fmu(bomb))
    assert message == (f"archive refused before extraction: the archive "
                       f"({bomb.stat().st_size / MB:.3g} MiB) expands to 1 GiB, more than the "
                       "limit of 512 MiB (raise it with COSIM_MAX_EXTRACTED_MB=MIB in the "
                       "environment, or cosim validate --max-extracted-mb)")
    assert no_leftovers() == []


def test_too_many_files_are_refused(tmp_path):
    path = raw_zip(tmp_path / "many.fmu", [stored("modelDescription.xml", MODEL_DESCRIPTION)]
                   + [stored(f"resources/{i}.txt", b"x") for i in range(10)])
    message = refused(check_fmu(path, Options(limits=ArchiveLimits(max_files=10))))
    assert message.endswith("11 files in the archive, more than the limit of 10 (raise it "
                            "with COSIM_MAX_FILES=N in the environment, or cosim validate "
                            "--max-files)")


def test_huge_model_description_is_refused_unless_the_limit_is_raised(tmp_path):
    padding = b"<!--" + b" " * (5 * MB) + b"-->"
    text = MODEL_DESCRIPTION.replace(b"<fmiModelDescription", padding + b"<fmiModelDescription")
    path = raw_zip(tmp_path / "huge.fmu", [stored("modelDescription.xml", text)])
    assert refused(check_fmu(path)).endswith("modelDescription.xml is 5 MiB, more than the "
                                             "limit of 4 MiB (raise it with "
                                             "COSIM_MAX_MODEL_DESCRIPTION_MB=MIB in the "
                                             "environment, or cosim validate "
                                             "--max-model-description-mb)")
    raised = check_fmu(path, Options(limits=ArchiveLimits(max_model_description=8 * MB)))
    assert not any("archive refused" in p.message for p in raised), raised


@pytest.mark.parametrize("name, says", [
    ("../outside.txt", "unsafe path in the archive: '../outside.txt'"),
    ("/etc/outside.txt", "unsafe path in the archive: '/etc/outside.txt'"),
    ("binaries\\win64\\m.dll", "unsafe path in the archive"),
])
def test_unsafe_entries_are_refused(tmp_path, name, says):
    path = raw_zip(tmp_path / "unsafe.fmu", [stored("modelDescription.xml", MODEL_DESCRIPTION),
                                             stored(name, b"x")])
    with pytest.raises(ArchiveRefused, match=says.replace("\\", "\\\\").replace(".", r"\.")):
        inspect(path)


def test_symbolic_links_are_refused(tmp_path):
    path = tmp_path / "link.fmu"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", MODEL_DESCRIPTION)
        link = zipfile.ZipInfo("resources/passwd")
        link.external_attr = (0o120777 << 16)  # S_IFLNK
        z.writestr(link, "/etc/passwd")
    with pytest.raises(ArchiveRefused, match="symbolic link in the archive: 'resources/passwd'"):
        inspect(path)


def test_failed_extraction_removes_its_folder(tmp_path, no_leftovers):
    """The second entry's checksum is wrong: zipfile raises after the first was written."""
    good = stored("modelDescription.xml", MODEL_DESCRIPTION)
    name, method, crc, data, size = stored("resources/data.bin", b"payload" * 1000)
    path = raw_zip(tmp_path / "torn.fmu", [good, (name, method, crc ^ 1, data, size)])
    with pytest.raises(zipfile.BadZipFile):
        extract(path)
    assert no_leftovers() == []


def test_cli_names_the_flag_that_raises_a_limit(tmp_path):
    path = raw_zip(tmp_path / "many.fmu", [stored("modelDescription.xml", MODEL_DESCRIPTION),
                                           stored("resources/a.txt", b"x")])
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "validate", str(path),
                           "--max-files", "1"], capture_output=True, text=True)
    assert done.returncode == 1
    assert ("archive refused before extraction: 2 files in the archive, more than the limit of "
            "1 (raise it with COSIM_MAX_FILES=N") in " ".join(done.stdout.split())


def test_an_archive_replaced_during_extraction_comes_out_whole_from_one_version(
        tmp_path, monkeypatch):
    """A rebuild renamed into place while a host extracts the FMU (as ``cosim build`` does
    while another process loads it): the files come from the archive first opened, all of
    them, not the directory of one version read against the data of the other (which zipfile
    refuses with 'Bad CRC-32'). The replacement has the same names and sizes, other bytes."""
    import os

    from cosim.run import archive

    def fmu(path: Path, guid: str) -> Path:
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("modelDescription.xml", MODEL_DESCRIPTION.replace(b"{0}", guid.encode()))
            z.writestr("resources/data.txt", guid * 100)
        return path

    path = fmu(tmp_path / "m.fmu", "A" * 36)
    rebuilt = fmu(tmp_path / ".m.fmu.tmp", "B" * 36)
    assert rebuilt.stat().st_size == path.stat().st_size
    mkdtemp = tempfile.mkdtemp

    def replaced_first(*args, **kwargs):  # the rename lands between two steps of extract
        if rebuilt.exists():
            os.replace(rebuilt, path)
        return mkdtemp(*args, **kwargs)

    monkeypatch.setattr(archive.tempfile, "mkdtemp", replaced_first)
    folder = Path(extract(path))
    assert not rebuilt.exists()  # the replacement did happen during the extraction
    assert b"A" * 36 in (folder / "modelDescription.xml").read_bytes()
    assert (folder / "resources" / "data.txt").read_text() == "A" * 3600
    assert zipfile.ZipFile(path).read("resources/data.txt") == b"B" * 3600


def test_a_run_reads_the_description_of_the_version_it_extracted(tmp_path, monkeypatch):
    """A rebuild renamed into place right after the master extracted the FMU: the
    modelDescription the run checks its scenario against is the extracted version's (the one
    whose binary it loads), not the new file's."""
    import os
    from types import SimpleNamespace

    from cosim.run.master import loading

    xml = MODEL_DESCRIPTION.replace(  # one output: a description fmpy's schema accepts
        b"<ModelVariables/><ModelStructure/>",
        b'<ModelVariables><ScalarVariable name="y" valueReference="0" causality="output" '
        b'variability="discrete"><Real/></ScalarVariable></ModelVariables><ModelStructure>'
        b'<Outputs><Unknown index="1"/></Outputs></ModelStructure>')

    def fmu(path: Path, guid: str) -> Path:
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("modelDescription.xml", xml.replace(b"{0}", guid.encode()))
            z.writestr("binaries/linux64/m.so", guid)
            z.writestr("binaries/win64/m.dll", guid)
            z.writestr("binaries/darwin64/m.dylib", guid)
        return path

    path = fmu(tmp_path / "m.fmu", "A" * 36)
    rebuilt = fmu(tmp_path / ".m.fmu.tmp", "B" * 36)
    extract_once = loading.extract_once

    def replaced_after(p):  # the rename lands once the master has extracted the file
        folder = extract_once(p)
        os.replace(rebuilt, path)
        return folder

    monkeypatch.setattr(loading, "extract_once", replaced_after)
    md, folder = loading.open_fmu(SimpleNamespace(path="s.toml"), "m", path)
    assert not rebuilt.exists()  # the replacement did happen before the XML was read
    assert md.guid == "A" * 36
    assert b"A" * 36 in (Path(folder) / "modelDescription.xml").read_bytes()
