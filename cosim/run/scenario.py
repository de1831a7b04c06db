"""Scenario files (TOML): which FMUs, their parameters, connections, timing and what to record.

Format (the files in ``scenarios/`` are examples)::

    description = "..."
    [simulation]
    stop_time = 60.0          # s (required)
    start_time = 0.0          # s
    output_interval = 0.2     # s, spacing of the recorded time series
    algorithm = "event"       # event | fixed | jacobi
    base_step = 0.2           # s, communication step of the fixed-step algorithms
    fmi_version = 2           # 2 | 3: catalog FMU names resolve to fmus/<Id>.fmu (FMI 2.0)
                              # or fmus/fmi3/<Id>.fmu (FMI 3.0); .fmu paths are used as given
    unconnected_inputs = "start"  # start | error: an input neither connected nor given in
                              # [fmus.NAME.inputs] keeps its declared start value (listed
                              # once in the log), or is an error; one without a start value
                              # is always an error
    [fmus.NAME]
    fmu = "BrakeDelayTrain"   # FMU identifier in fmus/ (built on demand) or a path to a .fmu
    build = "python"          # python | native: which build of a catalog FMU identifier;
                              # native: the C FMU fmus/native/<Id>.fmu (no Python; FMI 3.0:
                              # fmus/native/fmi3/<Id>.fmu)
    sample_time = 0.2         # s, optional: periodic events of a sampled FMU (also set as its
                              # `sample_time` parameter if it has one)
    max_step = 0.5            # s, optional: longest communication step for this FMU
    [fmus.NAME.parameters]    # parameter values (names as in the FMU's modelDescription)
    [fmus.NAME.inputs]        # constant values for inputs that are not connected
    [connections]             # "dst.input" = "src.output" (one source per input)
    [record]
    variables = ["NAME.var", ...]   # default: every output of every FMU
    [summary]                 # recorded variables the summary metrics read (cosim.run.metrics)

Every error names the file, the key and what is wrong.
"""

from __future__ import annotations

import difflib
import functools
import importlib
import math
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from cosim.build import native
from cosim.build.python import FMU_DIR, ROOT, catalog
from cosim.fmu.state import TICKS_PER_SECOND, to_ticks
from cosim.run import fmi_types
from cosim.run.metrics import PAPERS

RACY_S = 2.0  # s: a folder changed this recently may change again within its clock's tick
SCENARIO_DIR = ROOT / "scenarios"  # scenarios of no one paper (scenarios/*.toml)
PAPERS_DIR = ROOT / "papers"  # a folder per paper: papers/NAME/entry.toml, scenarios/*.toml, ...
ALGORITHMS = ("event", "fixed", "jacobi")
FMI_VERSIONS = (2, 3)
UNCONNECTED_INPUTS = ("start", "error")  # [simulation] unconnected_inputs
BUILDS = ("python", "native")  # [fmus.NAME] build: the Python FMU or the native C one
COMPONENT_KEYS = ("fmu", "build", "sample_time", "max_step")  # --set NAME.key=value


RECORD_KEYS = ("variables",)
# what cosim.run.metrics and the plot read (see the cosim.run.metrics module docstring)
# (tests/test_scenario_keys.py checks this list against the keys metrics.py reads)
SUMMARY_KEYS = ("position", "speed", "acceleration", "command", "command_resolution",
                "reference_speed",
                "speed_limit", "power", "coupler_forces", "stop_point", "reference_decel",
                "planned_arrival_time", "accel_command", "metrics")
# and the keys of the paper metrics the scenario names in ``metrics`` (cosim.papers)


# [summary] keys holding a number; a string "instance.parameter" there reads that parameter's
# value as the scenario sets it (after --set), so the summary never keeps a stale copy
SUMMARY_PARAMETER_KEYS = ("stop_point", "planned_arrival_time", "final_stop_window",
                          "ma_sample_time", "command_resolution", "reference_decel")


def resolve_parameter_refs(path: Path, summary: dict[str, Any],
                           components: dict[str, Any]) -> dict[str, Any]:
    """``summary`` with each ``"instance.parameter"`` value of a numeric key replaced by the
    parameter's value in ``[fmus.instance.parameters]``."""
    resolved = dict(summary)
    for key in SUMMARY_PARAMETER_KEYS:
        value = summary.get(key)
        if not isinstance(value, str):
            continue
        comp, _, name = value.partition(".")
        if comp not in components or name not in components[comp].parameters:
            raise ScenarioError(f"{path}: [summary] {key} = {value!r}: a reference reads a "
                                f"parameter set in [fmus.{comp}.parameters], and "
                                + (f"{comp!r} sets no {name!r}" if comp in components
                                   else f"there is no FMU instance {comp!r}"))
        resolved[key] = components[comp].parameters[name]
    return resolved


class ScenarioError(ValueError):
    """A scenario file or override that cannot be run; the message names file and key."""


@dataclass
class Component:
    name: str
    fmu: str  # identifier or path as written
    fmu_path: Path
    build: str = "python"  # python | native (BUILDS)
    sample_time: float | None = None
    max_step: float | None = None
    parameters: dict[str, Any] = field(default_factory=dict)
    inputs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Connection:
    src: str  # component name
    src_var: str
    dst: str
    dst_var: str

    def __str__(self) -> str:
        return f"{self.src}.{self.src_var} -> {self.dst}.{self.dst_var}"


@dataclass
class Simulation:
    stop_time: float
    start_time: float = 0.0
    output_interval: float = 0.1
    algorithm: str = "event"
    base_step: float | None = None
    fmi_version: int = 2  # which builds of catalog FMUs the scenario runs
    # an input neither connected nor set: keeps its start value ("start") or is refused
    unconnected_inputs: str = "start"


@dataclass
class Scenario:
    path: Path
    name: str
    description: str
    simulation: Simulation
    components: dict[str, Component]
    connections: list[Connection]
    record: list[str] | None
    summary: dict[str, Any]
    raw: dict[str, Any]
    # "[fmus.plant.parameters] mass" -> "plant.mass=539000": keys that came from --set
    overrides: dict[str, str] = field(default_factory=dict)


def scenario_files() -> dict[str, Path]:
    """The shipped scenarios by name, sorted: ``scenarios/*.toml`` and each paper's
    ``papers/*/scenarios/*.toml`` (the one list every caller reads); :class:`ScenarioError`
    naming both files when a name is found twice. The listing is kept while none of its
    folders changes (:func:`_scenario_folders`), not read at every call: an ensemble resolves
    a scenario name once per member. A folder changed within :data:`RACY_S` of now is read
    again at every call (a file system's clock may be coarser than the change, as in git's
    racy-clean rule)."""
    folders = _scenario_folders()
    now = time.time_ns()
    if any(now - changed < RACY_S * 1e9 for _folder, changed in folders):
        return dict(_scenario_listing.__wrapped__(folders))
    return dict(_scenario_listing(folders))


def _scenario_folders() -> tuple[tuple[str, int], ...]:
    """The folders :func:`scenario_files` lists with their modification times (ns; -1 for a
    missing one): adding, removing or renaming a scenario file changes its folder's time."""
    def mtime(folder: str) -> int:
        try:
            return os.stat(folder).st_mtime_ns
        except OSError:
            return -1

    try:
        papers = sorted(entry.path for entry in os.scandir(PAPERS_DIR) if entry.is_dir())
    except OSError:
        papers = []
    folders = [str(SCENARIO_DIR), *(os.path.join(paper, "scenarios") for paper in papers)]
    return tuple((folder, mtime(folder)) for folder in folders)


@functools.lru_cache(maxsize=8)
def _scenario_listing(folders: tuple[tuple[str, int], ...]) -> tuple[tuple[str, Path], ...]:
    found: dict[str, Path] = {}
    for path in [p for folder, changed in folders if changed >= 0
                 for p in Path(folder).glob("*.toml")]:
        if path.stem in found:
            raise ScenarioError(f"scenario {path.stem!r} is shipped twice: {found[path.stem]} "
                                f"and {path}")
        found[path.stem] = path
    return tuple(sorted(found.items()))


def entry_files() -> dict[str, Path]:
    """The reproduction entries by name, sorted: ``papers/NAME/entry.toml`` (the paper's
    folder names its entry)."""
    return {path.parent.name: path for path in sorted(PAPERS_DIR.glob("*/entry.toml"))}


def find_scenario(name_or_path: str | Path) -> Path:
    """A scenario by path, or by name among :func:`scenario_files` (with or without
    ``.toml``)."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    shipped = scenario_files()
    name = str(name_or_path)
    name = name[:-len(".toml")] if name.endswith(".toml") else name
    if name in shipped:
        return shipped[name]
    for candidate in (SCENARIO_DIR / f"{name}.toml", SCENARIO_DIR / f"{name_or_path}"):
        if candidate.is_file():  # a path under scenarios/ (scenarios/mixed/...)
            return candidate
    known = sorted(shipped)
    hint = difflib.get_close_matches(str(name_or_path), known, n=1)
    raise ScenarioError(f"{name_or_path}: no such scenario file"
                        + (f" (did you mean {hint[0]!r}?)" if hint else f"; shipped: {known}"))


def parse_value(text: str) -> Any:
    """A ``--set`` value: a TOML literal (number, bool, string, array), else the raw string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_overrides(raw: dict[str, Any], overrides: dict[str, Any] | list[str] | None,
                    source: str) -> None:
    """Apply ``NAME.param=value`` (parameter), ``NAME.sample_time=``, ``simulation.key=``,
    ``summary.key=`` overrides in place."""
    if not overrides:
        return
    items = overrides.items() if isinstance(overrides, dict) else [
        _split_override(o) for o in overrides]
    for key, value in items:
        if isinstance(value, str) and not isinstance(overrides, dict):
            value = parse_value(value)
        head, _, rest = key.partition(".")
        if not rest:
            raise ScenarioError(f"{source}: --set {key}: expected NAME.key=value")
        if head in ("simulation", "summary"):
            raw.setdefault(head, {})[rest] = value
            continue
        fmus = raw.get("fmus", {})
        if head not in fmus:
            raise ScenarioError(f"{source}: --set {key}: no FMU named {head!r} "
                                f"(scenario has {sorted(fmus)})")
        if rest in COMPONENT_KEYS:
            fmus[head][rest] = value
        elif rest.startswith("inputs."):
            fmus[head].setdefault("inputs", {})[rest[7:]] = value
        else:
            fmus[head].setdefault("parameters", {})[rest] = value


def override_keys(overrides: dict[str, Any] | list[str] | None) -> dict[str, str]:
    """The scenario key each override replaces, as error messages spell it
    (``"[fmus.plant.parameters] mass"``), mapped to the ``--set`` text that set it."""
    if not overrides:
        return {}
    items = ([(k, f"{k}={v}") for k, v in overrides.items()] if isinstance(overrides, dict)
             else [(_split_override(o)[0], o) for o in overrides])
    keys: dict[str, str] = {}
    for key, text in items:
        head, _, rest = key.partition(".")
        if head in ("simulation", "summary"):
            keys[f"[{head}] {rest}"] = text
        elif rest in COMPONENT_KEYS:
            keys[f"[fmus.{head}] {rest}"] = text
        elif rest.startswith("inputs."):
            keys[f"[fmus.{head}.inputs] {rest[7:]}"] = text
        else:
            keys[f"[fmus.{head}.parameters] {rest}"] = text
    return keys


def blame_override(err: ScenarioError, path: Path,
                   overrides: dict[str, str]) -> ScenarioError:
    """``err`` reworded to name the ``--set`` option when the key at fault came from one."""
    message = str(err)
    for key, text in overrides.items():
        name = key.rpartition("] ")[2]
        for head, lead in ((f"{path}: {key}: ", ""), (f"{path}: {key} ", f"{name} ")):
            if message.startswith(head):
                return ScenarioError(f"--set {text}: {lead}{message[len(head):]} (in place of "
                                     f"{key} in {path})")
    return err


def _split_override(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise ScenarioError(f"--set {text!r}: expected KEY=VALUE, e.g. plant.mass=539000")
    return key.strip(), value.strip()


def _paper_metric_keys(source: Path, summary: dict[str, Any]) -> list[str]:
    """The ``[summary]`` keys the paper metrics named in ``metrics`` read; raise naming the
    metric for an unknown name, and the metric to add for a key that only an unnamed metric
    reads."""
    papers = importlib.import_module(PAPERS)  # the plug-ins above this layer, by name

    names = summary.get("metrics", [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ScenarioError(f"{source}: [summary] metrics = {names!r}: expected a list of "
                            "metric names")
    registry = papers.registry()
    for name in names:
        if name not in registry:
            hint = difflib.get_close_matches(name, list(registry), n=1)
            raise ScenarioError(f"{source}: [summary] metrics: no metric {name!r}"
                                + (f" (did you mean {hint[0]!r}?)" if hint else
                                   f"; registered: {', '.join(sorted(registry))}"))
    keys = [k for n in names for k in registry[n].keys]
    for key in summary:
        if key in registry and key not in SUMMARY_KEYS:
            raise ScenarioError(f"{source}: [summary] {key}: a paper metric; name it in "
                                f"[summary] metrics = [{key!r}, ...]")
    for key, owners in papers.declared_keys().items():
        if key in summary and key not in keys and key not in SUMMARY_KEYS:
            raise ScenarioError(f"{source}: [summary] {key}: read by the metric "
                                f"{' or '.join(repr(o) for o in owners)}, which [summary] "
                                "metrics does not name")
    return keys


def _refuse_unknown(source: Path, table: str, given: dict[str, Any],
                    known: tuple[str, ...]) -> None:
    """Raise naming the first key of ``given`` that is not in ``known``, with the closest known
    key (difflib) or the list of known keys."""
    for bad in sorted(set(given) - set(known)):
        hint = difflib.get_close_matches(bad, known, n=1)
        raise ScenarioError(f"{source}: {table} {bad}: unknown key"
                            + (f" (did you mean {hint[0]!r}?)" if hint else
                               f"; known: {', '.join(known)}"))


def _number(source: str, key: str, value: Any, positive: bool = True,
            allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(f"{source}: {key} = {value!r}: expected a number")
    value = float(value)
    if not math.isfinite(value):
        raise ScenarioError(f"{source}: {key} = {value}: must be finite")
    if positive and not (value > 0 or (allow_zero and value == 0)):
        raise ScenarioError(f"{source}: {key} = {value}: must be "
                            + ("non-negative" if allow_zero else "positive"))
    return value


MAX_TIME_TICKS = 2**63 - 1  # ns: the master's times are integer nanoseconds in 64-bit integers


def _time(source: str, key: str, value: Any, positive: bool = True) -> float:
    """A time of the scenario (s): a finite number (positive unless ``positive`` is False)
    whose integer nanoseconds fit in 64 bits, and, when positive, at least the 1 ns tick."""
    seconds = _number(source, key, value, positive)
    if abs(seconds) > MAX_TIME_TICKS / TICKS_PER_SECOND:
        raise ScenarioError(f"{source}: {key} = {seconds}: out of range: times are integer "
                            f"nanoseconds in 64 bits, at most "
                            f"{MAX_TIME_TICKS / TICKS_PER_SECOND:.6g} s")
    if positive and to_ticks(seconds) == 0:
        raise ScenarioError(f"{source}: {key} = {seconds}: below the master's 1 ns tick")
    return seconds


def read_toml(path: Path, error: type[Exception] = ScenarioError) -> dict[str, Any]:
    """The TOML file ``path``; ``error`` naming the file when it is not UTF-8 (with the byte
    offset of the first byte that is not) or not valid TOML."""
    data = Path(path).read_bytes()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise error(f"{path}: not UTF-8 text: byte {err.start} is 0x{data[err.start]:02x} "
                    "(TOML files are UTF-8: save it as UTF-8, e.g. `iconv -f latin1 -t utf-8`)"
                    ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise error(f"{path}: not valid TOML: {err}") from None


def catalog_path(identifier: str, fmi_version: int = 2) -> Path:
    """Where the FMI ``fmi_version`` build of catalog FMU ``identifier`` lives."""
    return (FMU_DIR / "fmi3" if fmi_version == 3 else FMU_DIR) / f"{identifier}.fmu"


def native_path(source: Path, key: str, fmu: str, fmi_version: int) -> Path:
    """Where the native build of catalog FMU ``fmu`` in FMI version ``fmi_version`` lives
    (``fmus/native/<Id>.fmu``, ``fmus/native/fmi3/<Id>.fmu``); refused for an FMU without a
    native model."""
    if fmu.endswith(".fmu"):
        raise ScenarioError(f"{source}: {key} = 'native': fmu = {fmu!r} is a file, used as "
                            "given; build selects the build of a catalog identifier")
    if fmu not in native.NATIVE:
        raise ScenarioError(f"{source}: {key} = 'native': {fmu!r} has no native model "
                            f"(native: {sorted(native.NATIVE)})")
    return native.native_path(fmu, fmi_version)


def _resolve_fmu(source: Path, key: str, fmu: Any, fmi_version: int = 2,
                 build: str = "python") -> Path:
    if not isinstance(fmu, str) or not fmu:
        raise ScenarioError(f"{source}: {key} = {fmu!r}: expected an FMU identifier or path")
    if build not in BUILDS:
        raise ScenarioError(f"{source}: {key.replace(' fmu', ' build')} = {build!r}: expected "
                            f"one of {list(BUILDS)}")
    if build == "native":
        return native_path(source, key.replace(" fmu", " build"), fmu, fmi_version)
    if fmu.endswith(".fmu"):
        path = Path(fmu)
        if not path.is_absolute():
            path = (source.parent / path).resolve()
        if not path.is_file():
            raise ScenarioError(f"{source}: {key} = {fmu!r}: file {path} does not exist")
        return path
    built = catalog_path(fmu, fmi_version)
    if built.is_file():  # a built catalog FMU: no need to import every wrapper module
        return built
    known = catalog()
    if fmu not in known:
        hint = difflib.get_close_matches(fmu, list(known), n=1)
        raise ScenarioError(f"{source}: {key} = {fmu!r}: unknown FMU"
                            + (f" (did you mean {hint[0]!r}?)" if hint else "")
                            + f"; known: {sorted(known)}")
    return built


def _split_ref(source: Path, key: str, ref: Any, components: dict[str, Component]
               ) -> tuple[str, str]:
    if not isinstance(ref, str) or "." not in ref:
        raise ScenarioError(f"{source}: {key} = {ref!r}: expected 'FMU.variable'")
    comp, var = ref.split(".", 1)
    if comp not in components:
        raise ScenarioError(f"{source}: {key} = {ref!r}: no FMU named {comp!r} "
                            f"(scenario has {sorted(components)})")
    return comp, var


def load_scenario(name_or_path: str | Path,
                  overrides: dict[str, Any] | list[str] | None = None) -> Scenario:
    """Read, override and check the structure of a scenario (variables are checked against
    the FMUs' modelDescriptions by :func:`check_against_fmus`). An error in a value given by
    an override names the ``--set`` option."""
    path = find_scenario(name_or_path)
    keys = override_keys(overrides)
    try:
        scenario = _load_scenario(path, overrides)
    except ScenarioError as err:
        raise blame_override(err, path, keys) from None
    scenario.overrides = keys
    return scenario


@functools.lru_cache(maxsize=256)
def _parsed_scenario(path: str, mtime_ns: int, size: int) -> dict[str, Any]:
    """The scenario file ``path`` parsed, once per version of it (modification time, size)
    in this process (an ensemble loads the same file for every member)."""
    return read_toml(Path(path))


def _copied(value: Any) -> Any:
    """A copy of parsed TOML ``value`` whose tables and arrays are new (the scalars are
    immutable and shared): what ``copy.deepcopy`` gives for such data, at a fraction of its
    cost."""
    if isinstance(value, dict):
        return {key: _copied(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_copied(item) for item in value]
    return value


def _load_scenario(path: Path, overrides: dict[str, Any] | list[str] | None) -> Scenario:
    stat = path.stat()
    raw = _copied(_parsed_scenario(str(path), stat.st_mtime_ns, stat.st_size))
    apply_overrides(raw, overrides, str(path))
    _refuse_unknown(path, "top level", raw, ("description", "simulation", "fmus",
                                              "connections", "record", "summary"))

    sim_raw = raw.get("simulation")
    if isinstance(sim_raw, dict):  # an unknown key first: `stoptime` is a misspelt stop_time
        _refuse_unknown(path, "[simulation]", sim_raw, ("stop_time", "start_time",
                                                        "output_interval", "algorithm",
                                                        "base_step", "fmi_version",
                                                        "unconnected_inputs"))
    if not isinstance(sim_raw, dict) or "stop_time" not in sim_raw:
        raise ScenarioError(f"{path}: [simulation] stop_time is required")
    algorithm = sim_raw.get("algorithm", "event")
    if algorithm not in ALGORITHMS:
        raise ScenarioError(f"{path}: [simulation] algorithm = {algorithm!r}: expected one of "
                            f"{list(ALGORITHMS)}")
    fmi_version = sim_raw.get("fmi_version", 2)
    if fmi_version not in FMI_VERSIONS or isinstance(fmi_version, bool):
        raise ScenarioError(f"{path}: [simulation] fmi_version = {fmi_version!r}: expected one "
                            f"of {list(FMI_VERSIONS)} (which builds of catalog FMUs to run)")
    unconnected = sim_raw.get("unconnected_inputs", "start")
    if unconnected not in UNCONNECTED_INPUTS:
        raise ScenarioError(f"{path}: [simulation] unconnected_inputs = {unconnected!r}: "
                            f"expected one of {list(UNCONNECTED_INPUTS)}")
    sim = Simulation(
        fmi_version=int(fmi_version),
        unconnected_inputs=unconnected,
        stop_time=_time(path, "[simulation] stop_time", sim_raw["stop_time"]),
        start_time=_time(path, "[simulation] start_time", sim_raw.get("start_time", 0.0),
                           positive=False),
        output_interval=_time(path, "[simulation] output_interval",
                                sim_raw.get("output_interval", 0.1)),
        algorithm=algorithm,
        base_step=(_time(path, "[simulation] base_step", sim_raw["base_step"])
                   if "base_step" in sim_raw else None),
    )
    if sim.stop_time <= sim.start_time:
        raise ScenarioError(f"{path}: [simulation] stop_time = {sim.stop_time} must be after "
                            f"start_time = {sim.start_time}")

    fmus_raw = raw.get("fmus")
    if not isinstance(fmus_raw, dict) or not fmus_raw:
        raise ScenarioError(f"{path}: [fmus] must name at least one FMU")
    components: dict[str, Component] = {}
    for name, spec in fmus_raw.items():
        key = f"[fmus.{name}]"
        if not isinstance(spec, dict):
            raise ScenarioError(f"{path}: {key} must be a table")
        _refuse_unknown(path, key, spec, (*COMPONENT_KEYS, "parameters", "inputs"))
        if "fmu" not in spec:
            raise ScenarioError(f"{path}: {key} fmu is required")
        for table in ("parameters", "inputs"):
            if not isinstance(spec.get(table, {}), dict):
                raise ScenarioError(f"{path}: [fmus.{name}.{table}] must be a table")
        components[name] = Component(
            name=name,
            fmu=spec["fmu"],
            fmu_path=_resolve_fmu(path, f"{key} fmu", spec["fmu"], sim.fmi_version,
                                  spec.get("build", "python")),
            build=spec.get("build", "python"),
            sample_time=(_time(path, f"{key} sample_time", spec["sample_time"])
                         if "sample_time" in spec else None),
            max_step=(_time(path, f"{key} max_step", spec["max_step"])
                      if "max_step" in spec else None),
            parameters=dict(spec.get("parameters", {})),
            inputs=dict(spec.get("inputs", {})),
        )

    connections: list[Connection] = []
    conn_raw = raw.get("connections", {})
    if not isinstance(conn_raw, dict):
        raise ScenarioError(f"{path}: [connections] must be a table of \"dst.input\" = "
                            f"\"src.output\"")
    for dst_ref, src_ref in conn_raw.items():
        key = f"[connections] {dst_ref!r}"
        dst, dst_var = _split_ref(path, key, dst_ref, components)
        src, src_var = _split_ref(path, key, src_ref, components)
        connections.append(Connection(src, src_var, dst, dst_var))

    for table, known in (("record", RECORD_KEYS), ("summary", SUMMARY_KEYS)):
        value = raw.get(table, {})
        if not isinstance(value, dict):
            raise ScenarioError(f"{path}: [{table}] must be a table")
        if table == "summary":
            known = (*known, *_paper_metric_keys(path, value))
        _refuse_unknown(path, f"[{table}]", value, tuple(known))
    record = raw.get("record", {}).get("variables")
    if record is not None:
        if not isinstance(record, list) or not all(isinstance(r, str) for r in record):
            raise ScenarioError(f"{path}: [record] variables must be a list of 'FMU.variable'")
        for ref in record:
            _split_ref(path, "[record] variables", ref, components)

    summary = raw.get("summary", {})
    if not isinstance(summary, dict):
        raise ScenarioError(f"{path}: [summary] must be a table")
    summary = resolve_parameter_refs(path, summary, components)
    return Scenario(path=path, name=path.stem, description=str(raw.get("description", "")),
                    simulation=sim, components=components, connections=connections,
                    record=record, summary=summary, raw=raw)


def check_against_fmus(scenario: Scenario, descriptions: dict[str, Any],
                       ranges: bool = True) -> None:
    """Check names, causalities, types and units of everything the scenario refers to, and
    (``ranges``) that values lie within the variables' [min, max].

    ``descriptions`` maps component name to its fmpy ``ModelDescription``.
    """
    src = scenario.path
    variables = {name: {v.name: v for v in md.modelVariables}
                 for name, md in descriptions.items()}

    def lookup(comp: str, var: str, key: str, causalities: tuple[str, ...]) -> Any:
        vars_ = variables[comp]
        if var not in vars_:
            hint = difflib.get_close_matches(var, list(vars_), n=1)
            raise ScenarioError(
                f"{src}: {key}: {comp} ({scenario.components[comp].fmu}) has no variable "
                f"{var!r}" + (f" (did you mean {hint[0]!r}?)" if hint else ""))
        v = vars_[var]
        if v.causality not in causalities:
            raise ScenarioError(f"{src}: {key}: {comp}.{var} is a {v.causality}, expected "
                                f"{' or '.join(causalities)}")
        return v

    def check_value(comp: str, var: str, key: str, value: Any, v: Any) -> None:
        why = fmi_types.check_value(v, value, ranges)
        if why is not None:
            raise ScenarioError(f"{src}: {key}: {comp}.{var} {why}")

    for name, comp in scenario.components.items():
        for par, value in comp.parameters.items():
            key = f"[fmus.{name}.parameters] {par}"
            check_value(name, par, key, value, lookup(name, par, key, ("parameter",)))
        for inp, value in comp.inputs.items():
            key = f"[fmus.{name}.inputs] {inp}"
            check_value(name, inp, key, value, lookup(name, inp, key, ("input",)))
        if comp.sample_time is not None and "sample_time" in variables[name]:
            if "sample_time" in comp.parameters and \
                    comp.parameters["sample_time"] != comp.sample_time:
                raise ScenarioError(f"{src}: [fmus.{name}] sample_time = {comp.sample_time} "
                                    f"disagrees with parameters.sample_time = "
                                    f"{comp.parameters['sample_time']}")

    connected: dict[tuple[str, str], Connection] = {}
    for c in scenario.connections:
        key = f"[connections] \"{c.dst}.{c.dst_var}\""
        dv = lookup(c.dst, c.dst_var, key, ("input",))
        sv = lookup(c.src, c.src_var, key, ("output",))
        if not fmi_types.same_type(sv.type, dv.type):
            raise ScenarioError(f"{src}: {key}: type mismatch: {c.src}.{c.src_var} is "
                                f"{sv.type}, {c.dst}.{c.dst_var} is {dv.type}")
        src_items, dst_items = (fmi_types.enumeration_items(sv),
                                fmi_types.enumeration_items(dv))
        if src_items and dst_items and src_items != dst_items:
            raise ScenarioError(f"{src}: {key}: Enumeration items differ: {c.src}.{c.src_var} "
                                f"has {src_items}, {c.dst}.{c.dst_var} has {dst_items}")
        if (dv.unit or "") != (sv.unit or "") and dv.unit and sv.unit:
            raise ScenarioError(f"{src}: {key}: unit mismatch: {c.src}.{c.src_var} in "
                                f"{sv.unit}, {c.dst}.{c.dst_var} in {dv.unit}")
        if c.dst_var in scenario.components[c.dst].inputs:
            raise ScenarioError(f"{src}: {key}: input is both connected and given a constant "
                                f"in [fmus.{c.dst}.inputs]")
        connected[(c.dst, c.dst_var)] = c
    strict = scenario.simulation.unconnected_inputs == "error"
    for name, v in unconnected_inputs(scenario, descriptions):
        if strict or v.start is None:
            why = ("[simulation] unconnected_inputs = \"error\"" if v.start is not None
                   else "it declares no start value")
            raise ScenarioError(
                f"{src}: input {name}.{v.name} is not connected ({why}): add "
                f"\"{name}.{v.name}\" = \"FMU.output\" to [connections] or a constant in "
                f"[fmus.{name}.inputs]")

    def check_ref(ref: str, key: str) -> None:
        comp, var = ref.split(".", 1)
        if "*" in var:  # a glob must match at least one variable
            pattern = re.compile(re.escape(var).replace(r"\*", ".*") + "$")
            if not any(pattern.match(n) for n in variables[comp]):
                raise ScenarioError(f"{src}: {key}: {ref!r} matches no variable of {comp}")
            return
        lookup(comp, var, key, ("output", "input", "parameter", "local"))

    for ref in scenario.record or []:
        check_ref(ref, "[record] variables")
    for key, value in scenario.summary.items():
        for ref in value if isinstance(value, list) else [value]:
            if isinstance(ref, str) and "." in ref and ref.split(".", 1)[0] in variables:
                check_ref(ref, f"[summary] {key}")


def unconnected_inputs(scenario: Scenario, descriptions: dict[str, Any]
                       ) -> list[tuple[str, Any]]:
    """(component, fmpy variable) of every input neither connected nor given a value in
    [fmus.NAME.inputs]: it keeps its declared start value (FMI 3.0 sec. 2.4.7.5: an input not
    set uses its start value; FMI 2.0.4 sec. 2.2.7 likewise)."""
    connected = {(c.dst, c.dst_var) for c in scenario.connections}
    return [(name, v) for name, md in descriptions.items() for v in md.modelVariables
            if v.causality == "input" and (name, v.name) not in connected
            and v.name not in scenario.components[name].inputs]


def check_timing(scenario: Scenario, descriptions: dict[str, Any], algorithm: str) -> None:
    """Fixed-step algorithms (``fixed``, ``jacobi``; also libcosim running an SSP export) only
    exchange values every ``base_step``: the output points and every sampled FMU's sample
    instants must be communication points, so ``output_interval`` and each ``sample_time``
    must be multiples of ``base_step`` (a longer base step would skip controller events, which
    our controllers refuse; a misaligned output grid would be recorded elsewhere)."""
    if algorithm not in ("fixed", "jacobi"):
        return
    src, sim = scenario.path, scenario.simulation
    base = sim.base_step if sim.base_step is not None else sim.output_interval
    base_ticks = to_ticks(base)
    if to_ticks(sim.output_interval) % base_ticks:
        raise ScenarioError(
            f"{src}: [simulation] output_interval = {sim.output_interval} s is not a multiple "
            f"of base_step = {base} s: with algorithm {algorithm!r} values exist only at the "
            f"communication points (every {base} s); make output_interval a multiple of "
            "base_step")
    for name, comp in scenario.components.items():
        variables = {v.name: v for v in descriptions[name].modelVariables}
        sample = comp.sample_time if comp.sample_time is not None else \
            comp.parameters.get("sample_time")
        var = variables.get("sample_time")
        if sample is None and var is not None and var.causality == "parameter" and var.start:
            sample = float(var.start)
        if sample is None or not isinstance(sample, (int, float)) or sample <= 0:
            continue
        if to_ticks(float(sample)) % base_ticks:
            raise ScenarioError(
                f"{src}: [fmus.{name}] sample_time = {sample} s is not a multiple of "
                f"[simulation] base_step = {base} s: with algorithm {algorithm!r} its events "
                "would fall inside communication steps (a base step longer than the sample "
                "time would skip events); choose a base_step that divides every sample_time")
