"""Hang detection for the compliance worker's FMI calls, decided on the FMU's own progress.

The worker announces each FMI call on a :class:`CallBoard` (a small shared file it and its
supervisor map into memory); the supervisor (:func:`supervise`) polls it and reads the worker's
CPU time from ``/proc``. A call is a hang when

* it used more CPU time than its limit (a spinning hang: CPU time does not grow faster on an
  idle machine or slower on a busy one), or
* it has not returned although the machine, at its measured speed, would have given it
  :data:`BLOCKED_FACTOR` times its CPU limit (a blocked hang uses no CPU). The speed is a
  :class:`SpeedGauge`: a fixed CPU workload timed against the wall clock, i.e. the share of a
  core a runnable process gets now. On a machine at load 20 on 2 cores the share is about 0.1,
  so the wall-clock time allowed grows tenfold.

The whole check of one FMU has a budget in the same units (seconds of a free core:
wall-clock time times the measured share), so a busy machine never turns a healthy FMU into a
hang. Linux: the worker's CPU time comes from ``/proc/<pid>/stat``.
"""

from __future__ import annotations

import mmap
import os
import signal
import struct
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

# Set-up calls may legitimately take long (fmi2Instantiate imports the FMU's Python runtime,
# e.g. cvxpy, and may compile its kernels on a first run; fmi2ExitInitializationMode builds the
# core: DARE, invariant sets; loading the binary runs its constructors): at least this much CPU.
SETUP_CALL_ALLOWANCE = 60.0  # CPU s
SETUP_CALLS = ("fmi2Instantiate", "fmi2ExitInitializationMode", "fmi3Instantiate",
               "fmi3ExitInitializationMode", "dlopen")
INSTANTIATE_CALLS = ("fmi2Instantiate", "fmi3Instantiate", "dlopen")
BLOCKED_FACTOR = 2.0  # a call is blocked once the machine offered it this many CPU limits
POLL = 0.05  # s between two looks at the board
GAUGE_EVERY = 0.5  # s between two speed measurements
GAUGE_WORK = 0.005  # CPU s of the speed measurement's workload
_CLOCK_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


class CallBoard:
    """The FMI call in progress, shared between the worker (:meth:`begin`, :meth:`end`) and its
    supervisor (:meth:`read`): a sequence number (odd while a call runs) and the call's
    description, in one small memory-mapped file."""

    SIZE = 4096
    _HEAD = struct.Struct("<QI")  # sequence number, description length

    def __init__(self, path: str | Path, create: bool = False) -> None:
        self.path = Path(path)
        if create:
            self.path.write_bytes(bytes(self.SIZE))
        with open(self.path, "r+b") as f:
            self._map = mmap.mmap(f.fileno(), self.SIZE)
        self._seq = 0

    def begin(self, description: str) -> None:
        data = description.encode("utf-8", "replace")[: self.SIZE - self._HEAD.size]
        self._map[self._HEAD.size:self._HEAD.size + len(data)] = data
        self._seq += 1 if self._seq % 2 == 0 else 2
        self._HEAD.pack_into(self._map, 0, self._seq, len(data))

    def end(self) -> None:
        if self._seq % 2:
            self._seq += 1
            self._HEAD.pack_into(self._map, 0, self._seq, 0)

    def clear(self) -> None:
        """No call in progress (before a new worker starts)."""
        self._HEAD.pack_into(self._map, 0, 0, 0)

    def read(self) -> tuple[int, str | None]:
        """(sequence number, description of the call in progress or None)."""
        for _ in range(10):  # a torn read (the worker wrote meanwhile) is read again
            seq, n = self._HEAD.unpack_from(self._map, 0)
            text = bytes(self._map[self._HEAD.size:self._HEAD.size + n])
            if self._HEAD.unpack_from(self._map, 0) == (seq, n):
                return seq, text.decode("utf-8", "replace") if seq % 2 else None
        return seq, None

    def close(self) -> None:
        self._map.close()


class SpeedGauge:
    """The share of one core a runnable process gets now (1 on an idle machine, about 0.1 at
    load 20 on 2 cores): this thread spins until it used :data:`GAUGE_WORK` s of CPU, and the
    share is that CPU time over the wall-clock time it took."""

    def sample(self) -> float:
        wall0, cpu0 = time.perf_counter(), time.thread_time()
        while time.thread_time() - cpu0 < GAUGE_WORK:
            pass
        wall = time.perf_counter() - wall0
        return min(1.0, (time.thread_time() - cpu0) / wall) if wall > 0 else 1.0


def process_cpu(pid: int) -> float | None:
    """CPU seconds (user + system, all threads) a live process has used; None if unreadable."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()
    return (int(fields[11]) + int(fields[12])) / _CLOCK_TICK


def call_name(description: str | None) -> str | None:
    """``fmi2DoStep`` of ``fmi2DoStep(currentCommunicationPoint=0.0, ...)``."""
    return description.split("(", 1)[0] if description else None


@dataclass
class Limits:
    """How long FMI calls and the whole check of one FMU may take."""

    call_cpu: float = 5.0  # CPU s one FMI call may use
    setup_call_cpu: float = SETUP_CALL_ALLOWANCE  # CPU s of a set-up call (at least call_cpu)
    budget: float = 300.0  # s of a free core for the whole check of one FMU

    def for_call(self, description: str) -> float:
        if description.startswith(SETUP_CALLS):
            return max(self.call_cpu, self.setup_call_cpu)
        return self.call_cpu


@dataclass
class Outcome:
    """How a supervised worker ended: its exit status (negative: the signal), or a hang."""

    returncode: int | None
    call: str | None = None  # the FMI call in progress when it ended (description)
    hang: str = ""  # "" (it ended by itself), "spinning", "blocked" or "budget"
    cpu: float = 0.0  # CPU s the call in progress used
    wall: float = 0.0  # wall-clock s the call in progress ran
    limit: float = 0.0  # its CPU limit

    def describe(self) -> str:
        """What happened, naming the call (used by the worker's reports)."""
        call = self.call or "no FMI call (the host's own code)"
        if self.hang == "spinning":
            return (f"hang: {self.call} did not return: it used {self.cpu:.3g} s of CPU in "
                    f"{self.wall:.3g} s, over its limit of {self.limit:g} CPU s (the host was "
                    "killed; --call-timeout sets the limit)")
        if self.hang == "blocked":
            return (f"hang: {self.call} did not return and used only {self.cpu:.3g} s of CPU "
                    f"in {self.wall:.3g} s (blocked: the machine, at its measured speed, "
                    f"offered it {BLOCKED_FACTOR:g} x its limit of {self.limit:g} CPU s; the "
                    "host was killed; --call-timeout sets the limit)")
        if self.hang == "budget":
            return (f"hang: the checks of this FMU did not finish within their budget "
                    f"(--timeout) while in {call}; the host was killed")
        code = self.returncode
        if code is not None and code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = f"signal {-code}"
            how = f"crashed ({name})"
        else:
            how = f"exited with status {code}"
        where = f" in {self.call}" if self.call else ""
        return f"the host process {how}{where}"


class Budget:
    """Seconds of a free core left for one FMU's checks (shared by its worker restarts)."""

    def __init__(self, seconds: float) -> None:
        self.left = seconds


def _pdeathsig() -> None:  # pragma: no cover - runs in the child between fork and exec
    """The worker dies with its supervisor (Linux prctl PR_SET_PDEATHSIG)."""
    try:
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)
    except Exception:
        pass


def supervise(cmd: list[str], env: dict[str, str], board: CallBoard, limits: Limits,
              budget: Budget, stdout, stderr) -> Outcome:
    """Run ``cmd`` (the worker) until it ends, or kill it on a hang (see the module's
    docstring); the worker's output goes to the files ``stdout`` and ``stderr``."""
    board.clear()
    proc = subprocess.Popen(cmd, env=env, stdout=stdout, stderr=stderr,
                            preexec_fn=_pdeathsig if os.name == "posix" else None)
    gauge = SpeedGauge()
    try:
        share = previous = gauge.sample()
        last = last_gauge = time.monotonic()
        seq_seen, call_cpu0, call_wall0, offered = -1, 0.0, last, 0.0
        while True:
            try:
                code = proc.wait(POLL)
                return Outcome(code, board.read()[1])
            except subprocess.TimeoutExpired:
                pass
            now = time.monotonic()
            if now - last_gauge >= GAUGE_EVERY:
                # the smaller of two samples: a lucky time slice never shortens a limit
                sample = gauge.sample()
                share, previous, last_gauge = min(previous, sample), sample, time.monotonic()
            offered_now = share * (now - last)
            last = now
            budget.left -= offered_now
            seq, call = board.read()
            cpu = process_cpu(proc.pid)
            if call is not None and seq != seq_seen:
                seq_seen, call_cpu0, call_wall0, offered = seq, cpu or 0.0, now, 0.0
            elif call is not None:
                offered += offered_now
            outcome = None
            if call is not None:
                limit = limits.for_call(call)
                used = (cpu - call_cpu0) if cpu is not None else 0.0
                if used > limit:
                    outcome = Outcome(None, call, "spinning", used, now - call_wall0, limit)
                elif offered > BLOCKED_FACTOR * limit:
                    outcome = Outcome(None, call, "blocked", used, now - call_wall0, limit)
            if outcome is None and budget.left <= 0:
                outcome = Outcome(None, call, "budget")
            if outcome is not None:
                proc.kill()
                proc.wait()
                return outcome
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
