"""An FMU archive from an untrusted source, bounded before any work: the extracted size, the
number of files and the size of modelDescription.xml are read from the zip directory and
refused over their limits (a 1 MB zip bomb expanding to 1 GiB is refused with its sizes before
a byte is written); entries with absolute, drive or parent-directory paths and symbolic links
are refused; extraction writes at most the declared sizes and removes its folder when it fails.

The defaults are far above any real FMU (ours are a few MB; the FMI Reference FMUs below one);
the environment variables of :data:`LIMIT_SETTINGS` raise them for every command that opens an
FMU (``cosim run``, ``sweep``, ``reproduce``, ``validate``), and ``cosim validate``'s options
``--max-extracted-mb / --max-files / --max-model-description-mb`` for that command.
"""

from __future__ import annotations

import os
import shutil
import stat
import tempfile
import zipfile
from dataclasses import dataclass, fields
from pathlib import Path, PurePosixPath

MB = 1 << 20

# field of ArchiveLimits -> (cosim validate's option, environment variable, unit in bytes)
LIMIT_SETTINGS = {
    "max_extracted": ("--max-extracted-mb", "COSIM_MAX_EXTRACTED_MB", MB),
    "max_files": ("--max-files", "COSIM_MAX_FILES", 1),
    "max_model_description": ("--max-model-description-mb", "COSIM_MAX_MODEL_DESCRIPTION_MB",
                              MB),
}


@dataclass(frozen=True)
class ArchiveLimits:
    """What one FMU archive may hold."""

    max_extracted: int = 512 * MB  # bytes, all files extracted
    max_files: int = 10_000  # entries
    max_model_description: int = 4 * MB  # bytes of modelDescription.xml (1e6 variables: 5.7 MB)

    @classmethod
    def from_environment(cls) -> ArchiveLimits:
        """The defaults, each replaced by its environment variable of :data:`LIMIT_SETTINGS`
        where set (MiB for sizes, a count for files); ValueError naming a variable whose value
        is not a positive number."""
        given = {}
        for limit in fields(cls):
            _, variable, unit = LIMIT_SETTINGS[limit.name]
            text = os.environ.get(variable)
            if text is None:
                continue
            try:
                value = float(text)
            except ValueError:
                value = float("nan")
            if not value > 0 or value == float("inf"):
                raise ValueError(f"environment variable {variable}={text!r}: expected a "
                                 "positive number")
            given[limit.name] = int(value * unit)
        return cls(**given)


def raise_hint(limit: str) -> str:
    """How the user raises ``limit`` (a field of :class:`ArchiveLimits`)."""
    option, variable, unit = LIMIT_SETTINGS[limit]
    example = "N" if unit == 1 else "MIB"
    return f"raise it with {variable}={example} in the environment, or cosim validate {option}"


class ArchiveRefused(Exception):
    """The archive breaks a limit or holds an unsafe entry (the message says which)."""


def _size(n: int) -> str:
    for unit, scale in (("GiB", 1 << 30), ("MiB", MB), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} bytes"


def inspect(path: str | Path, limits: ArchiveLimits = ArchiveLimits()) -> list[zipfile.ZipInfo]:
    """The archive's entries, after checking ``limits`` and the entry names on its directory
    (nothing is decompressed). Raises :class:`ArchiveRefused` or ``zipfile.BadZipFile``."""
    with zipfile.ZipFile(path) as z:
        return _checked(z, Path(path), limits)


def _checked(z: zipfile.ZipFile, path: Path, limits: ArchiveLimits) -> list[zipfile.ZipInfo]:
    """The entries of the open archive ``z`` (read from ``path``), checked as :func:`inspect`
    says."""
    entries = z.infolist()
    if len(entries) > limits.max_files:
        raise ArchiveRefused(f"{len(entries)} files in the archive, more than the limit of "
                             f"{limits.max_files} ({raise_hint('max_files')})")
    total = sum(e.file_size for e in entries)
    if total > limits.max_extracted:
        raise ArchiveRefused(f"the archive ({_size(path.stat().st_size)}) expands to "
                             f"{_size(total)}, more than the limit of "
                             f"{_size(limits.max_extracted)} ({raise_hint('max_extracted')})")
    for e in entries:
        name = e.filename
        parts = PurePosixPath(name).parts
        if "\\" in name or ":" in name or name.startswith("/") or ".." in parts:
            raise ArchiveRefused(f"unsafe path in the archive: {name!r}")
        if stat.S_ISLNK(e.external_attr >> 16):
            raise ArchiveRefused(f"symbolic link in the archive: {name!r}")
        if name == "modelDescription.xml" and e.file_size > limits.max_model_description:
            raise ArchiveRefused(f"modelDescription.xml is {_size(e.file_size)}, more than the "
                                 f"limit of {_size(limits.max_model_description)} "
                                 f"({raise_hint('max_model_description')})")
    return entries


def extract(path: str | Path, limits: ArchiveLimits = ArchiveLimits()) -> str:
    """Extract the FMU into a new temporary folder (returned) within ``limits``; on any failure
    the folder is removed and the error raised. The directory is checked and the files are read
    through one open handle, so an archive replaced at ``path`` meanwhile (a rebuild renamed
    into place) is extracted whole from the version first opened, never mixed with the other."""
    with zipfile.ZipFile(path) as z:
        entries = _checked(z, Path(path), limits)
        folder = Path(tempfile.mkdtemp(prefix="cosim-fmu-"))
        try:
            written = 0
            for e in entries:
                target = folder / e.filename
                if e.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                # zipfile reads at most file_size bytes of an entry (and checks its CRC)
                with z.open(e) as src, open(target, "wb") as dst:
                    while chunk := src.read(MB):
                        written += len(chunk)
                        if written > limits.max_extracted:
                            raise ArchiveRefused("the archive expands past the limit of "
                                                 f"{_size(limits.max_extracted)}")
                        dst.write(chunk)
            return str(folder)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
