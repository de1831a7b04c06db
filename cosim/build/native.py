"""Native C FMUs (FMI 2.0, and FMI 3.0 derived from them): the C twin of a core behind our C
fronts, no Python needed.

A native FMU has the same variables as its Python FMU: its modelDescription.xml is the Python
wrapper's own (``CoreSlave.to_xml``: value references, units, ranges, starts, structure), and
the C header ``<id>_decl.h`` (value references, starts, ranges as ``ato_var`` rows) is written
from the same declarations at build time, so nothing is declared twice. Route data are exported
from the bundled route files (parsed by :mod:`plants.route`) to ``resources/routes/<name>.grade``
and, for the models that read them, ``<name>.<profile>`` (:data:`ROUTE_PROFILES`), and the
bundled reference profiles (:data:`DATA`) to ``resources/references``. What a model's core
computes for its C twin (EMPC region tables, preview gains, the seed-003 trackers' planned
target profiles, generated headers of model data) the core declares itself: its
``native_data(identifier, shipped)`` (path in the FMU -> text), which the builder asks of the
catalog's core of every model (:func:`core_data`), handing it the parameter values the project
ships for any FMU (:func:`shipped_values`). The C files are in the folders of
:data:`NATIVE_FOLDERS` under ``cosim/fmu/native/`` (``runtime``, ``numerics``, ``plants``,
``controllers``), each named once, and copied side by side into the FMU's ``sources/``
(:func:`native_file` finds one by name). Every native FMU links the runtime ``runtime.c``,
the C twin of :mod:`cosim.fmu.slave`'s CoreSlave, under a policy: a controller is its law's C
file linked with ``controller_backend.c``, the sampled controllers' event policy (the timing
of :mod:`cosim.fmu.slave`); every plant links the plants' stepping policy
``plant_backend.c``; BrakeDelayTrain, Crh3Train and the Emus read the step profiles of
:data:`STEP_PROFILES` from ``<name>.profiles``.

The FMU holds ``binaries/linux64/<id>.so`` (gcc), ``binaries/win64/<id>.dll`` when the
mingw-w64 cross compiler ``x86_64-w64-mingw32-gcc`` is installed, and ``sources/`` (the C
files, the generated header, the FMI 2 headers and ``buildDescription.xml``) so any tool can
compile it. Native FMUs are built to ``fmus/native/<id>.fmu`` (``cosim build --native``).

Builds are deterministic and cached: the GUID is derived from the FMU's sources (the same
sources give the same GUID, a changed file a new one), and the compiled binaries are kept in
the user cache (``$ATO_COSIM_CACHE`` or ``$XDG_CACHE_HOME/ato-cosim``, folder ``native``;
``ATO_COSIM_CACHE=off`` disables it) under the SHA-256 of every file of the FMU but its
binaries, the compilers' ``--version`` and the flags, so a rebuild of unchanged sources
compiles nothing.

Compiled with ``-std=c99 -ffp-contract=off`` (no fused multiply-add, no fast math), so the C
model performs the core's IEEE operations in the core's order (libm calls: ``exp``, and
``pow`` in the freight brake cylinders; ``sqrt``, correctly rounded, in the controllers;
``log1p`` in numpy's normal draws and ``log2`` in the choice of squarings of the Emu's matrix
exponential).
"""

from __future__ import annotations

import fcntl
import functools
import hashlib
import math
import os
import re
import shutil
import struct
import subprocess
import tempfile
import threading
import uuid
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement, indent, tostring

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from cosim.build import fmi3
from cosim.build.python import FMU_DIR, ROOT, bundled_files, catalog, stale_unless_known
from cosim.build.solvers import solver_files
from cosim.fmu.c_text import c_double, c_string
from cosim.fmu.disk_cache import cache_root
from plants.route import ROUTES_DIR, Route, load_reference, load_route

HERE = Path(__file__).resolve().parent
FMU_LAYER = HERE.parent / "fmu"  # cosim/fmu: the C models and fronts beside the Python slaves
NATIVE_DIR = FMU_LAYER / "native"  # runtime/, numerics/, plants/, controllers/ (NATIVE_FOLDERS)
NATIVE_FOLDERS = ("runtime", "numerics", "plants", "controllers")
FRONT_DIR = FMU_LAYER / "front"
NATIVE_FMU_DIR = FMU_DIR / "native"
CC_FLAGS = ["-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math", "-Wall", "-Wextra"]
LINUX_CC = "gcc"
WINDOWS_CC = "x86_64-w64-mingw32-gcc"


@dataclass(frozen=True)
class NativeSpec:
    """A native model: the C file of its backend, further C files it links and headers it
    includes (``helpers``; a controller's law links with ``controller_backend.c``), each named
    by its file name and found in its folder of cosim/fmu/native/ (:func:`native_file`), the
    route profiles it reads besides the grade steps (``route_profiles``, keys of
    :data:`ROUTE_PROFILES`) and the other resources the builder
    writes for it (``data``, keys of :data:`DATA`: the bundled reference profiles); files it
    shares with other plant models (``shared``, C and headers; with
    ``plant_common.c`` the route's step profiles ``<name>.profiles`` are exported), the headers
    of :data:`GENERATED` it includes (``generated``), and the numerical solvers it links
    (``solvers``, keys of :data:`cosim.build.solvers.SOLVERS`: their C sources come from
    the registry's source distribution at build time, their licence is shipped in the FMU);
    ``defines``: ``(name, value)`` macros of the model's header ``ato_model.h`` (a law file
    shared by several models, e.g. which of the seed 000 predictive controllers). What the
    model's core computes for it at build time (region tables, gains, planned profiles,
    generated headers) is not listed here: the core declares it (:func:`core_data`)."""

    identifier: str
    source: str
    helpers: tuple[str, ...] = ()
    route_profiles: tuple[str, ...] = ()
    data: tuple[str, ...] = ()
    shared: tuple[str, ...] = ()
    generated: tuple[str, ...] = ()
    solvers: tuple[str, ...] = ()
    defines: tuple[tuple[str, int], ...] = ()

    @property
    def path(self) -> Path:
        return NATIVE_FMU_DIR / f"{self.identifier}.fmu"


# the runtime under every native FMU (runtime.c, the twin of CoreSlave: variables, their
# checks, logging, FMU-state image, the FMI 2-shaped table); a backend is a policy on it
RUNTIME = ("runtime.c", "runtime.h")
# the sampled controllers' event policy over a law and what the laws share
CONTROLLER = (*RUNTIME, "controller_backend.c", "law.h", "law_common.h", "minmax.h")
BUNDLED = ("bundled.c", "bundled.h")  # bundled data files opened by name
# reference profiles (resources/references)
PROFILE = ("profile.c", "profile.h", *BUNDLED)
# the plants' stepping policy (plant_backend.c: the core stepped, its part of the FMU
# state) and the plant helpers (plant_common.c: route profiles, envelope, resistance)
PLANT_BACKEND = (*RUNTIME, "plant_backend.h", "plant_backend.c", "minmax.h")
PLANT_SHARED = (*PLANT_BACKEND, "plant_common.h", "plant_common.c", *BUNDLED)
# numpy's default_rng(seed words).standard_normal in C (seeded disturbances)
NUMPY_RANDOM = ("numpy_random.h", "numpy_random.c")
GRADE = ("grade.c", "grade.h", *BUNDLED)  # a controller's bundled route grades
# the freight controllers' shared base: observer, blending, brake-pipe model (freight_tracker.c)
FREIGHT_TRACKER = ("freight_tracker.c", "freight_tracker.h")
# the seed-001 data-driven controllers: their drive part (scaling, input box, reference,
# holding brake) and small dense linear algebra (truncated inverse, solve); the FFDL
# estimator for MFAC and ISMC
DATADRIVEN = (*CONTROLLER, *PROFILE, "datadriven.c", "datadriven.h", "linalg.c",
              "linalg.h")
FFDL = ("ffdl.c", "ffdl.h")
# the integral sliding surface and equivalent control of ISMC and ISMPC
SLIDING = (*FFDL, "sliding.c", "sliding.h")
# the seed-004 controllers' shared parameter checks and move blocks
HYBRID = ("hybrid.c", "hybrid.h")
# the GPC with RLS of controllers/common/gpc.py (seeds 001 and 003)
GPC = ("gpc.c", "gpc.h", "linalg.c", "linalg.h")

NATIVE: dict[str, NativeSpec] = {
    "BrakeDelayTrain": NativeSpec("BrakeDelayTrain", "brake_delay.c",
                                  shared=(*PLANT_SHARED, *NUMPY_RANDOM),
                                  generated=("ato_numpy_normal.h",)),
    "StopPid": NativeSpec("StopPid", "stop_pid.c", (*CONTROLLER, *GRADE)),
    "EmuSpeedPid3": NativeSpec("EmuSpeedPid3", "speed_pid.c", (*CONTROLLER, *PROFILE),
                               data=("references",)),
    "EmuSpeedPid8": NativeSpec("EmuSpeedPid8", "speed_pid.c", (*CONTROLLER, *PROFILE),
                               data=("references",)),
    "Empc3": NativeSpec("Empc3", "explicit_mpc.c", (*CONTROLLER, *PROFILE, *HYBRID),
                        data=("references",)),
    **{identifier: NativeSpec(identifier, "hybrid_mpc.c", (*CONTROLLER, *PROFILE, *HYBRID),
                              data=("references",), solvers=("daqp",))
       for identifier in ("Gmpc3", "MbMpc3")},
    **{identifier: NativeSpec(identifier, source, (*CONTROLLER, *PROFILE, *FREIGHT_TRACKER),
                              data=("references",))
       for identifier, source in (("FreightPid", "freight_pid.c"),
                                  ("FreightSmc", "freight_smc.c"),
                                  ("FreightFpid", "freight_fpid.c"),
                                  ("FreightPreview", "freight_preview.c"))},
    "EmuMfac3": NativeSpec("EmuMfac3", "ffdl_mfac.c", (*DATADRIVEN, *FFDL),
                           data=("references",)),
    "EmuIsmc3": NativeSpec("EmuIsmc3", "ffdl_ismc.c", (*DATADRIVEN, *SLIDING),
                           data=("references",)),
    "EmuIsmpc3": NativeSpec("EmuIsmpc3", "ffdl_ismpc.c", (*DATADRIVEN, *SLIDING),
                            data=("references",), solvers=("daqp",)),
    "EmuGpc3": NativeSpec("EmuGpc3", "emu_gpc.c", (*DATADRIVEN, *GPC), data=("references",)),
    # seed 003's GPC: its target profiles planned at build time by its core
    "Crh3Gpc": NativeSpec("Crh3Gpc", "crh3_gpc.c", (*CONTROLLER, *PROFILE, *GPC)),
    # seed 000's predictive stopping controllers: one law, DAQP from its sdist; the tube
    # controllers' terminal sets as computed by the core (ato_stop_mpc_sets.h)
    **{identifier: NativeSpec(identifier, "stop_mpc.c",
                              (*CONTROLLER, *GRADE, "linalg.c", "linalg.h"),
                              solvers=("daqp",), defines=(("ATO_STOP_MPC_KIND", kind),))
       for kind, identifier in enumerate(("StopMpc", "StopRmpc", "StopRsmpc"))},
    "FreightTrain": NativeSpec("FreightTrain", "freight.c",
                               ("freight_kernel.c", "freight_kernel.h"),
                               ("speed_limit", "additional"),
                               shared=(*PLANT_BACKEND, *NUMPY_RANDOM, *BUNDLED),
                               generated=("ato_numpy_normal.h",)),
    "Crh3Train": NativeSpec("Crh3Train", "crh3.c", shared=PLANT_SHARED),
    **{identifier: NativeSpec(identifier, "emu.c", shared=(*PLANT_SHARED, *NUMPY_RANDOM),
                              generated=("ato_numpy_normal.h",))
       for identifier in ("Emu3", "Emu8")},
}


def native_file(name: str) -> Path:
    """The C file or header ``name`` of the native models: the one file of that name in a
    folder of :data:`NATIVE_FOLDERS` under :data:`NATIVE_DIR` (the FMU's ``sources/`` holds
    them side by side, so a name is never used twice). Raises :class:`FileNotFoundError`
    naming the file and the folders searched when none has it."""
    found = _native_index(NATIVE_DIR).get(name)
    if found is None:
        raise FileNotFoundError(
            f"native C file {name!r} not found in {NATIVE_DIR}/"
            f"{{{','.join(NATIVE_FOLDERS)}}}/ (a NativeSpec names a file that is not there)")
    return found


@functools.cache
def _native_index(root: Path) -> dict[str, Path]:
    """File name -> path of every C file and header under ``root``'s :data:`NATIVE_FOLDERS`,
    read once per folder; raises :class:`ValueError` when a name is in two places or a file
    lies outside those folders (a flat ``sources/`` could hold only one of them)."""
    index: dict[str, Path] = {}
    for path in sorted(root.rglob("*")):
        if path.suffix not in (".c", ".h"):
            continue
        if path.relative_to(root).parts[0] not in NATIVE_FOLDERS or path.parent.parent != root:
            raise ValueError(f"{path}: a native C file belongs directly in one of "
                             f"{root}/{{{','.join(NATIVE_FOLDERS)}}}/")
        if path.name in index:
            raise ValueError(f"{path.name}: in {index[path.name].parent} and {path.parent}; "
                             "the FMU's flat sources/ needs one name per file")
        index[path.name] = path
    return index


class CompilerMissing(RuntimeError):
    """The C compiler a native build needs is not installed."""


def c_identifier(name: str) -> str:
    """A variable name as a C identifier: ``v[12]`` -> ``v_12`` (``[`` -> ``_``, ``]`` dropped)."""
    return name.replace("[", "_").replace("]", "")


def decl_header(identifier: str, variables, guid: str, options: dict | None = None) -> str:
    """``<id>_decl.h``: model identifier, GUID, one ``ATO_VR_<name>`` per variable (name as
    :func:`c_identifier`), the ``ATO_VARS`` table (causality, type, start, range) in
    value-reference order, ``ATO_OPTION_<key>`` per integer core option (e.g. ``units``), and
    for indexed names ``x[i]`` per base name ``ATO_N_x`` and ``ATO_VRS_x[]`` (value references
    in index order)."""
    types = {float: "ATO_REAL", int: "ATO_INTEGER", bool: "ATO_BOOLEAN", str: "ATO_STRING"}
    causality = {"parameter": "ATO_PARAMETER", "input": "ATO_INPUT", "output": "ATO_OUTPUT"}
    lines = [f"/* generated by cosim/build/native.py from the declarations of {identifier};"
             " do not edit */",
             "#include <math.h>", '#include "vars.h"',
             f"#define ATO_MODEL_IDENTIFIER {c_string(identifier)}",
             f"#define ATO_GUID {c_string(guid)}",
             f"#define ATO_N_VARS {len(variables)}", "enum {"]
    lines += [f"    ATO_VR_{c_identifier(v.name)} = {vr}," for vr, v in enumerate(variables)]
    lines += ["};"]
    lines += [f"#define ATO_OPTION_{key} {int(value)}" for key, value in (options or {}).items()]
    indexed: dict[str, list[int]] = {}
    for vr, v in enumerate(variables):
        found = re.fullmatch(r"(\w+)\[(\d+)\]", v.name)
        if found:
            indexed.setdefault(found[1], []).append(vr)
    for base, vrs in indexed.items():  # v[1] ... v[n]: ATO_N_v and ATO_VRS_v[] = {vr...}
        lines += [f"#define ATO_N_{base} {len(vrs)}",
                  f"static const int ATO_VRS_{base}[{len(vrs)}] = "
                  f"{{{', '.join(map(str, vrs))}}};"]
    lines += ["static const ato_var ATO_VARS[ATO_N_VARS] = {"]
    for v in variables:
        start = 0.0 if isinstance(v.start, str) else float(v.start)
        text = c_string(v.start) if isinstance(v.start, str) else "0"
        lines.append(
            f"    {{{c_string(v.name)}, {causality[v.causality]}, {types[v.type]}, "
            f"{c_double(start)}, {text}, {int(v.min is not None)}, {int(v.max is not None)}, "
            f"{c_double(v.min if v.min is not None else 0.0)}, "
            f"{c_double(v.max if v.max is not None else 0.0)}}},")
    lines.append("};")
    # the backend's event_time_vr (ato_backend.h): the value reference of the next_event_time
    # output, -1 for a model without events, from the same declaration as the FMI 3
    # modelDescription's hasEventMode (cosim.build.fmi3)
    event_vr = next((vr for vr, v in enumerate(variables)
                     if v.name == EVENT_TIME_OUTPUT and v.causality == "output"), -1)
    lines.append(f"#define ATO_EVENT_TIME_VR {event_vr}")
    return "\n".join(lines) + "\n"


def model_description(identifier: str, slave_class, sources: list[str], guid: str) -> bytes:
    """The Python wrapper's modelDescription (FMI 2.0) with this FMU's identifier, GUID and
    sources, ``needsExecutionTool="false"`` and no ``generationDateAndTime`` (a build is a
    function of its sources)."""
    with tempfile.TemporaryDirectory() as tmp:
        slave = slave_class(instance_name="native_build", resources=tmp)
        root: Element = slave.to_xml()
    root.set("modelName", identifier)
    root.set("guid", guid)
    root.set("generationTool", "ato-cosim native_build (C)")
    root.attrib.pop("generationDateAndTime", None)  # same sources, same file (and GUID)
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
    options that decide the floating-point results (:data:`FP_FLAGS`)."""
    root = Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    conf = SubElement(root, "BuildConfiguration", {"modelIdentifier": identifier})
    files = SubElement(conf, "SourceFileSet", {"language": "C99",
                                                "compilerOptions": " ".join(FP_FLAGS)})
    for name in sources:
        SubElement(files, "SourceFile", {"name": name})
    SubElement(files, "IncludeDirectory", {"name": "."})
    indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="utf-8")


def bundled_routes() -> Iterator[tuple[str, Route]]:
    """(name, route) of every bundled route, by name; the reference-profile TOMLs beside the
    routes are skipped."""
    for toml in sorted(ROUTES_DIR.glob("*.toml")):
        try:
            yield toml.stem, load_route(toml.stem)
        except ValueError:  # a reference-profile TOML beside the routes, not a route
            continue


def route_tables() -> dict[str, str]:
    """``<name>.grade`` text per bundled route: its grade steps ``start permille`` (%.17g via
    repr, which reads back exactly), the first start ``-inf``."""
    tables = {}
    for name, route in bundled_routes():
        grade = route.grade
        rows = [f"{'-inf' if math.isinf(s) else repr(float(s))} {float(g)!r}"
                for s, g in zip(grade.starts.tolist(), grade.values.tolist())]
        tables[name] = f"# grade steps of route {name}: start_m permille\n" + \
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
    tables = {}
    for name, loaded in bundled_routes():
        for kind in kinds:
            title, rows = ROUTE_PROFILES[kind](loaded)
            tables[f"{name}.{kind}"] = f"# {title} of route {name}\n" + \
                "\n".join(rows) + "\n"
    return tables


def reference_tables() -> dict[str, str]:
    """``references/<name>.ref`` per bundled reference profile (:func:`plants.route.
    load_reference`): the line ``kind distance|time`` then its points ``x v`` (SI, %.17g via
    repr, which reads back exactly)."""
    tables = {}
    for path in sorted([*ROUTES_DIR.glob("*.csv"), *ROUTES_DIR.glob("*.toml")]):
        try:
            profile = load_reference(path.stem)
        except (ValueError, AttributeError):  # a route, not a reference profile
            continue
        rows = [f"{float(x)!r} {float(v)!r}" for x, v in zip(profile.x.tolist(),
                                                              profile.v.tolist())]
        tables[f"references/{path.stem}.ref"] = (
            f"# reference profile {path.stem}: x (m or s) v (m/s)\nkind {profile.kind}\n"
            + "\n".join(rows) + "\n")
    return tables


# resources the builder writes for the models that ask for them (NativeSpec.data)
DATA = {"references": reference_tables}


# the step profiles of a route a native plant reads (plants.route.Route fields); sums such as
# Route.additional are formed in C by the same operations as StepProfile.sum
STEP_PROFILES = ("grade", "curve_resistance", "tunnel_resistance", "speed_limit", "neutral")


def _bits(value: float) -> str:
    """A double as the 16 hex digits of its IEEE bits: read back exactly by any C library."""
    return f"{struct.unpack('<Q', struct.pack('<d', float(value)))[0]:016x}"


def step_profile_tables() -> dict[str, str]:
    """``<name>.profiles`` text per bundled route: for each of :data:`STEP_PROFILES` a line
    ``profile <field> <count>`` and ``count`` lines ``<start bits> <value bits>`` (IEEE bits
    in hex, the decimal value after ``#``), the first start ``-inf``."""
    tables = {}
    for name, loaded in bundled_routes():
        lines = [f"# step profiles of route {name}: start_m value (IEEE bits, hex)"]
        for field in STEP_PROFILES:
            profile = getattr(loaded, field)
            lines.append(f"profile {field} {profile.starts.size}")
            lines += [f"{_bits(a)} {_bits(b)}  # {a!r} {b!r}"
                      for a, b in zip(profile.starts.tolist(), profile.values.tolist())]
        tables[name] = "\n".join(lines) + "\n"
    return tables


_PCG_MULT = 0x2360ED051FC65DA44385DF649FCCF645  # PCG64's 128-bit LCG multiplier
_M128 = (1 << 128) - 1


def numpy_normal_header() -> str:
    """``ato_numpy_normal.h``: the ziggurat tables of numpy's ``Generator.standard_normal``
    (``ATO_ZIG_KI``, ``ATO_ZIG_WI``, ``ATO_ZIG_FI``, 256 strips), measured from the installed
    numpy by feeding its PCG64 chosen raw outputs (the state is set so that the next outputs
    are given words): a draw ``idx | sign << 8 | rabs << 9`` returns ``rabs * wi[idx]`` and
    takes a second word exactly when ``rabs >= ki[idx]``, so ``wi`` (``rabs = 1``) and ``ki``
    (bisection on ``rabs``) are exact. ``fi[idx]`` enters only the rejection test of the
    rare slow path (``(fi[idx-1] - fi[idx]) u + fi[idx] < exp(-x^2 / 2)``): it is
    ``exp(-x_idx^2 / 2)`` of the strip edge ``x_idx = wi[idx] 2^52``, moved into the interval
    that numpy's accept/reject boundary at ``u = 0`` leaves for it (bisection on ``rabs``), so
    a decision can differ from numpy's only for a draw inside that interval (a few ulp)."""
    bg = np.random.PCG64(0)
    gen = np.random.Generator(bg)
    minv = pow(_PCG_MULT, -1, 1 << 128)

    def draw(first: int, second: int) -> tuple[float, int]:
        """standard_normal() with the next two raw words given; (value, words taken: 1, 2,
        or 3 for more)."""
        s1, s2 = first, second  # new states with high word 0 output their low word
        if (s2 - s1) % 2 == 0:  # the increment must be odd: high word 1, low word ^ 1
            s2 = second ^ (1 << 64) ^ 1
        inc = (s2 - s1 * _PCG_MULT) & _M128
        bg.state = {"bit_generator": "PCG64", "has_uint32": 0, "uinteger": 0,
                    "state": {"state": ((s1 - inc) * minv) & _M128, "inc": inc}}
        x = float(gen.standard_normal())
        now = bg.state["state"]["state"]
        return x, 1 if now == s1 else 2 if now == s2 else 3

    def word(idx: int, rabs: int) -> int:
        return idx | (rabs << 9)

    def first_true(pred, lo: int, hi: int) -> int:
        """Smallest n in [lo, hi] with pred(n) (pred monotone), hi if none."""
        while lo < hi:
            mid = (lo + hi) // 2
            if pred(mid):
                hi = mid
            else:
                lo = mid + 1
        return lo

    top = (1 << 52) - 1
    wi, ki, fi = [], [], []
    for idx in range(256):
        x, taken = draw(word(idx, 1), 0)
        if taken > 2:
            raise RuntimeError(f"numpy's standard_normal: strip {idx} rejects rabs = 1")
        wi.append(x)
        ki.append(first_true(lambda r, idx=idx: draw(word(idx, r), 0)[1] > 1, 0, top + 1))
    for idx in range(256):
        if idx == 0:
            fi.append(1.0)  # f(0): the top of the first strip
            continue
        edge = wi[idx] * 2.0 ** 52
        value = math.exp(-0.5 * edge * edge)

        def e(r: int, idx: int = idx) -> float:
            x = r * wi[idx]
            return math.exp(-0.5 * x * x)

        start = max(ki[idx], 1)
        rejected = first_true(lambda r, idx=idx: draw(word(idx, r), 0)[1] > 2, start,
                              top + 1)
        if rejected <= top:
            value = max(value, e(rejected))  # fi >= exp at the first rejected draw
        if rejected - 1 >= start:
            below = e(rejected - 1)  # fi < exp at the last accepted draw
            if value >= below:
                value = math.nextafter(below, 0.0)
        fi.append(value)

    def table(name: str, ctype: str, values, fmt) -> str:
        rows = [", ".join(fmt(v) for v in values[i:i + 4]) for i in range(0, 256, 4)]
        return f"static const {ctype} {name}[256] = {{\n    " + ",\n    ".join(rows) + "\n};"

    return "\n".join([
        f"/* generated by cosim/build/native.py from numpy {np.__version__}"
        " (numpy_normal_header); do not edit */",
        "#include <stdint.h>",
        table("ATO_ZIG_KI", "uint64_t", ki, lambda v: f"{v}ULL"),
        table("ATO_ZIG_WI", "double", wi, c_double),
        table("ATO_ZIG_FI", "double", fi, c_double),
    ]) + "\n"


# headers the builder generates for the models that include them (NativeSpec.generated)
GENERATED = {"ato_numpy_normal.h": numpy_normal_header}


def shipped_scenarios() -> list[Path]:
    """The shipped scenarios, sorted by name: ``scenarios/*.toml`` and each paper's
    ``papers/*/scenarios/*.toml`` (the files of :func:`cosim.run.scenario.scenario_files`)."""
    return sorted([*(ROOT / "scenarios").glob("*.toml"),
                   *(ROOT / "papers").glob("*/scenarios/*.toml")], key=lambda p: p.stem)


def shipped_entries() -> list[Path]:
    """The reproduction entries ``papers/*/entry.toml``, sorted by paper (the files of
    :func:`cosim.run.scenario.entry_files`)."""
    return sorted((ROOT / "papers").glob("*/entry.toml"))


def shipped_values(fmus: tuple[str, ...]) -> list[dict[str, Any]]:
    """The parameter values (FMU names) the project ships for the catalog FMUs ``fmus``: the
    declared defaults (``{}``), then per shipped scenario (:func:`shipped_scenarios`) each of
    its components whose ``fmu`` is one of them with its ``parameters``, then per
    reproduction run (:func:`shipped_entries`, ``[[runs]]``) of such a scenario that
    component's values with the run's ``<component>.*`` settings over them."""
    values: list[dict[str, Any]] = [{}]
    used: dict[str, list[tuple[str, dict[str, Any]]]] = {}
    for path in shipped_scenarios():
        components = tomllib.loads(path.read_text()).get("fmus", {})
        for name, component in components.items():
            if isinstance(component, dict) and component.get("fmu") in fmus:
                given = dict(component.get("parameters", {}))
                used.setdefault(path.stem, []).append((name, given))
                values.append(given)
    for path in shipped_entries():
        for run in tomllib.loads(path.read_text()).get("runs", []):
            for name, given in used.get(run.get("scenario"), []):
                merged = dict(given)
                merged.update({key.split(".", 1)[1]: value
                               for key, value in run.get("set", {}).items()
                               if key.startswith(f"{name}.")})
                values.append(merged)
    return values


def core_data(identifier: str, slave_class: Any) -> dict[str, str]:
    """What the core of the catalog FMU ``identifier`` ships to its native twin: its
    ``native_data(identifier, shipped_values)`` (path in the FMU -> text: generated headers
    under ``sources/``, data files under ``resources/``), none for a core without one."""
    declared = getattr(slave_class.core_class, "native_data", None)
    return {} if declared is None else declared(identifier, shipped_values)


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


GUID_PLACEHOLDER = "{00000000-0000-4000-8000-000000000000}"  # replaced by the sources' GUID


def _tree_digest(root: Path, skip: str = "binaries") -> bytes:
    """SHA-256 of every file under ``root`` (relative POSIX path and bytes, in sorted order),
    the folder ``skip`` left out."""
    h = hashlib.sha256()
    for f in sorted(p for p in root.rglob("*") if p.is_file()):
        rel = f.relative_to(root).as_posix()
        if rel.split("/")[0] == skip:
            continue
        data = f.read_bytes()
        h.update(f"{rel}\0{len(data)}\0".encode())
        h.update(data)
    return h.digest()


def _stamp_guid(root: Path, files: list[Path]) -> str:
    """Replace :data:`GUID_PLACEHOLDER` in ``files`` by the GUID derived from the tree's
    digest (:func:`_tree_digest` with the placeholder in place): a UUID version 4 layout of
    its first 16 bytes. Returns the GUID."""
    guid = "{" + str(uuid.UUID(bytes=_tree_digest(root)[:16], version=4)) + "}"
    for f in files:
        f.write_bytes(f.read_bytes().replace(GUID_PLACEHOLDER.encode(), guid.encode()))
    return guid


@functools.cache
def _compiler_identity(cc: str) -> str:
    """The compiler's path and ``--version`` text (a part of the build cache's key)."""
    done = subprocess.run([cc, "--version"], capture_output=True, text=True)
    return f"{cc}\n{done.stdout}"


def _compile_cached(root: Path, jobs: list[tuple[str, Path, Path, bool]]) -> None:
    """:func:`_compile_side_by_side` of ``jobs`` (each output under ``root``), or their
    outputs from the build cache (``<cache>/native/<key>/``) when the same sources (every file
    under ``root`` but ``binaries/``) were compiled by the same compilers with the same flags
    before. A new result is stored in a staged folder renamed into place, so concurrent
    builds never see a partial entry, and a lock file per key makes a second build of the
    same sources wait for the first instead of compiling again; an unwritable cache only
    skips the cache."""
    base = cache_root()
    if base is None:
        _compile_side_by_side(jobs)
        return
    h = hashlib.sha256(_tree_digest(root))
    for cc, _src, out, windows in jobs:
        h.update(f"{_compiler_identity(cc)}\0{out.relative_to(root).as_posix()}\0"
                 f"{windows}\0{' '.join(CC_FLAGS)}\0".encode())
    outputs = [out.relative_to(root) for _cc, _src, out, _windows in jobs]
    entry = base / "native" / h.hexdigest()
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        lock = open(entry.with_suffix(".lock"), "a")  # noqa: SIM115 - held for the build
    except OSError:  # an unwritable cache: build without it
        _compile_side_by_side(jobs)
        return
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one build of these sources at a time; others wait
        if all((entry / rel).is_file() for rel in outputs):
            for rel in outputs:
                (root / rel).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(entry / rel, root / rel)
            return
        _compile_side_by_side(jobs)
        staged = entry.with_name(f".{entry.name}.{os.getpid()}.{threading.get_ident()}.tmp")
        try:
            for rel in outputs:
                (staged / rel).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(root / rel, staged / rel)
            os.replace(staged, entry)
        except OSError:  # stored by another build, or the cache is full: keep the build
            shutil.rmtree(staged, ignore_errors=True)


def _compile_side_by_side(jobs: list[tuple[str, Path, Path, bool]]) -> None:
    """:func:`compile_binary` of each ``(cc, src_dir, out, windows)`` job, the compilers
    running at the same time (each in its own process); creates the output folders."""
    from concurrent.futures import ThreadPoolExecutor

    for job in jobs:
        job[2].parent.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(max_workers=max(len(jobs), 1)) as pool:
        for done in [pool.submit(compile_binary, *job) for job in jobs]:
            done.result()


def native_sources(identifier: str, fmi_version: int = 2) -> list[Path]:
    """Every file the native FMU ``identifier`` is made from: its C files, the FMI 2 front
    (and for FMI 3.0 the FMI 3 front and the modelDescription derivation), this builder, the
    C literals it writes with (``cosim/fmu/c_text.py``) and the Python wrapper's files
    (declarations, the core and its ``native_data``, bundled data)."""
    spec = NATIVE[identifier]
    fmi3_files = [FRONT_DIR / "fmi3_front.c", HERE / "fmi3.py"] if fmi_version == 3 else []
    return [*map(native_file, (spec.source, "vars.h", *spec.helpers, *spec.shared)),
            FRONT_DIR / "fmi2_front.c",
            FRONT_DIR / "ato_backend.h", FRONT_DIR / "instance_registry.h", Path(__file__),
            FMU_LAYER / "c_text.py", *([HERE / "solvers.py"] if spec.solvers else []),
            *bundled_files(catalog()[identifier].module), *fmi3_files]


def native_is_stale(identifier: str, fmi_version: int = 2) -> bool:
    """True when the native FMI ``fmi_version`` FMU ``identifier`` is missing or older than a
    file it is made from (:func:`native_sources`; checked once while neither it nor a project
    file changes, :func:`cosim.build.python.stale_unless_known`)."""
    path = native_path(identifier, fmi_version)
    return stale_unless_known(("native", identifier, fmi_version), path,
                              functools.partial(_native_is_stale, identifier, fmi_version, path))


def _native_is_stale(identifier: str, fmi_version: int, path: Path) -> bool:
    if not path.is_file():
        return True
    built = path.stat().st_mtime
    return any(f.is_file() and f.stat().st_mtime > built
               for f in native_sources(identifier, fmi_version))


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
    from_core = core_data(identifier, slave_class)
    guid = GUID_PLACEHOLDER  # the sources' own GUID is stamped in once they are written
    headers = Path(fmpy.__file__).parent / "c-code"
    solvers = [solver_files(name) for name in spec.solvers]
    c_files = list(dict.fromkeys([  # a file two shared groups name is compiled once
        "fmi2_front.c", spec.source,
        *(f for f in (*spec.helpers, *spec.shared) if f.endswith(".c")),
        *(f.name for solver in solvers for f in solver.sources if f.suffix == ".c")]))
    with tempfile.TemporaryDirectory(prefix="atocosim_native_") as tmp:
        root = Path(tmp) / "fmu"
        src = root / "sources"
        src.mkdir(parents=True)
        shutil.copy2(FRONT_DIR / "fmi2_front.c", src)
        shutil.copy2(FRONT_DIR / "ato_backend.h", src)
        shutil.copy2(FRONT_DIR / "instance_registry.h", src)
        for name in (spec.source, *spec.helpers, "vars.h", *spec.shared):  # flat, by name
            shutil.copy2(native_file(name), src)
        for name in spec.generated:
            (src / name).write_text(GENERATED[name]())
        for rel, text in from_core.items():  # the core's headers (sources/), data (resources/)
            target = root / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text)
        config = f"{identifier}_config.h"  # named train data, from the core (Emu)
        if spec.shared:  # the plant model includes this FMU's headers by one name
            (src / "ato_model_decl.h").write_text(
                f'#include "{identifier}_decl.h"\n'
                + (f'#include "{config}"\n' if f"sources/{config}" in from_core else ""))
        for h in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"):
            shutil.copy2(headers / h, src)
        for solver in solvers:  # the solver's own files, flat beside ours, and its licence
            for f in solver.sources:
                if (src / f.name).exists():
                    raise RuntimeError(f"{identifier}: {solver.name}'s {f.name} has the name "
                                       "of a file of the model")
                shutil.copy2(f, src)
            licence = root / solver.license_name
            licence.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(solver.license, licence)
        (src / f"{identifier}_decl.h").write_text(
            decl_header(identifier, slave_class.variables, guid,
                        getattr(slave_class, "core_options", None)))
        (src / "ato_model.h").write_text(  # the model's header for the shared C files
            f'/* generated by cosim/build/native.py */\n#include "{identifier}_decl.h"\n'
            + "".join(f"#define {name} {int(value)}\n" for name, value in spec.defines))
        (src / "buildDescription.xml").write_bytes(build_description(identifier, c_files))
        (root / "modelDescription.xml").write_bytes(
            model_description(identifier, slave_class, c_files, guid))
        routes = root / "resources" / "routes"
        routes.mkdir(parents=True)
        for name, text in route_tables().items():
            (routes / f"{name}.grade").write_text(text)
        for name, text in route_profile_tables(spec.route_profiles).items():
            (routes / name).write_text(text)
        if "plant_common.c" in spec.shared:
            for name, text in step_profile_tables().items():
                (routes / f"{name}.profiles").write_text(text)
        for kind in spec.data:
            for rel, content in DATA[kind]().items():
                target = root / "resources" / rel
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_text(content)
        _stamp_guid(root, [src / f"{identifier}_decl.h", root / "modelDescription.xml"])
        _compile_cached(
            root,
            [(cc, src, root / "binaries" / platform / f"{identifier}{suffix}", suffix == ".dll")
             for cc, platform, suffix in ((gcc, "linux64", ".so"), (mingw, "win64", ".dll"))
             if cc is not None])
        dest.mkdir(parents=True, exist_ok=True)
        staged = dest / f".{identifier}.fmu.{os.getpid()}.tmp"
        with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as z:
            for f in sorted(p for p in root.rglob("*") if p.is_file()):
                z.write(f, f.relative_to(root).as_posix())
        final = dest / f"{identifier}.fmu"
        os.replace(staged, final)
    return final


# -- FMI 3.0: the FMI 2 build's sources behind the FMI 3 front ------------------------------

FMI_VERSIONS = (2, 3)
EVENT_TIME_OUTPUT = "next_event_time"  # the controllers' announced next event (slave.py)
FP_FLAGS = [f for f in CC_FLAGS if not f.startswith(("-O", "-W"))]  # decide the results
FMI2_FRONT = "fmi2_front.c"
FMI3_FRONT = "fmi3_front.c"
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
FMI3_LINUX, FMI3_WINDOWS = "x86_64-linux", "x86_64-windows"  # binaries/<platform tuple>


def native_path(identifier: str, fmi_version: int = 2, dest: Path = NATIVE_FMU_DIR) -> Path:
    """Where the native FMI ``fmi_version`` build of ``identifier`` goes under ``dest``:
    ``dest/<id>.fmu`` (FMI 2.0) or ``dest/fmi3/<id>.fmu`` (FMI 3.0), as ``fmus/`` and
    ``fmus/fmi3/`` hold the Python FMUs' builds."""
    if fmi_version not in FMI_VERSIONS:
        raise ValueError(f"fmi_version {fmi_version!r}: expected one of {list(FMI_VERSIONS)}")
    return (dest if fmi_version == 2 else dest / "fmi3") / f"{identifier}.fmu"


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


def package_fmi3(fmi2_fmu: Path, out: Path, windows: bool | None = None) -> Path:
    """Write the native FMI 3.0 FMU ``out`` from the native FMI 2.0 FMU ``fmi2_fmu``.

    Whatever the FMI 2 build holds (every C file, generated header and resource of the model)
    is kept; the FMI 2 front in ``sources/`` is replaced by ``cosim/fmu/front/fmi3_front.c``
    (the front of the Python FMUs' FMI 3 builds, here linked with the model, whose backend
    calls the model directly) plus the FMI 3 headers (the FMI 2 ones stay: the backend
    interface is declared with them), ``buildDescription.xml`` names it, modelDescription.xml
    is :func:`cosim.build.fmi3.model_description` of the FMI 2 one (same variables and GUID as
    ``instantiationToken``), and the sources are compiled into
    ``binaries/x86_64-linux/<id>.so`` and, with ``windows`` (default: when mingw-w64 is
    installed), ``binaries/x86_64-windows/<id>.dll``."""
    from xml.etree import ElementTree

    import fmpy

    gcc, mingw = _compilers(windows)
    headers = Path(fmpy.__file__).parent / "c-code"
    with tempfile.TemporaryDirectory(prefix="atocosim_native3_") as tmp:
        root = Path(tmp) / "fmu"
        with zipfile.ZipFile(fmi2_fmu) as z:
            z.extractall(root)
        md, _ = fmi3.model_description((root / "modelDescription.xml").read_bytes())
        (root / "modelDescription.xml").write_bytes(md)
        identifier = ElementTree.fromstring(md).find("CoSimulation").get("modelIdentifier")
        shutil.rmtree(root / "binaries")
        src = root / "sources"
        if not (src / FMI2_FRONT).is_file():
            raise ValueError(f"{fmi2_fmu}: no sources/{FMI2_FRONT}: not a native FMI 2.0 FMU "
                             "of this project")
        (src / FMI2_FRONT).unlink()
        shutil.copy2(FRONT_DIR / FMI3_FRONT, src)
        shutil.copy2(FRONT_DIR / "instance_registry.h", src)
        for name in FMI3_HEADERS:
            shutil.copy2(headers / name, src)
        described = ElementTree.parse(src / "buildDescription.xml").getroot()
        for entry in described.iter("SourceFile"):
            if entry.get("name") == FMI2_FRONT:
                entry.set("name", FMI3_FRONT)
        (src / "buildDescription.xml").write_bytes(
            b'<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(described, encoding="utf-8"))
        _compile_cached(
            root,
            [(cc, src, root / "binaries" / platform / f"{identifier}{suffix}", suffix == ".dll")
             for cc, platform, suffix in ((gcc, FMI3_LINUX, ".so"), (mingw, FMI3_WINDOWS, ".dll"))
             if cc is not None])
        out.parent.mkdir(parents=True, exist_ok=True)
        staged = out.parent / f".{out.name}.{os.getpid()}.tmp"
        with zipfile.ZipFile(staged, "w", zipfile.ZIP_DEFLATED) as z:
            for f in sorted(p for p in root.rglob("*") if p.is_file()):
                z.write(f, f.relative_to(root).as_posix())
        os.replace(staged, out)
    return out


def build_natives(identifier: str, fmi_versions: tuple[int, ...] = FMI_VERSIONS,
                  dest: Path = NATIVE_FMU_DIR, windows: bool | None = None) -> list[Path]:
    """Build the native FMUs of ``identifier`` in ``fmi_versions`` to :func:`native_path`
    under ``dest`` (the paths in the order given): the FMI 2 build (:func:`build_native`; made
    in a scratch folder when only FMI 3 is asked for) and the FMI 3 build derived from it
    (:func:`package_fmi3`), so both share one GUID. ``windows``: also the Windows DLLs
    (default: when mingw-w64 is installed). Raises :class:`CompilerMissing` naming the
    compiler when it is absent, before anything is written."""
    if identifier not in NATIVE:
        raise ValueError(f"no native model of {identifier!r}; native: {sorted(NATIVE)}")
    targets = {version: native_path(identifier, version, dest) for version in fmi_versions}
    _compilers(windows)
    with tempfile.TemporaryDirectory(prefix="atocosim_native2_") as scratch:
        if 2 in targets:
            fmi2 = build_native(identifier, dest, windows)
        else:  # only its sources and model description are used: no Windows DLL
            fmi2 = build_native(identifier, Path(scratch), windows=False)
        if 3 in targets:
            package_fmi3(fmi2, targets[3], windows)
    return [targets[version] for version in fmi_versions]


def build_all_natives(identifiers: list[str], fmi_versions: tuple[int, ...] = FMI_VERSIONS,
                      dest: Path = NATIVE_FMU_DIR, windows: bool | None = None,
                      workers: int | None = None) -> dict[str, list[Path]]:
    """:func:`build_natives` of each of ``identifiers``, ``workers`` models at a time (default:
    the machine's CPU count; the compilers are processes, so threads suffice). Returns
    identifier -> paths in the order given; raises the first model's error (after the builds
    under way have ended), :class:`CompilerMissing` before anything is written."""
    from concurrent.futures import ThreadPoolExecutor

    for identifier in identifiers:
        if identifier not in NATIVE:
            raise ValueError(f"no native model of {identifier!r}; native: {sorted(NATIVE)}")
        for version in fmi_versions:
            native_path(identifier, version, dest)  # a known FMI version
    _compilers(windows)
    with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 1) as pool:
        futures = {identifier: pool.submit(build_natives, identifier, fmi_versions, dest,
                                           windows)
                   for identifier in identifiers}
        return {identifier: future.result() for identifier, future in futures.items()}
