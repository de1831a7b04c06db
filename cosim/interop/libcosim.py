"""Run our FMUs under other masters: libcosim (fixed step, directly or from an SSP) and fmpy.

libcosim (``libcosimpy``) is the Open Simulation Platform's C++ master. Its fixed-step
algorithm (``fixed_step_algorithm.cpp``, ``slave_simulator.cpp``; confirmed by experiment with
libcosimpy 0.0.6) does, for every FMU:

* initialisation: start values/parameters set in the instantiated state, ``setupExperiment``,
  ``enterInitializationMode``; then N rounds (N = number of FMUs) of "set inputs, read
  outputs" for every FMU followed by a transfer of every connection; then for every FMU "set
  inputs, ``exitInitializationMode``, read outputs", and one more transfer;
* each step: for every FMU "set inputs, ``doStep(t, h)``, read outputs" (in parallel threads),
  then every connection is transferred (cached output -> input of the next step).

So outputs are read right after ``doStep``, before any input changes: a sampled controller of
ours computes its event at t+h from the measurement of t and the plant receives it for the step
starting at t+h (one step later than our event/fixed masters; our master's ``jacobi`` mode
reproduces this exactly). Values are recorded with a last-value observer after each step; the
first row is t = h (libcosim initialises inside its first ``step``).

libcosim ignores FMI 2.0 Enumeration variables (it logs "FMI 2.0 Enumeration variable type not
supported, variable with name ... will be ignored") and aborts its process on an SSP
``ssc:Enumeration`` connector ("Don't know how to handle Enumeration type!"); an Integer connector
or parameter in their place finds no variable. So a scenario or SSP that sets or connects an
Enumeration is refused before libcosim starts (:func:`enumerations_used`,
:func:`ssp_enumerations`), naming each such variable.

``simulate_single`` runs one FMU under ``fmpy.simulate_fmu`` with inputs recorded from one of
our runs (sample-and-hold, as the master delivered them).
"""

from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cosim.fmu.state import to_seconds, to_ticks
from cosim.run.scenario import Scenario, check_against_fmus, load_scenario


class LibcosimError(RuntimeError):
    """libcosim refused a call; the message names it and includes libcosim's last error."""


def _lc():
    """Import libcosimpy quietly (it is a binary wheel, optional for the rest of the package)."""
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    from libcosimpy import CosimEnums, CosimExecution, CosimObserver, CosimSlave

    return CosimExecution, CosimSlave, CosimObserver, CosimEnums


ENUMERATION_REASON = ("libcosim ignores FMI 2.0 Enumeration variables (and aborts on an SSP "
                      "Enumeration connector), so it cannot set, connect or record them")


def enumerations_used(sc: Scenario, descriptions: dict[str, Any]) -> list[str]:
    """``component.variable`` of every FMI 2.0 Enumeration variable the scenario sets
    (parameter, ``sample_time`` or constant input) or connects; ``descriptions``: component ->
    its fmpy model description."""
    used = []
    for comp in sc.components.values():
        named = set(comp.parameters) | set(comp.inputs)
        named |= {c.src_var for c in sc.connections if c.src == comp.name}
        named |= {c.dst_var for c in sc.connections if c.dst == comp.name}
        used += [f"{comp.name}.{v.name}" for v in descriptions[comp.name].modelVariables
                 if v.type == "Enumeration" and v.name in named]
    return sorted(used)


def ssp_enumerations(ssp_path: str | Path) -> list[str]:
    """``component.connector`` of every Enumeration connector or parameter value in the SSP's
    ``SystemStructure.ssd``."""
    import zipfile
    from xml.etree.ElementTree import fromstring

    with zipfile.ZipFile(ssp_path) as z:
        root = fromstring(z.read("SystemStructure.ssd"))
    found = []
    for comp in root.iter():
        if not comp.tag.endswith("}Component"):
            continue
        for node in comp.iter():
            if node.tag.endswith(("}Connector", "}Parameter")) and any(
                    child.tag.endswith("}Enumeration") for child in node):
                found.append(f"{comp.get('name')}.{node.get('name')}")
    return sorted(set(found))


def _refuse_enumerations(where: str, names: list[str]) -> None:
    if names:
        raise LibcosimError(f"{where}: {', '.join(names)} "
                            f"{'is an Enumeration' if len(names) == 1 else 'are Enumerations'}; "
                            f"{ENUMERATION_REASON}: run it with `cosim run` (our master), or "
                            f"leave these variables out")


def _last_error() -> str:
    try:
        from libcosimpy._internal import get_last_error_message

        return str(get_last_error_message())
    except Exception:  # pragma: no cover - diagnostics only
        return ""


@dataclass
class _Var:
    slave: int
    ref: int
    type: int  # CosimVariableType value
    name: str


class _Slaves:
    """Variables of the slaves of one execution, by ``component.variable``."""

    def __init__(self, execution: Any, names: list[str]) -> None:
        self.execution = execution
        self.index: dict[str, int] = {}
        self.vars: dict[str, dict[str, _Var]] = {}
        for info in execution.slave_infos():
            name = info.name.decode()
            self.index[name] = info.index
        for name in names:
            idx = self.index[name]
            self.vars[name] = {d.name.decode(): _Var(idx, d.reference, d.type, d.name.decode())
                               for d in execution.slave_variables(idx)}

    def get(self, ref: str) -> _Var:
        comp, var = ref.split(".", 1)
        try:
            return self.vars[comp][var]
        except KeyError:
            raise LibcosimError(f"{ref}: no such variable under libcosim") from None

    def expand(self, ref: str) -> list[str]:
        comp, var = ref.split(".", 1)
        if "*" not in var:
            return [ref]
        return [f"{comp}.{n}" for n in self.vars[comp] if fnmatch(n, var)]


def _set_initial(execution: Any, var: _Var, value: Any, enums: Any) -> None:
    kind = enums.CosimVariableType(var.type)
    setter = {
        enums.CosimVariableType.REAL: (execution.real_initial_value, float),
        enums.CosimVariableType.INTEGER: (execution.integer_initial_value, int),
        enums.CosimVariableType.BOOLEAN: (execution.boolean_initial_value, bool),
        enums.CosimVariableType.STRING: (execution.string_initial_value, str),
    }[kind]
    if not setter[0](var.slave, var.ref, setter[1](value)):
        raise LibcosimError(f"initial value {var.name} = {value!r} refused: {_last_error()}")


def _connect(execution: Any, src: _Var, dst: _Var, enums: Any) -> None:
    if src.type != dst.type:
        raise LibcosimError(f"cannot connect {src.name} to {dst.name}: types differ")
    connect = {
        enums.CosimVariableType.REAL: execution.connect_real_variables,
        enums.CosimVariableType.INTEGER: execution.connect_integer_variables,
        enums.CosimVariableType.BOOLEAN: execution.connect_boolean_variables,
        enums.CosimVariableType.STRING: execution.connect_string_variables,
    }[enums.CosimVariableType(src.type)]
    if connect(src.slave, src.ref, dst.slave, dst.ref) != 0:  # returns libcosimc's status
        raise LibcosimError(f"connection {src.name} -> {dst.name} refused: {_last_error()}")


def _record(execution: Any, slaves: _Slaves, refs: list[str], stop_ticks: int,
            step_ticks: int) -> pd.DataFrame:
    """Step to ``stop_ticks`` one base step at a time, reading ``refs`` after every step."""
    _, _, CosimObserver, enums = _lc()
    observer = CosimObserver.CosimObserver.create_last_value()
    execution.add_observer(observer)
    wanted = [slaves.get(r) for r in refs]
    groups: dict[tuple[int, int], list[int]] = {}
    for i, v in enumerate(wanted):
        groups.setdefault((v.slave, v.type), []).append(i)
    readers = {
        enums.CosimVariableType.REAL.value: observer.last_real_values,
        enums.CosimVariableType.INTEGER.value: observer.last_integer_values,
        enums.CosimVariableType.BOOLEAN.value: observer.last_boolean_values,
    }
    n = int(round(stop_ticks / step_ticks))
    rows = np.full((n, len(refs) + 1), np.nan)
    for k in range(n):
        if not execution.step(1):
            raise LibcosimError(f"step {k + 1} failed: {_last_error()}")
        rows[k, 0] = to_seconds((k + 1) * step_ticks)
        for (slave, kind), idx in groups.items():
            if kind not in readers:
                continue  # strings are not recorded
            values = readers[kind](slave, [wanted[i].ref for i in idx])
            rows[k, [i + 1 for i in idx]] = values
    return pd.DataFrame(rows, columns=["time", *refs])


def _record_refs(sc: Scenario, slaves: _Slaves, record: list[str] | None) -> list[str]:
    refs = record if record is not None else (sc.record or [])
    if not refs:
        refs = [f"{c.src}.{c.src_var}" for c in sc.connections]
    out: list[str] = []
    for r in refs:
        out += [e for e in slaves.expand(r) if e not in out]
    return out


def _isolated(function: str, *args: Any) -> pd.DataFrame:
    """Call ``function`` of this module in a child Python process and return its frame.

    libcosim aborts its process on some refusals (an FMU rejecting a start value at
    initialisation, an SSP Enumeration connector: "Don't know how to handle Enumeration
    type!"), which no Python exception can catch. In a child the abort ends only the child;
    the error raised here carries what libcosim and the FMU wrote to the child's stderr."""
    import os
    import pickle
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory(prefix="ato-libcosim-") as tmp:
        request, reply = Path(tmp) / "request.pkl", Path(tmp) / "reply.pkl"
        request.write_bytes(pickle.dumps((function, args)))
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        proc = subprocess.run([sys.executable, "-m", "cosim.interop.libcosim", str(request),
                               str(reply)], env=env, capture_output=True, text=True)
        if reply.is_file():
            ok, value = pickle.loads(reply.read_bytes())
            if ok:
                return value
            raise LibcosimError(value)
        tail = "\n".join(proc.stderr.strip().splitlines()[-12:])
        raise LibcosimError(f"libcosim ended its process (exit status {proc.returncode}) in "
                            f"{function.removeprefix('_')}"
                            + (f"; it reported:\n{tail}" if tail else ""))


def _child(request: str, reply: str) -> None:
    """The child of :func:`_isolated`: run the request, pickle ``(ok, frame or message)``."""
    import pickle

    function, args = pickle.loads(Path(request).read_bytes())
    try:
        result = (True, globals()[function](*args))
    except Exception as err:  # reported to the parent as a LibcosimError
        result = (False, str(err) if isinstance(err, LibcosimError)
                  else f"{type(err).__name__}: {err}")
    Path(reply).write_bytes(pickle.dumps(result))


def run_libcosim(scenario: str | Path | Scenario, overrides: dict[str, Any] | None = None,
                 step: float | None = None, record: list[str] | None = None,
                 isolated: bool = True) -> pd.DataFrame:
    """Run a scenario's FMUs under libcosim's fixed-step master (base step: ``step``, else the
    scenario's ``base_step``, else its ``output_interval``). Returns a frame with ``time`` (s,
    from h to stop_time) and the recorded ``component.variable`` columns.

    ``isolated`` (the default): libcosim runs in a child process (:func:`_isolated`), so its
    aborts become a :class:`LibcosimError`. ``isolated=False`` runs libcosim in this process
    and gives the same frame without the child's start-up (a new interpreter importing
    cosim and every FMU's Python again): for a caller that accepts that libcosim aborting
    (on an FMU refusing a start value at initialisation, say) ends this process, as no
    Python exception can catch it; its other errors are raised here as they are (a
    :class:`LibcosimError`, or the exception of the failing call)."""
    from fmpy import read_model_description

    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario, overrides)
    # what cosim run refuses (names, types, ranges) is refused here too, naming the key
    descriptions = {c.name: read_model_description(str(c.fmu_path))
                    for c in sc.components.values()}
    check_against_fmus(sc, descriptions)
    _refuse_enumerations(str(sc.path), enumerations_used(sc, descriptions))
    if not isolated:
        return _run_libcosim(sc, step, record)
    return _isolated("_run_libcosim", sc, step, record)


def _run_libcosim(sc: Scenario, step: float | None, record: list[str] | None) -> pd.DataFrame:
    CosimExecution, CosimSlave, _, enums = _lc()
    sim = sc.simulation
    if sim.start_time != 0.0:
        raise LibcosimError("libcosim runs start at t = 0 here")
    h = step or sim.base_step or sim.output_interval
    step_ticks = to_ticks(h)
    execution = CosimExecution.CosimExecution.from_step_size(step_ticks)
    for comp in sc.components.values():
        slave = CosimSlave.CosimLocalSlave(fmu_path=str(comp.fmu_path), instance_name=comp.name)
        if execution.add_local_slave(slave) < 0:
            raise LibcosimError(f"cannot load {comp.fmu_path}: {_last_error()}")
    slaves = _Slaves(execution, list(sc.components))
    for comp in sc.components.values():
        params = dict(comp.parameters)
        if comp.sample_time is not None and "sample_time" in slaves.vars[comp.name]:
            params.setdefault("sample_time", comp.sample_time)
        for name, value in {**params, **comp.inputs}.items():
            _set_initial(execution, slaves.get(f"{comp.name}.{name}"), value, enums)
    for c in sc.connections:
        _connect(execution, slaves.get(f"{c.src}.{c.src_var}"),
                 slaves.get(f"{c.dst}.{c.dst_var}"), enums)
    refs = _record_refs(sc, slaves, record)
    return _record(execution, slaves, refs, to_ticks(sim.stop_time), step_ticks)


def run_ssp(ssp_path: str | Path, record: list[str], stop_time: float,
            step: float, isolated: bool = True) -> pd.DataFrame:
    """Run an SSP (e.g. from ``cosim export --ssp``) with libcosim's fixed-step master; an
    SSP with an Enumeration connector or parameter is refused before libcosim starts
    (:data:`ENUMERATION_REASON`). ``isolated`` as for :func:`run_libcosim`: by default in a
    child process, so libcosim's aborts become a :class:`LibcosimError`; ``isolated=False``
    runs it in this process, the same frame, and an abort of libcosim ends this process."""
    _refuse_enumerations(str(ssp_path), ssp_enumerations(ssp_path))
    args = (str(ssp_path), list(record), float(stop_time), float(step))
    if not isolated:
        return _run_ssp(*args)
    return _isolated("_run_ssp", *args)


def _run_ssp(ssp_path: str, record: list[str], stop_time: float, step: float) -> pd.DataFrame:
    CosimExecution, _, _, _ = _lc()
    step_ticks = to_ticks(step)
    execution = CosimExecution.CosimExecution.from_ssp_file(str(ssp_path), step_ticks)
    names = [i.name.decode() for i in execution.slave_infos()]
    slaves = _Slaves(execution, names)
    refs: list[str] = []
    for r in record:
        refs += [e for e in slaves.expand(r) if e not in refs]
    return _record(execution, slaves, refs, to_ticks(stop_time), step_ticks)


def compare_frames(ours: pd.DataFrame, theirs: pd.DataFrame,
                   columns: list[str] | None = None) -> dict[str, float]:
    """Largest absolute difference per column at the times both frames share."""
    a = ours.assign(_tick=[to_ticks(t) for t in ours["time"]]).set_index("_tick")
    b = theirs.assign(_tick=[to_ticks(t) for t in theirs["time"]]).set_index("_tick")
    common = a.index.intersection(b.index)
    if len(common) == 0:
        raise ValueError("the frames share no time point")
    cols = columns or [c for c in b.columns if c in a.columns and c not in ("time",)]
    return {c: float(np.nanmax(np.abs(a.loc[common, c].to_numpy(float)
                                      - b.loc[common, c].to_numpy(float)))) for c in cols}


def simulate_single(fmu_path: str | Path, frame: pd.DataFrame, inputs: dict[str, str],
                    parameters: dict[str, Any] | None = None, step: float | None = None,
                    outputs: list[str] | None = None) -> pd.DataFrame:
    """One FMU under ``fmpy.simulate_fmu``, its inputs replayed from a recorded frame.

    ``inputs`` maps the FMU's input names to frame columns. The recorded value at t_k is held
    over [t_k, t_k+1) (as our master delivered it): the signal repeats each time point, the
    held value just before it and the new one at it, which fmpy applies as a step.
    """
    from fmpy import simulate_fmu

    times = frame["time"].to_numpy(float)
    h = step or float(np.min(np.diff(times)))
    names = list(inputs)
    dtype = [("time", np.float64)] + [(n, np.float64) for n in names]
    rows = []
    for k, t in enumerate(times):
        now = [float(frame[inputs[n]].iloc[k]) for n in names]
        if k > 0:
            rows.append((t, *[float(frame[inputs[n]].iloc[k - 1]) for n in names]))
        rows.append((t, *now))
    signal = np.array(rows, dtype=dtype)
    result = simulate_fmu(str(fmu_path), start_time=float(times[0]), stop_time=float(times[-1]),
                          step_size=h, output_interval=h, start_values=parameters or {},
                          input=signal, output=outputs, fmi_type="CoSimulation")
    return pd.DataFrame({name: result[name] for name in result.dtype.names})


if __name__ == "__main__":  # the child of _isolated
    import sys

    _child(sys.argv[1], sys.argv[2])
