"""Opening FMU files: the checks before a run, one extraction per file, the unit class of
each FMI version."""

from __future__ import annotations

import atexit
import shutil
import zipfile
from pathlib import Path
from typing import Any

from cosim.build.python import FMU_DIR
from cosim.run.archive import ArchiveLimits, ArchiveRefused, extract, inspect
from cosim.run.master.fmi2 import Fmi2Unit
from cosim.run.master.fmi3 import Fmi3Unit, read_model_description
from cosim.run.master.scheduled import Fmi3ScheduledUnit
from cosim.run.master.unit import Unit
from cosim.run.scenario import Scenario, ScenarioError

# One extraction per FMU file (and version) per process: pythonfmu caches the FMU's Python
# module by name, so later instances keep using the first extraction; it stays until exit.
_EXTRACTED: dict[tuple[str, float], str] = {}


def extract_once(path: Path) -> str:
    """The folder the FMU file ``path`` is extracted into, once per process, within the
    limits of :meth:`ArchiveLimits.from_environment` (a failed extraction leaves no folder);
    :class:`ScenarioError` naming the file when the archive breaks one."""
    key = (str(path.resolve()), path.stat().st_mtime)
    if key not in _EXTRACTED:
        try:
            _EXTRACTED[key] = extract(path, ArchiveLimits.from_environment())
        except (ArchiveRefused, ValueError) as err:
            raise ScenarioError(f"{path}: {err}") from None
    return _EXTRACTED[key]


@atexit.register
def _remove_extractions() -> None:
    for d in _EXTRACTED.values():
        shutil.rmtree(d, ignore_errors=True)


def unit_class(md: Any) -> type[Unit]:
    """The unit class of the FMI version ``md`` declares."""
    if str(md.fmiVersion).startswith("3"):
        if md.coSimulation is None:
            return Fmi3ScheduledUnit
        return Fmi3Unit
    return Fmi2Unit


def own_python_build(path: Path, folder: str | Path) -> bool:
    """Whether the FMU file ``path`` (extracted into ``folder``) is one of this package's
    Python builds: a file of the package's FMU folder (:data:`cosim.build.python.FMU_DIR`) whose
    binary is pythonfmu's (``resources/slavemodule.txt``), i.e. code of this package."""
    return (Path(path).resolve().is_relative_to(FMU_DIR.resolve())
            and (Path(folder) / "resources" / "slavemodule.txt").is_file())


def warm_up(path: Path) -> None:
    """Extract ``path`` (once per process) and, for one of this package's Python builds
    (:func:`own_python_build`), instantiate it once, so its bundled modules are imported (and
    shared by processes forked afterwards). Any other FMU (native or third-party) is only
    extracted: its code runs in the workers alone, where a crash or hang ends one child and
    not the run (:mod:`cosim.run.isolation`). Failures are left to the runs."""
    try:
        folder = extract_once(path)  # within the limits, before the XML is parsed
        if not own_python_build(path, folder):
            return
        md = read_model_description(folder)
        unit = unit_class(md)("warm-up", path, folder, md)
        unit.instantiate()
        unit.free()
    except Exception:  # noqa: BLE001 - the run of a point reports what is wrong
        pass


def binary_dirs(md: Any) -> tuple[str, list[str]]:
    """(this platform's binaries folder, every folder that would do) for ``md``'s version:
    FMI 2 ``linux64`` (FMI 2.0.4 sec. 2.4), FMI 3 ``x86_64-linux`` (FMI 3.0 sec. 2.5.1.4.1)."""
    from fmpy import platform, platform_tuple

    return (platform_tuple, [platform_tuple]) if str(md.fmiVersion).startswith("3") \
        else (platform, [platform])


def archive_names(where: str, path: Path) -> set[str]:
    """The entry names of the FMU file ``path``, its zip directory checked against
    :meth:`ArchiveLimits.from_environment` before anything is decompressed; otherwise a
    :class:`ScenarioError` starting with ``where``."""
    try:
        return {entry.filename for entry in inspect(path, ArchiveLimits.from_environment())}
    except (zipfile.BadZipFile, OSError) as err:
        raise ScenarioError(f"{where}: not an FMU (not a readable zip archive: {err})") from None
    except (ArchiveRefused, ValueError) as err:
        raise ScenarioError(f"{where}: refused before extraction: {err}") from None


def read_fmu(sc: Scenario, instance: str, path: Path) -> Any:
    """The modelDescription of the FMU of ``instance`` (:func:`open_fmu`)."""
    return open_fmu(sc, instance, path)[0]


def open_fmu(sc: Scenario, instance: str, path: Path) -> tuple[Any, str]:
    """The modelDescription of the FMU of ``instance`` and the folder it is extracted into
    (:func:`extract_once`), after checking the file is an FMU with a co-simulation (or FMI 3
    Scheduled Execution) binary for this platform: otherwise a :class:`ScenarioError` naming
    the scenario file, the instance and the path (instead of BadZipFile / KeyError later).
    The XML is read from that folder, so the description and the binary a run loads are of
    one version of a file rebuilt meanwhile."""
    where = f"{sc.path}: [fmus.{instance}] fmu = {str(path)!r}"
    names = archive_names(where, path)
    if "modelDescription.xml" not in names:
        raise ScenarioError(f"{where}: not an FMU (no modelDescription.xml in the archive)")
    unzipdir = extract_once(path)  # within the limits, before the XML is parsed
    try:
        md = read_model_description(unzipdir)
    except Exception as err:  # noqa: BLE001 - fmpy raises many kinds on a bad XML
        raise ScenarioError(f"{where}: modelDescription.xml is not valid: {err}") from None
    version = str(md.fmiVersion)
    scheduled = getattr(md, "scheduledExecution", None)
    if md.coSimulation is None and not (scheduled and version.startswith("3")):
        raise ScenarioError(f"{where}: not a co-simulation FMU ("
                            f"{'model exchange' if md.modelExchange else 'no interface'} "
                            "only; the master runs co-simulation and Scheduled Execution FMUs)")
    if not (version.startswith("2") or version.startswith("3")):
        raise ScenarioError(f"{where}: FMI {version}: the master runs FMI 2.0 and 3.0 FMUs")
    ident = (md.coSimulation or scheduled).modelIdentifier
    ext = {"linux": ".so", "darwin": ".dylib", "win": ".dll"}
    from fmpy import platform

    suffix = next(v for k, v in ext.items() if platform.startswith(k))
    folder, _ = binary_dirs(md)
    if f"binaries/{folder}/{ident}{suffix}" not in names:
        found = sorted({n.split("/")[1] for n in names
                        if n.startswith("binaries/") and n.count("/") >= 2 and n.split("/")[1]})
        if folder in found:  # the platform's folder, without the library the XML names
            held = sorted(n.removeprefix(f"binaries/{folder}/") for n in names
                          if n.startswith(f"binaries/{folder}/") and n.endswith(suffix))
            raise ScenarioError(f"{where}: binaries/{folder}/ has no {ident}{suffix}, the "
                                f"library of modelIdentifier {ident!r} in modelDescription.xml "
                                f"(it holds {', '.join(held) or f'no {suffix} file'})")
        raise ScenarioError(f"{where}: no binary for this platform ({folder}; the FMU has "
                            f"{', '.join(found) or 'no binaries'}): FMI {version} looks for "
                            f"binaries/{folder}/{ident}{suffix}")
    return md, unzipdir
