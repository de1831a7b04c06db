"""Native C FMUs (FMI 2.0): the C twin of a core behind the FMI 2 front, no Python needed.

A native FMU has the same variables as its Python FMU: its modelDescription.xml is the Python
wrapper's own (``CoreSlave.to_xml``: value references, units, ranges, starts, structure), and
the C header ``<id>_decl.h`` (value references, starts, ranges as ``ato_var`` rows) is written
from the same declarations at build time, so nothing is declared twice. Route data are exported
from the bundled route files (parsed by :mod:`plants.route`) to ``resources/routes/<name>.grade``
and, for the models that read them, ``<name>.<profile>`` (:data:`ROUTE_PROFILES`); the
bundled reference profiles and EMPC region tables (:data:`DATA`) to ``resources/references``
and ``resources/regions``. A controller is its law's C file linked with ``ato_controller.c``,
the C twin of the sampled-controller timing of :mod:`cosim.fmu.slave`.

The FMU holds ``binaries/linux64/<id>.so`` (gcc), ``binaries/win64/<id>.dll`` when the
mingw-w64 cross compiler ``x86_64-w64-mingw32-gcc`` is installed, and ``sources/`` (the C
files, the generated header, the FMI 2 headers and ``buildDescription.xml``) so any tool can
compile it. Native FMUs are built to ``fmus/native/<id>.fmu`` (``cosim build --native``).

Compiled with ``-std=c99 -ffp-contract=off`` (no fused multiply-add, no fast math), so the C
model performs the core's IEEE operations in the core's order (libm calls: ``exp``, and
``pow`` in the freight brake cylinders; ``sqrt``, correctly rounded, in the controllers).
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
from dataclasses import dataclass, replace
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, indent, tostring

import numpy as np

from cosim.fmu.build import FMU_DIR, bundled_files, catalog

HERE = Path(__file__).resolve().parent
NATIVE_DIR = HERE / "native"
FRONT_DIR = HERE / "front"
NATIVE_FMU_DIR = FMU_DIR / "native"
CC_FLAGS = ["-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math", "-Wall", "-Wextra"]
LINUX_CC = "gcc"
WINDOWS_CC = "x86_64-w64-mingw32-gcc"


@dataclass(frozen=True)
class NativeSpec:
    """A native model: the C file of its backend (in cosim/fmu/native/), further C files it
    links and headers it includes (``helpers``, same folder; a controller's law links with
    ``ato_controller.c``), the route profiles it reads besides the grade steps
    (``route_profiles``, keys of :data:`ROUTE_PROFILES`) and the other generated resources it
    reads (``data``, keys of :data:`DATA`: reference profiles, region tables)."""

    identifier: str
    source: str
    helpers: tuple[str, ...] = ()
    route_profiles: tuple[str, ...] = ()
    data: tuple[str, ...] = ()

    @property
    def path(self) -> Path:
        return NATIVE_FMU_DIR / f"{self.identifier}.fmu"


CONTROLLER = ("ato_controller.c", "ato_law.h")  # the sampled-controller backend of a law
PROFILE = ("ato_profile.c", "ato_profile.h")  # reference profiles (resources/references)

NATIVE: dict[str, NativeSpec] = {
    "BrakeDelayTrain": NativeSpec("BrakeDelayTrain", "brake_delay.c"),
    "StopPid": NativeSpec("StopPid", "stop_pid.c", CONTROLLER),
    "EmuSpeedPid3": NativeSpec("EmuSpeedPid3", "speed_pid.c", (*CONTROLLER, *PROFILE),
                               data=("references",)),
    "EmuSpeedPid8": NativeSpec("EmuSpeedPid8", "speed_pid.c", (*CONTROLLER, *PROFILE),
                               data=("references",)),
    "Empc3": NativeSpec("Empc3", "explicit_mpc.c", (*CONTROLLER, *PROFILE),
                        data=("references", "empc_regions")),
    "FreightTrain": NativeSpec("FreightTrain", "freight.c", ("freight_kernel.c",),
                               ("speed_limit", "additional")),
}


class CompilerMissing(RuntimeError):
    """The C compiler a native build needs is not installed."""


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def c_identifier(name: str) -> str:
    """A variable name as a C identifier: ``v[12]`` -> ``v_12`` (``[`` -> ``_``, ``]`` dropped)."""
    return name.replace("[", "_").replace("]", "")


def _c_double(value: float) -> str:
    """A double literal that reads back to the same float (hex, exact)."""
    if math.isinf(value):
        return "INFINITY" if value > 0 else "-INFINITY"
    return float(value).hex()


def decl_header(identifier: str, variables, guid: str, options: dict | None = None) -> str:
    """``<id>_decl.h``: model identifier, GUID, one ``ATO_VR_<name>`` per variable (name as
    :func:`c_identifier`), the ``ATO_VARS`` table (causality, type, start, range) in
    value-reference order, and ``ATO_OPTION_<key>`` per integer core option (e.g. ``units``)."""
    types = {float: "ATO_REAL", int: "ATO_INTEGER", bool: "ATO_BOOLEAN", str: "ATO_STRING"}
    causality = {"parameter": "ATO_PARAMETER", "input": "ATO_INPUT", "output": "ATO_OUTPUT"}
    lines = [f"/* generated by cosim/fmu/native_build.py from the declarations of {identifier};"
             " do not edit */",
             "#include <math.h>", '#include "ato_vars.h"',
             f"#define ATO_MODEL_IDENTIFIER {_c_string(identifier)}",
             f"#define ATO_GUID {_c_string(guid)}",
             f"#define ATO_N_VARS {len(variables)}", "enum {"]
    lines += [f"    ATO_VR_{c_identifier(v.name)} = {vr}," for vr, v in enumerate(variables)]
    lines += ["};"]
    lines += [f"#define ATO_OPTION_{key} {int(value)}" for key, value in (options or {}).items()]
    lines += ["static const ato_var ATO_VARS[ATO_N_VARS] = {"]
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
    """The Python wrapper's modelDescription with this FMU's identifier, GUID and sources."""
    with tempfile.TemporaryDirectory() as tmp:
        slave = slave_class(instance_name="native_build", resources=tmp)
        root: Element = slave.to_xml()
    root.set("modelName", identifier)
    root.set("guid", guid)
    root.set("generationTool", "ato-cosim native_build (C)")
    cosim = root.find("CoSimulation")
    cosim.set("modelIdentifier", identifier)
    files = SubElement(cosim, "SourceFiles")
    for name in sources:
        SubElement(files, "File", {"name": name})
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")


def build_description(identifier: str, sources: list[str]) -> bytes:
    """``sources/buildDescription.xml`` (FMI 2.0.4 / 3.0 layout)."""
    root = Element("fmiBuildDescription", {"fmiVersion": "2.0"})
    conf = SubElement(root, "BuildConfiguration", {"modelIdentifier": identifier})
    files = SubElement(conf, "SourceFileSet", {"language": "C99"})
    for name in sources:
        SubElement(files, "SourceFile", {"name": name})
    SubElement(conf, "IncludeDirectory", {"name": "."})
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


def _step_rows(starts, values) -> list[str]:
    return [f"{'-inf' if math.isinf(s) and s < 0 else repr(float(s))} {float(g)!r}"
            for s, g in zip(starts.tolist(), values.tolist())]


def _speed_limit_table(route) -> tuple[str, list[str]]:
    limit = route.speed_limit
    return "speed limit steps: start_m limit_m_per_s", _step_rows(limit.starts, limit.values)


def _additional_table(route) -> tuple[str, list[str]]:
    xs, cum = route.additional._cumulative  # the knots the compiled kernels interpolate on
    return ("additional resistance (grade + curve + tunnel), cumulative over position: "
            "position_m integral_N_per_kN_m", _step_rows(xs, cum))


ROUTE_PROFILES = {"speed_limit": _speed_limit_table, "additional": _additional_table}


def route_profile_tables(kinds: tuple[str, ...]) -> dict[str, str]:
    """``<name>.<kind>`` text per bundled route and profile kind (:data:`ROUTE_PROFILES`):
    rows of two floats (repr, which reads back exactly; ``inf`` where a value is infinite)."""
    route = importlib.import_module("plants.route")
    tables = {}
    for toml in sorted(route.ROUTES_DIR.glob("*.toml")):
        try:
            loaded = route.load_route(toml.stem)
        except ValueError:  # a reference-profile TOML beside the routes, not a route
            continue
        for kind in kinds:
            title, rows = ROUTE_PROFILES[kind](loaded)
            tables[f"{toml.stem}.{kind}"] = f"# {title} of route {toml.stem}\n" + \
                "\n".join(rows) + "\n"
    return tables


def reference_tables() -> dict[str, str]:
    """``references/<name>.ref`` per bundled reference profile (:func:`plants.route.
    load_reference`): the line ``kind distance|time`` then its points ``x v`` (SI, %.17g via
    repr, which reads back exactly)."""
    route = importlib.import_module("plants.route")  # by name: layering
    tables = {}
    for path in sorted([*route.ROUTES_DIR.glob("*.csv"), *route.ROUTES_DIR.glob("*.toml")]):
        try:
            profile = route.load_reference(path.stem)
        except (ValueError, AttributeError):  # a route, not a reference profile
            continue
        rows = [f"{float(x)!r} {float(v)!r}" for x, v in zip(profile.x.tolist(),
                                                              profile.v.tolist())]
        tables[f"references/{path.stem}.ref"] = (
            f"# reference profile {path.stem}: x (m or s) v (m/s)\nkind {profile.kind}\n"
            + "\n".join(rows) + "\n")
    return tables


def _numbers(key: str, values) -> str:
    flat = [float(x) for x in np.asarray(values, dtype=float).ravel().tolist()]
    return f"{key} {len(flat)} " + " ".join(repr(x) for x in flat)


def empc_tables() -> dict[str, str]:
    """``regions/<name>.empc`` per bundled EMPC region file (controllers/hybrid/data/*.npz):
    its design settings (``meta key value``), the design constants of the online law
    (mean-speed weights ``c``, PWA ``breakpoints``, ``motored`` cars, per-mode limit ratios)
    and per mode and segment the parameter box, the regions (E, e, row offsets, first-move
    F, f, tolerance) and the bounding-box tree :class:`controllers.hybrid.explicit.BoxTree`
    built from them; one ``key count values...`` line per array (%.17g via repr: exact)."""
    explicit = importlib.import_module("controllers.hybrid.explicit")  # by name: layering
    empc = importlib.import_module("controllers.hybrid.explicit_mpc")
    hybrid = importlib.import_module("controllers.hybrid.hybrid_mpc")
    emu = importlib.import_module("plants.emu")
    tables = {}
    for path in sorted(explicit.DATA_DIR.glob("*.npz")):
        law = explicit.ExplicitLaw.load(path)
        meta = law.meta
        train = emu.emu_config(str(meta["configuration"]))
        params = replace(hybrid.HybridMpcParams(), fit_speed_max=float(meta["fit_speed_max"]),
                         sample_time=float(meta["sample_time"]),
                         configuration=str(meta["configuration"]))
        model = hybrid.chain_model(train, params)
        lines = [f"# EMPC region data {path.stem} (from {path.name}; generated)"]
        lines += [f"meta {key} {value}" for key, value in meta.items()]
        lines += [_numbers("c", model.c[:model.n]), _numbers("breakpoints",
                                                             model.res.breakpoints),
                  _numbers("motored", model.motored),
                  *(_numbers(f"ratio{m}", empc.ExplicitMpc.limit_ratio(train, m))
                    for m in explicit.MODES),
                  _numbers("keys", sorted(law.sets))]
        for (mode, seg), rs in sorted(law.sets.items()):
            p = f"m{mode}s{seg}_"
            tree = rs.tree
            lines += [_numbers(p + "box", law.boxes[mode, seg]), _numbers(p + "E", rs.E),
                      _numbers(p + "e", rs.e), _numbers(p + "rows", rs.rows),
                      _numbers(p + "na", [rs.F.shape[1]]), _numbers(p + "F", rs.F),
                      _numbers(p + "f", rs.f), _numbers(p + "tol", [rs.tol]),
                      *(_numbers(p + name, getattr(tree, name))
                        for name in ("dim", "thr", "left", "right", "start", "stop", "items"))]
        tables[f"regions/{path.stem}.empc"] = "\n".join(lines) + "\n"
    return tables


# generated resources a native model may ask for (NativeSpec.data)
DATA = {"references": reference_tables, "empc_regions": empc_tables}


def _compiler(name: str) -> str:
    found = shutil.which(name)
    if found is None:
        raise CompilerMissing(
            f"native FMUs need the C compiler {name!r} on PATH"
            + (" (Debian: apt-get install gcc)" if name == LINUX_CC
               else " (Debian: apt-get install mingw-w64)"))
    return found


def compile_binary(cc: str, src_dir: Path, out: Path, windows: bool) -> None:
    """Compile the FMU's sources in ``src_dir`` into the shared library ``out``."""
    sources = sorted(str(p) for p in src_dir.glob("*.c"))
    cmd = [cc, "-shared", *CC_FLAGS, f"-I{src_dir}", "-o", str(out), *sources]
    if windows:
        cmd += ["-static-libgcc"]
    else:
        cmd += ["-fPIC", "-fvisibility=hidden", "-lm"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{cc} failed on {out.name}:\n{done.stderr.strip()[-3000:]}")


def native_sources(identifier: str) -> list[Path]:
    """Every file the native FMU ``identifier`` is made from: its C files, the FMI 2 front,
    this builder and the Python wrapper's files (declarations, bundled data)."""
    spec = NATIVE[identifier]
    return [NATIVE_DIR / spec.source, NATIVE_DIR / "ato_vars.h",
            *(NATIVE_DIR / name for name in spec.helpers), FRONT_DIR / "fmi2_front.c",
            FRONT_DIR / "ato_backend.h", Path(__file__),
            *bundled_files(catalog()[identifier].module)]


def native_is_stale(identifier: str) -> bool:
    """True when the native FMU ``identifier`` is missing or older than a file it is made
    from (:func:`native_sources`)."""
    path = NATIVE[identifier].path
    if not path.is_file():
        return True
    built = path.stat().st_mtime
    return any(f.is_file() and f.stat().st_mtime > built for f in native_sources(identifier))


def build_native(identifier: str, dest: Path = NATIVE_FMU_DIR, windows: bool | None = None
                 ) -> Path:
    """Build the native FMU ``identifier`` into ``dest``; ``windows``: also the win64 DLL
    (default: when mingw-w64 is installed). Raises :class:`CompilerMissing` naming the
    compiler when it is absent."""
    import fmpy

    if identifier not in NATIVE:
        raise ValueError(f"no native model of {identifier!r}; native: {sorted(NATIVE)}")
    spec = NATIVE[identifier]
    gcc = _compiler(LINUX_CC)
    mingw = None
    if windows or windows is None:
        try:
            mingw = _compiler(WINDOWS_CC)
        except CompilerMissing:
            if windows:
                raise
    slave_class = catalog()[identifier].load()
    guid = "{" + str(uuid.uuid4()) + "}"
    headers = Path(fmpy.__file__).parent / "c-code"
    c_files = ["fmi2_front.c", spec.source, *(f for f in spec.helpers if f.endswith(".c"))]
    with tempfile.TemporaryDirectory(prefix="atocosim_native_") as tmp:
        root = Path(tmp) / "fmu"
        src = root / "sources"
        src.mkdir(parents=True)
        shutil.copy2(FRONT_DIR / "fmi2_front.c", src)
        shutil.copy2(FRONT_DIR / "ato_backend.h", src)
        for name in (spec.source, *spec.helpers):
            shutil.copy2(NATIVE_DIR / name, src)
        shutil.copy2(NATIVE_DIR / "ato_vars.h", src)
        for h in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"):
            shutil.copy2(headers / h, src)
        (src / f"{identifier}_decl.h").write_text(
            decl_header(identifier, slave_class.variables, guid,
                        getattr(slave_class, "core_options", None)))
        (src / "ato_model.h").write_text(  # the model's header for the shared C files
            f'/* generated by cosim/fmu/native_build.py */\n#include "{identifier}_decl.h"\n')
        (src / "buildDescription.xml").write_bytes(build_description(identifier, c_files))
        (root / "modelDescription.xml").write_bytes(
            model_description(identifier, slave_class, c_files, guid))
        routes = root / "resources" / "routes"
        routes.mkdir(parents=True)
        for name, text in route_tables().items():
            (routes / f"{name}.grade").write_text(text)
        for name, text in route_profile_tables(spec.route_profiles).items():
            (routes / name).write_text(text)
        for kind in spec.data:
            for rel, content in DATA[kind]().items():
                target = root / "resources" / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(content)
        (root / "binaries" / "linux64").mkdir(parents=True)
        compile_binary(gcc, src, root / "binaries" / "linux64" / f"{identifier}.so", False)
        if mingw:
            (root / "binaries" / "win64").mkdir(parents=True)
            compile_binary(mingw, src, root / "binaries" / "win64" / f"{identifier}.dll", True)
        dest.mkdir(parents=True, exist_ok=True)
        staged = dest / f".{identifier}.fmu.{os.getpid()}.tmp"
        with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as z:
            for f in sorted(p for p in root.rglob("*") if p.is_file()):
                z.write(f, f.relative_to(root).as_posix())
        final = dest / f"{identifier}.fmu"
        os.replace(staged, final)
    return final
