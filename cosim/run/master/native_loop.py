"""The event-driven algorithm's communication points in C, for FMUs called through their C
functions (``native_loop.c``; compiled once per machine into the user cache).

:class:`cosim.run.master.algorithms.EventDriven` runs its loop here when every FMU is an FMI
2.0 co-simulation instance whose functions the master calls directly (native builds,
third-party binaries and the Python builds' C entry points alike), every connection moves a
Real, Integer or Boolean to a variable of the same C type, and every recorded variable is one
of those: the C loop makes the same FMI calls with the same arguments in the same order as the
Python loop, so the results are the same bit for bit, at about a tenth of the cost per
communication point (the master then reaches more than half of a bare C loop's speed on the
native EMU; ``benchmarks/bench_c_limit.py``). What the Python loop does besides (a refused or
failed step, a failed get or set, a bad announced event, the first use of a set of due FMUs,
a full recording, progress at every hundredth of the run where a progress display is given,
Ctrl-C every :data:`BUDGET` seconds) goes back to Python with the loop's state, which goes on
from there.

``ATO_COSIM_NATIVE_LOOP=off`` keeps the Python loop (as does a machine without a C compiler
and without the compiled loop in its cache).
"""

from __future__ import annotations

import atexit
import ctypes
import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cosim.build.native import CC_FLAGS, LINUX_CC
from cosim.fmu.disk_cache import cache_root
from cosim.run import exchange, isolation
from cosim.run.master.errors import SimulationError
from cosim.run.master.fmi2 import Fmi2Unit

if TYPE_CHECKING:
    from cosim.run.master.core import Link, Master

ENV = "ATO_COSIM_NATIVE_LOOP"  # "off": the Python loop
SOURCE = Path(__file__).with_suffix(".c")
BUDGET = 0.05  # s of wall time in C between progress reports (and Ctrl-C checks), at most
REPORTS = 100  # progress reports over the run with a progress display (one per hundredth)
HISTORY = 4096  # values of a kept connection history per return to Python
MAX_UNITS = 64  # the due FMUs are one bit each in a 64-bit mask
FAMILIES = ("Real", "Integer", "Boolean")  # the C loop's value types (double, int, int)
LOG = logging.getLogger(__name__)

OP_GET, OP_SET, OP_COPY, OP_TRACK, OP_ROW = range(5)
NOT_SCHEDULED, SAMPLED, ANNOUNCED = range(3)
DONE, YIELD, NEED_PLAN, NEED_ROWS, CALL_FAILED, BAD_EVENT, STEP_FAILED = range(7)
_i32, _i64, _u64, _p, _d = (ctypes.c_int32, ctypes.c_int64, ctypes.c_uint64, ctypes.c_void_p,
                            ctypes.c_double)


class COp(ctypes.Structure):
    _fields_ = [("kind", _i32), ("is_int", _i32), ("unit", _i32), ("n", _i32),
                ("offset", _i64), ("fn", _p), ("component", _p), ("vrs", _p), ("buf", _p),
                ("src", _p)]


class CPlan(ctypes.Structure):
    _fields_ = [("due", _u64), ("n_ops", _i64), ("ops", ctypes.POINTER(COp))]


class CUnit(ctypes.Structure):
    _fields_ = [("component", _p), ("do_step", _p), ("get_real", _p), ("time", _i64),
                ("sample", _i64), ("max_step", _i64), ("next_event", _i64),
                ("do_steps", _i64), ("wall", _d), ("scheduled", _i32),
                ("next_event_column", _i32), ("next_event_vr", ctypes.c_uint32),
                ("crumb_index", _i32)]


class CLink(ctypes.Structure):
    _fields_ = [("last", _d), ("has_last", _i64), ("changes", _i64),
                ("history", ctypes.POINTER(_d)), ("n_history", _i64), ("capacity", _i64)]


class CLoop(ctypes.Structure):
    _fields_ = [("n_units", _i64), ("units", ctypes.POINTER(CUnit)),
                ("n_plans", _i64), ("plans", ctypes.POINTER(CPlan)),
                ("n_record", _i64), ("record", ctypes.POINTER(COp)),
                ("n_links", _i64), ("links", ctypes.POINTER(CLink)),
                ("t", _i64), ("due", _u64), ("stop", _i64), ("next_output", _i64),
                ("output", _i64), ("store", ctypes.POINTER(_d)), ("width", _i64),
                ("rows", _i64), ("capacity", _i64), ("crumb", ctypes.POINTER(_d)),
                ("budget", _d), ("report_at", _i64), ("failed_unit", _i64), ("failed_op", _i64),
                ("failed_plan", _i64), ("status", _i64), ("step_t", _i64),
                ("step_h", _i64), ("t_next", _i64), ("due_next", _u64), ("value", _d)]


_LIBRARY: list[Any] = []  # [the loaded library or None], once per process


def _compile(out: Path) -> None:
    """``native_loop.c`` into the shared library ``out`` (written beside it, then renamed, so
    a concurrent process never loads a partial file)."""
    cc = shutil.which(LINUX_CC)
    if cc is None:
        raise FileNotFoundError(f"no C compiler {LINUX_CC!r} on PATH")
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=out.parent, suffix=".so.tmp")
    os.close(fd)
    try:
        done = subprocess.run([cc, "-shared", "-fPIC", *CC_FLAGS, "-o", tmp, str(SOURCE),
                               "-lm"], capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{cc} failed on {SOURCE}:\n{done.stderr.strip()[-2000:]}")
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _own_folder() -> Path:
    """A temporary folder of this process, removed when it exits."""
    folder = Path(tempfile.mkdtemp(prefix="ato-cosim-loop-"))
    atexit.register(shutil.rmtree, folder, True)
    return folder


def library() -> Any:
    """The compiled loop (``ctypes.CDLL``), built on first use into ``<cache>/native_loop/``
    (:func:`cosim.fmu.disk_cache.cache_root`; with ``ATO_COSIM_CACHE=off`` a temporary folder
    of this process) under the digest of its source and flags; None where it cannot be built
    (said once in the log)."""
    if _LIBRARY:
        return _LIBRARY[0]
    key = hashlib.sha256(SOURCE.read_bytes() + " ".join(CC_FLAGS).encode()).hexdigest()[:24]
    base = cache_root()  # None: ATO_COSIM_CACHE=off, compiled for this process only
    name = f"native_loop-{key}.so"
    path = base / "native_loop" / name if base is not None else _own_folder() / name
    lib = None
    try:
        if not path.is_file():
            try:
                _compile(path)
            except OSError:  # an unwritable cache: a folder of this process's own
                path = _own_folder() / name
                _compile(path)
        lib = ctypes.CDLL(str(path))
        lib.native_loop_run.argtypes = [ctypes.POINTER(CLoop)]
        lib.native_loop_run.restype = ctypes.c_int
    except (OSError, RuntimeError) as err:
        LOG.info("the event-driven loop runs in Python (the C loop is unavailable: %s)", err)
        lib = None
    _LIBRARY.append(lib)
    return lib


def _address(obj: Any) -> int:
    return ctypes.cast(obj, ctypes.c_void_p).value or 0


def why_not(m: Master) -> str | None:
    """Why ``m``'s run cannot take the C loop (None: it can)."""
    if os.environ.get(ENV, "").lower() == "off":
        return f"{ENV}=off"
    if len(m.units) > MAX_UNITS:
        return f"more than {MAX_UNITS} FMUs"
    for u in m.units:
        raw = u.raw_slave()
        if type(u) is not Fmi2Unit or not (hasattr(raw, "dll") and hasattr(raw, "component")):
            return f"{u.name} is not an FMI 2.0 instance called through its C functions"
        if u.has_next_event_output and u.vars["next_event_time"].family != "Real":
            return f"{u.name}.next_event_time is not a Real"
    for lk in m.links:
        src, dst = lk.src.vars[lk.src_name].family, lk.dst.vars[lk.dst_name].family
        if src not in FAMILIES or dst not in FAMILIES or (src == "Real") != (dst == "Real"):
            return f"connection {lk.conn.src}.{lk.src_name} -> {lk.conn.dst}.{lk.dst_name}"
    for batch, target, _extra, _unit in m.recorder.reads():
        if not batch.fast or not isinstance(target, (int, slice)):
            return f"recorded {batch.family} variables of {batch.unit.name}"
    return None if library() is not None else "no compiled loop"


class NativeLoop:
    """The C loop over ``m``'s units (:func:`why_not` is None): :meth:`run` takes over from
    :class:`EventDriven`'s loop after its fixed grids are set."""

    def __init__(self, m: Master) -> None:
        self.m = m
        self.lib = library()
        self.units = m.units
        self.index = {u: k for k, u in enumerate(self.units)}
        self.links = m.links
        self.link_index = {id(lk): i for i, lk in enumerate(self.links)}
        self.keep: list[Any] = []  # ctypes objects the C side points into
        self.plans: list[tuple[CPlan, list[Any]]] = []  # with each op's batch (or None)
        s = self.state = CLoop()
        s.n_units = len(self.units)
        self.c_units = (CUnit * len(self.units))()
        s.units = self.c_units
        for k, u in enumerate(self.units):
            raw = u.raw_slave()
            c = self.c_units[k]
            c.component = _address(raw.component)
            c.do_step = _address(raw.dll.fmi2DoStep)
            c.get_real = _address(raw.dll.fmi2GetReal)
            c.max_step = u.max_step_ticks or 0
            c.crumb_index = getattr(u, "crumb_index", -1)
            c.next_event_column = -1
            if u.has_next_event_output:
                c.scheduled = ANNOUNCED
                c.next_event_vr = u.vars["next_event_time"].vr
            elif u.sample_ticks is not None:
                c.scheduled, c.sample = SAMPLED, u.sample_ticks
        self.c_links = (CLink * max(len(self.links), 1))()
        s.links, s.n_links = self.c_links, len(self.links)
        self.histories: list[Any] = []
        for i, lk in enumerate(self.links):
            c = self.c_links[i]
            c.has_last = lk.last is not None
            c.last = float(lk.last) if lk.last is not None else 0.0
            c.changes = lk.changes
            if lk.history is not None:
                buf = (_d * HISTORY)()
                self.histories.append(buf)
                c.history = ctypes.cast(buf, ctypes.POINTER(_d))
                c.capacity = HISTORY
        self.bind_recorder()
        s.stop, s.output = m.stop_ticks, m.output_ticks
        s.budget = BUDGET
        crumb = isolation._crumb
        s.crumb = ctypes.cast(crumb, ctypes.POINTER(_d)) if crumb is not None else None

    # -- what the C side points into ---------------------------------------------------------
    def bind_recorder(self) -> None:
        """The recorder's reads as ROW ops into its store (again after the store grows)."""
        rec = self.m.recorder
        reads = self.m.recorder.reads()
        ops = (COp * max(len(reads), 1))()
        for i, (batch, target, extra, unit) in enumerate(reads):
            op = ops[i]
            self._call_op(op, OP_ROW, batch)
            op.offset = target if isinstance(target, int) else target.start
            if extra >= 0:
                self.c_units[self.index[unit]].next_event_column = extra
        self.record_ops, self.record_batches = ops, [r[0] for r in reads]
        s = self.state
        s.record, s.n_record = ops, len(reads)
        store = rec._store
        s.store = store.ctypes.data_as(ctypes.POINTER(_d))
        s.width, s.capacity = store.shape[1], store.shape[0]

    def _call_op(self, op: COp, kind: int, batch: Any) -> None:
        op.kind, op.unit, op.n = kind, self.index[batch.unit], batch.n
        op.is_int = batch.ctype is not ctypes.c_double
        op.fn, op.component = _address(batch._fn), _address(batch._component)
        op.vrs, op.buf = ctypes.addressof(batch._vr), ctypes.addressof(batch.buf)

    def add_plan(self, due_mask: int) -> None:
        """Compile the exchange plan of the FMUs in ``due_mask`` (the master's plan of that
        set, as ``Master.propagate`` builds it) into C ops."""
        m = self.m
        due = frozenset(u for k, u in enumerate(self.units) if due_mask >> k & 1)
        stages = m._plans.get(due)
        if stages is None:
            stages = m._plans[due] = exchange.plan(
                [link for link in m.link_order if link.dst in due])
        items: list[tuple[int, Any, Any]] = []  # (kind, batch or link, extra)
        for st in stages:
            items += [(OP_GET, batch, None) for batch in st.reads]
            items += [(OP_TRACK, link, (buf, i)) for link, buf, i in st.sources]
            for w in st.writes:
                items += [(OP_COPY, w.batch, (j, buf, i)) for j, buf, i in w.copy or ()]
                items.append((OP_SET, w.batch, None))
        ops = (COp * max(len(items), 1))()
        batches: list[Any] = []
        for op, (kind, obj, extra) in zip(ops, items):
            op.kind = kind
            if kind in (OP_GET, OP_SET):
                self._call_op(op, kind, obj)
            elif kind == OP_TRACK:
                buf, i = extra
                op.unit = self.link_index[id(obj)]
                op.is_int = buf._type_ is not ctypes.c_double
                op.buf = ctypes.addressof(buf) + i * ctypes.sizeof(buf._type_)
            else:  # OP_COPY: the source's value into the write's buffer
                j, buf, i = extra
                op.is_int = buf._type_ is not ctypes.c_double
                op.buf = ctypes.addressof(obj.buf) + j * ctypes.sizeof(obj.buf._type_)
                op.src = ctypes.addressof(buf) + i * ctypes.sizeof(buf._type_)
            batches.append(obj if kind in (OP_GET, OP_SET) else None)
        self.plans.append((CPlan(due_mask, len(items), ops), batches))
        self.keep.append(ops)
        array = (CPlan * len(self.plans))(*(p for p, _ in self.plans))
        self.keep.append(array)
        self.state.plans, self.state.n_plans = array, len(self.plans)

    # -- state between the two sides -------------------------------------------------------
    def push(self) -> None:
        """The Python side's times, schedules, output point and recording into the C state."""
        m, s = self.m, self.state
        for k, u in enumerate(self.units):
            c = self.c_units[k]
            c.time = u.time_ticks
            c.next_event = u.next_event_ticks if u.next_event_ticks is not None else 0
        s.next_output, s.rows = m.next_output_ticks, m.recorder.rows
        if m._progress_fn is None:  # nothing to report: back to Python every BUDGET only
            s.report_at = m.stop_ticks + 1
            return
        every = max((m.stop_ticks - m.start_ticks) // REPORTS, 1)
        s.report_at = m.start_ticks + ((s.t - m.start_ticks) // every + 1) * every

    def pull(self) -> None:
        """The C side's times, schedules, counters, recording and connection values into the
        Python objects (counters handed over: zeroed on the C side)."""
        m, s = self.m, self.state
        for k, u in enumerate(self.units):
            c = self.c_units[k]
            u.time_ticks = c.time
            if c.scheduled != NOT_SCHEDULED:
                u.next_event_ticks = c.next_event
            u.do_steps += c.do_steps
            u.wall_time += c.wall
            c.do_steps, c.wall = 0, 0.0
        m.next_output_ticks, m.recorder.rows = s.next_output, s.rows
        for i, lk in enumerate(self.links):
            self._pull_link(lk, self.c_links[i])

    def _pull_link(self, lk: Link, c: CLink) -> None:
        integer = lk.src.vars[lk.src_name].family != "Real"
        if c.has_last:
            lk.last = int(c.last) if integer else c.last
        lk.changes = c.changes
        if lk.history is not None and c.n_history:
            values = c.history[:c.n_history]
            lk.history.extend(int(v) for v in values) if integer else lk.history.extend(values)
            c.n_history = 0

    # -- the loop ----------------------------------------------------------------------------
    def run(self) -> None:
        """From the start point (every FMU due) to the stop time's point."""
        m, s = self.m, self.state
        s.t, s.due = m.start_ticks, (1 << len(self.units)) - 1
        self.reported = m.start_ticks  # the Python loop reports the points after the first
        while True:
            self.push()
            code = self.lib.native_loop_run(ctypes.byref(s))
            self.pull()
            if code == DONE:
                break
            if code == YIELD:
                self.report(s.t)
            elif code == NEED_PLAN:
                self.add_plan(s.due)
            elif code == NEED_ROWS:
                m.recorder.grow()
                self.bind_recorder()
            elif code == CALL_FAILED:
                batches = (self.record_batches if s.failed_plan < 0
                           else self.plans[s.failed_plan][1])
                batch = batches[s.failed_op]
                batch.on_error(batch.call, int(s.status))
                raise SimulationError(f"{batch.unit.name}: {batch.call} failed "
                                      f"(status {s.status})")
            elif code == BAD_EVENT:
                unit = self.units[s.failed_unit]
                unit.update_schedule(s.t, None if s.status else s.value)  # raises
                raise SimulationError(f"{unit.name}: next_event_time = {s.value!r} s refused")
            elif code == STEP_FAILED:
                self.finish_step()
            else:
                raise SimulationError(f"the C loop returned {code}")
        self.report(s.t)
        m.finish(s.t)

    def report(self, t: int) -> None:
        """``Master.progress`` once per point reached (it also raises on Ctrl-C)."""
        if t != self.reported:
            self.reported = t
            self.m.progress(t)

    def finish_step(self) -> None:
        """A doStep the C side saw fail: its unit's step (the refused piece retried, or the
        error raised) and the later due FMUs' steps in Python, then the next point."""
        s = self.state
        k, t_next = int(s.failed_unit), int(s.t_next)
        self.units[k].step_to(t_next, first_status=int(s.status))
        for j in range(k + 1, len(self.units)):
            if s.due_next >> j & 1:
                self.units[j].step_to(t_next)
        s.t, s.due = t_next, s.due_next
        self.report(t_next)
