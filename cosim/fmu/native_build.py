"""Native C FMUs (FMI 2.0 and FMI 3.0): the C twin of a core behind one of our C fronts, no
Python needed.

A native model (``cosim/fmu/native/<model>.c``) is a backend with FMI 2-shaped functions
(``cosim/fmu/front/ato_backend.h``: it defines ``ato_backend_get()``). The same model file is
linked statically with either front, with nothing else in between:

* FMI 2.0: ``cosim/fmu/front/fmi2_front.c``; ``binaries/linux64/<id>.so`` and
  ``binaries/win64/<id>.dll``; built to ``fmus/native/<id>.fmu``;
* FMI 3.0: ``cosim/fmu/front/fmi3_front.c`` (the front of our FMI 3 builds of the Python FMUs,
  there over a backend that loads an FMI 2 binary); ``binaries/x86_64-linux/<id>.so`` and
  ``binaries/x86_64-windows/<id>.dll``; built to ``fmus/native/fmi3/<id>.fmu``.

A native FMU has the same variables as its Python FMU: the FMI 2 modelDescription.xml is the
Python wrapper's own (``CoreSlave.to_xml``: value references, units, ranges, starts,
structure), the FMI 3 one is derived from it by :func:`cosim.fmu.fmi3.model_description`
(as for the Python FMUs' FMI 3 builds), and the C header ``<id>_decl.h`` (value references,
starts, ranges as ``ato_var`` rows, the event-time output) is written from the same
declarations at build time, so nothing is declared twice. Route data are exported from the
bundled route files (parsed by :mod:`plants.route`) to ``resources/routes/<name>.grade``.

Every FMU holds ``sources/`` (the model's C file, the front, the generated header, the FMI
headers and ``buildDescription.xml`` in the FMI 3.0 format that FMI 2.0.4 adopts) so any tool
can compile it. The Linux binary needs gcc; the Windows one is built when the mingw-w64 cross
compiler ``x86_64-w64-mingw32-gcc`` is installed.

Compiled with ``-std=c99 -ffp-contract=off`` (no fused multiply-add, no fast math), so the C
model performs the core's IEEE operations in the core's order.
"""

from __future__ import annotations

import importlib
import math
import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, indent, tostring

from cosim.fmu.build import FMU_DIR, catalog

HERE = Path(__file__).resolve().parent
NATIVE_DIR = HERE / "native"
FRONT_DIR = HERE / "front"
NATIVE_FMU_DIR = FMU_DIR / "native"
# the flags that decide the floating-point results, also written into buildDescription.xml
FP_FLAGS = ["-std=c99", "-ffp-contract=off", "-fno-fast-math"]
CC_FLAGS = [*FP_FLAGS, "-O2", "-Wall", "-Wextra"]
LINUX_CC = "gcc"
WINDOWS_CC = "x86_64-w64-mingw32-gcc"
FMI_VERSIONS = (2, 3)
EVENT_TIME_OUTPUT = "next_event_time"  # the controllers' announced next event (slave.py)
FMI2_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")


@dataclass(frozen=True)
class Front:
    """The C front of one FMI version: its source (in cosim/fmu/front/), the FMI headers it
    and the backend interface need (from fmpy's c-code/), and its binaries folders."""

    fmi_version: int
    source: str
    headers: tuple[str, ...]
    linux: str    # binaries/<linux>/<id>.so
    windows: str  # binaries/<windows>/<id>.dll


FRONTS: dict[int, Front] = {
    2: Front(2, "fmi2_front.c", FMI2_HEADERS, "linux64", "win64"),
    # ato_backend.h declares the backend with the FMI 2 function types: FMI 2 headers too
    3: Front(3, "fmi3_front.c", FMI2_HEADERS + FMI3_HEADERS, "x86_64-linux", "x86_64-windows"),
}


def native_path(identifier: str, fmi_version: int = 2, dest: Path = NATIVE_FMU_DIR) -> Path:
    """Where the native FMI ``fmi_version`` build of ``identifier`` goes under ``dest``:
    ``dest/<id>.fmu`` (FMI 2.0) or ``dest/fmi3/<id>.fmu`` (FMI 3.0), as ``fmus/`` and
    ``fmus/fmi3/`` for the Python FMUs."""
    if fmi_version not in FRONTS:
        raise ValueError(f"fmi_version {fmi_version!r}: expected one of {sorted(FRONTS)}")
    return (dest if fmi_version == 2 else dest / "fmi3") / f"{identifier}.fmu"


@dataclass(frozen=True)
class NativeSpec:
    """A native model: the C file of its backend (in cosim/fmu/native/)."""

    identifier: str
    source: str

    @property
    def path(self) -> Path:
        """The FMI 2.0 build."""
        return native_path(self.identifier, 2)

    @property
    def path_fmi3(self) -> Path:
        """The FMI 3.0 build."""
        return native_path(self.identifier, 3)

    def path_for(self, fmi_version: int) -> Path:
        """The build of FMI version ``fmi_version`` (2 or 3)."""
        return native_path(self.identifier, fmi_version)


NATIVE: dict[str, NativeSpec] = {
    "BrakeDelayTrain": NativeSpec("BrakeDelayTrain", "brake_delay.c"),
}


class CompilerMissing(RuntimeError):
    """The C compiler a native build needs is not installed."""


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_double(value: float) -> str:
    """A double literal that reads back to the same float (hex, exact)."""
    if math.isinf(value):
        return "INFINITY" if value > 0 else "-INFINITY"
    return float(value).hex()


def decl_header(identifier: str, variables, guid: str) -> str:
    """``<id>_decl.h``: model identifier, GUID, one ``ATO_VR_<name>`` per variable, the
    ``ATO_VARS`` table (causality, type, start, range) in value-reference order and
    ``ATO_EVENT_TIME_VR``, the value reference of the ``next_event_time`` output or -1 (a
    model without events): the backend's ``event_time_vr``, so the FMI 3 front's Event Mode
    follows the same declaration as the modelDescription's ``hasEventMode``."""
    types = {float: "ATO_REAL", int: "ATO_INTEGER", bool: "ATO_BOOLEAN", str: "ATO_STRING"}
    causality = {"parameter": "ATO_PARAMETER", "input": "ATO_INPUT", "output": "ATO_OUTPUT"}
    lines = [f"/* generated by cosim/fmu/native_build.py from the declarations of {identifier};"
             " do not edit */",
             "#include <math.h>", '#include "ato_vars.h"',
             f"#define ATO_MODEL_IDENTIFIER {_c_string(identifier)}",
             f"#define ATO_GUID {_c_string(guid)}",
             f"#define ATO_N_VARS {len(variables)}"]
    event_vr = next((vr for vr, v in enumerate(variables)
                     if v.name == EVENT_TIME_OUTPUT and v.causality == "output"), -1)
    lines += [f"#define ATO_EVENT_TIME_VR {event_vr}", "enum {"]
    lines += [f"    ATO_VR_{v.name} = {vr}," for vr, v in enumerate(variables)]
    lines += ["};", "static const ato_var ATO_VARS[ATO_N_VARS] = {"]
    for v in variables:
        start = 0.0 if isinstance(v.start, str) else float(v.start)
        text = _c_string(v.start) if isinstance(v.start, str) else "0"
        lines.append(
            f"    {{{_c_string(v.name)}, {causality[v.causality]}, {types[v.type]}, "
            f"{_c_double(start)}, {text}, {int(v.min is not None)}, {int(v.max is not None)}, "
            f"{_c_double(v.min if v.min is not None else 0.0)}, "
            f"{_c_double(v.max if v.max is not None else 0.0)}}},")
    lines.append("};")
    return "\n".join(lines) + "\n"


def model_description(identifier: str, slave_class, sources: list[str], guid: str) -> bytes:
    """The Python wrapper's modelDescription (FMI 2.0) with this FMU's identifier, GUID and
    sources, and ``needsExecutionTool="false"``."""
    with tempfile.TemporaryDirectory() as tmp:
        slave = slave_class(instance_name="native_build", resources=tmp)
        root: Element = slave.to_xml()
    root.set("modelName", identifier)
    root.set("guid", guid)
    root.set("generationTool", "ato-cosim native_build (C)")
    cosim = root.find("CoSimulation")
    cosim.set("modelIdentifier", identifier)
    cosim.set("needsExecutionTool", "false")  # a binary of its own, no Python (pythonfmu: true)
    files = SubElement(cosim, "SourceFiles")
    for name in sources:
        SubElement(files, "File", {"name": name})
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")


def build_description(identifier: str, sources: list[str]) -> bytes:
    """``sources/buildDescription.xml`` in the FMI 3.0 schema (``fmiVersion="3.0"``), which
    FMI 2.0.4 adopts for its sources too: the C files, the include directory and the compiler
    options that decide the floating-point results."""
    root = Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    conf = SubElement(root, "BuildConfiguration", {"modelIdentifier": identifier})
    files = SubElement(conf, "SourceFileSet", {"language": "C99",
                                                "compilerOptions": " ".join(FP_FLAGS)})
    for name in sources:
        SubElement(files, "SourceFile", {"name": name})
    SubElement(files, "IncludeDirectory", {"name": "."})
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")


def route_tables() -> dict[str, str]:
    """``<name>.grade`` text per bundled route: its grade steps ``start permille`` (%.17g via
    repr, which reads back exactly), the first start ``-inf``."""
    # by name, as the catalog imports the wrappers: cosim.fmu never imports plants statically
    route = importlib.import_module("plants.route")
    tables = {}
    for toml in sorted(route.ROUTES_DIR.glob("*.toml")):
        try:
            grade = route.load_route(toml.stem).grade
        except ValueError:  # a reference-profile TOML beside the routes, not a route
            continue
        rows = [f"{'-inf' if math.isinf(s) else repr(float(s))} {float(g)!r}"
                for s, g in zip(grade.starts.tolist(), grade.values.tolist())]
        tables[toml.stem] = f"# grade steps of route {toml.stem}: start_m permille\n" + \
            "\n".join(rows) + "\n"
    return tables


def _compiler(name: str) -> str:
    found = shutil.which(name)
    if found is None:
        raise CompilerMissing(
            f"native FMUs need the C compiler {name!r} on PATH"
            + (" (Debian: apt-get install gcc)" if name == LINUX_CC
               else " (Debian: apt-get install mingw-w64)"))
    return found


def compile_command(cc: str, src_dir: Path, out: Path, windows: bool) -> list[str]:
    """The compiler call that builds the FMU's sources in ``src_dir`` (every ``*.c``: one
    front and the model) into the shared library ``out``."""
    sources = sorted(str(p) for p in src_dir.glob("*.c"))
    cmd = [cc, "-shared", *CC_FLAGS, f"-I{src_dir}", "-o", str(out), *sources]
    if windows:
        return [*cmd, "-static-libgcc"]
    return [*cmd, "-fPIC", "-fvisibility=hidden", "-lm"]


def compile_binaries(commands: list[list[str]]) -> None:
    """Run the compiler calls side by side (one per core at most); the first failure is
    raised with the compiler's message, naming the library."""
    pending, running, failures = list(commands), [], []
    limit = max(1, os.cpu_count() or 1)
    while pending or running:
        while pending and len(running) < limit:
            cmd = pending.pop(0)
            running.append((cmd, subprocess.Popen(cmd, stdout=subprocess.PIPE,
                                                  stderr=subprocess.PIPE, text=True)))
        cmd, proc = running.pop(0)
        _, err = proc.communicate()
        if proc.returncode != 0:
            failures.append(f"{Path(cmd[0]).name} failed on {Path(cmd[cmd.index('-o') + 1]).name}"
                            f":\n{err.strip()[-3000:]}")
    if failures:
        raise RuntimeError("\n".join(failures))


def _compilers(windows: bool | None) -> tuple[str, str | None]:
    """gcc, and mingw-w64 when ``windows`` (True: required; None: when installed)."""
    gcc = _compiler(LINUX_CC)
    if windows is False:
        return gcc, None
    try:
        return gcc, _compiler(WINDOWS_CC)
    except CompilerMissing:
        if windows:
            raise
        return gcc, None


def _stage(root: Path, spec: NativeSpec, front: Front, decl: str, md2: bytes,
           routes: dict[str, str]) -> Path:
    """Lay out the FMU tree of ``spec`` behind ``front`` under ``root``; returns sources/."""
    import fmpy

    from cosim.fmu import fmi3

    headers = Path(fmpy.__file__).parent / "c-code"
    src = root / "sources"
    src.mkdir(parents=True)
    for name in (front.source, "ato_backend.h"):
        shutil.copy2(FRONT_DIR / name, src)
    for name in (spec.source, "ato_vars.h"):
        shutil.copy2(NATIVE_DIR / name, src)
    for name in front.headers:
        shutil.copy2(headers / name, src)
    (src / f"{spec.identifier}_decl.h").write_text(decl)
    (src / "buildDescription.xml").write_bytes(
        build_description(spec.identifier, [front.source, spec.source]))
    md = md2 if front.fmi_version == 2 else fmi3.model_description(md2)[0]
    (root / "modelDescription.xml").write_bytes(md)
    folder = root / "resources" / "routes"
    folder.mkdir(parents=True)
    for name, text in routes.items():
        (folder / f"{name}.grade").write_text(text)
    return src


def _zip(root: Path, final: Path) -> None:
    """Zip the tree ``root`` into ``final`` atomically (staged beside it, then renamed)."""
    final.parent.mkdir(parents=True, exist_ok=True)
    staged = final.parent / f".{final.name}.{os.getpid()}.tmp"
    with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted(p for p in root.rglob("*") if p.is_file()):
            z.write(f, f.relative_to(root).as_posix())
    os.replace(staged, final)


def build_natives(identifier: str, fmi_versions: tuple[int, ...] = FMI_VERSIONS,
                  dest: Path = NATIVE_FMU_DIR, windows: bool | None = None) -> list[Path]:
    """Build the native FMUs of ``identifier``, one per FMI version in ``fmi_versions``, to
    :func:`native_path` under ``dest``; ``windows``: also the Windows DLLs (default: when
    mingw-w64 is installed). The builds share one GUID (the FMI 3 ``instantiationToken``) and
    their compiler calls run side by side. Raises :class:`CompilerMissing` naming the
    compiler when it is absent."""
    if identifier not in NATIVE:
        raise ValueError(f"no native model of {identifier!r}; native: {sorted(NATIVE)}")
    for version in fmi_versions:
        native_path(identifier, version)  # refuses an unknown version
    spec = NATIVE[identifier]
    gcc, mingw = _compilers(windows)
    slave_class = catalog()[identifier].load()
    guid = "{" + str(uuid.uuid4()) + "}"
    decl = decl_header(identifier, slave_class.variables, guid)
    routes = route_tables()
    with tempfile.TemporaryDirectory(prefix="atocosim_native_") as tmp:
        trees, commands = [], []
        for version in fmi_versions:
            front = FRONTS[version]
            root = Path(tmp) / f"fmi{version}"
            md2 = model_description(identifier, slave_class, [front.source, spec.source], guid)
            src = _stage(root, spec, front, decl, md2, routes)
            for cc, folder, suffix in ((gcc, front.linux, ".so"), (mingw, front.windows, ".dll")):
                if cc is None:
                    continue
                (root / "binaries" / folder).mkdir(parents=True)
                commands.append(compile_command(
                    cc, src, root / "binaries" / folder / f"{identifier}{suffix}",
                    suffix == ".dll"))
            trees.append((root, native_path(identifier, version, dest)))
        compile_binaries(commands)
        for root, final in trees:
            _zip(root, final)
    return [final for _, final in trees]


def build_native(identifier: str, dest: Path = NATIVE_FMU_DIR, windows: bool | None = None,
                 fmi_version: int = 2) -> Path:
    """Build the native FMI ``fmi_version`` FMU of ``identifier`` (:func:`build_natives`)."""
    return build_natives(identifier, (fmi_version,), dest, windows)[0]
