"""Compiled plant kernels (numba), one call per communication step.

:func:`freight_steps` advances :class:`plants.freight.FreightTrain` over a run of sub-steps with
the equations of its numpy reference (``FreightTrain._substep``, kept and tested against this):
traction lag, brake-pipe wave and cylinder filling (eq. 9), resistance (eqs. 2-6) and the
trapezoidal coupler step; the tridiagonal coupler system is solved by the Thomas algorithm
(O(n), diagonally dominant, no pivoting) instead of the cached dense inverse. The route's
additional resistance is integrated over each vehicle's length from the per-segment slopes of
the cumulative profile, each vehicle keeping the segment its front and rear were last in
(a hint: the search walks from it, so a segment is only changed when a vehicle crosses a
boundary).

numba is optional: without it (``KERNELS is False``) the plants run their numpy reference.
The on-disk cache is keyed by the content of this file (not its path or time stamp), under
``$ATO_COSIM_NUMBA_CACHE`` or ``$XDG_CACHE_HOME/ato-cosim/numba`` (default ``~/.cache``), so an
FMU extracted to a fresh temporary directory reuses the machine code compiled by an earlier
extraction instead of compiling again (about a second).
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import os
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

# numba is a third-party dependency of the plant FMUs, optional at run time; it is imported
# (about a second) only when a plant asks for its kernels (compile_kernels), not by importing
# this module: the catalog, the CLI and the controllers' nominal models do not pay for it
KERNELS = (importlib.util.find_spec("numba") is not None
           and os.environ.get("ATO_COSIM_NO_KERNELS", "") == "")
_SOURCE = Path(__file__).resolve()
_DIGEST = hashlib.sha256(_SOURCE.read_bytes()).hexdigest()[:20]
KMH = 1.0 / 3.6
_OPTIONS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
_HELPERS: list[str] = []  # compiled with the kernels that call them
_ENTRIES: dict[str, str] = {}  # kernel name -> signature (compiled eagerly)
_LOCK = threading.Lock()
_compiled = False


def cache_dir() -> Path:
    """Where compiled kernels are kept (one sub-folder per content digest of this file)."""
    env = os.environ.get("ATO_COSIM_NUMBA_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ato-cosim" / "numba"


def njit(func):
    """A helper of the kernels: compiled by :func:`compile_kernels` (plain Python before)."""
    _HELPERS.append(func.__name__)
    return func


def njit_eager(signature: str):
    """A kernel with its signature: compiled (or loaded from the cache) by
    :func:`compile_kernels`, which plants call when they are built."""
    def mark(func):
        _ENTRIES[func.__name__] = signature
        return func
    return mark


def _install_locator(caching) -> None:
    """numba cache locator for this file only: by content digest, not path or mtime."""
    global _ContentCacheLocator

    class _ContentCacheLocator(caching._CacheLocator):
        def __init__(self, py_func, py_file):
            self._path = str(cache_dir() / _DIGEST)

        def ensure_cache_path(self):
            os.makedirs(self._path, exist_ok=True)
            tempfile.TemporaryFile(dir=self._path).close()  # writable, or numba moves on

        def get_cache_path(self):
            return self._path

        def get_source_stamp(self):
            return _DIGEST

        def get_disambiguator(self):
            return _DIGEST

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                if Path(py_file).resolve() != _SOURCE:
                    return None
                locator = cls(py_func, py_file)
                locator.ensure_cache_path()
            except OSError:
                return None  # not writable: numba tries its own locators, else no cache
            return locator

    caching.CacheImpl._locator_classes.insert(0, _ContentCacheLocator)


def compile_kernels() -> bool:
    """Import numba and compile the kernels (or load them from the on-disk cache), once per
    process and copy of this module; returns whether compiled kernels are available.

    Called when a plant is built (inside an FMU: at initialisation). Only numba is imported
    here, nothing of the project: inside an FMU the bundled modules are importable only while
    the FMU imports them, and this module was imported then. Stale cache folders (other
    digests of this file) are pruned at the first compilation, see :func:`prune_cache`."""
    global _compiled
    if not KERNELS:
        return False
    with _LOCK:
        if _compiled:
            return True
        try:
            import numba
            from numba.core import caching
        except ImportError:  # pragma: no cover - found by find_spec but broken
            return False

        _install_locator(caching)
        space = globals()
        originals = {name: space[name] for name in (*_HELPERS, *_ENTRIES)}
        if not _cache_entries_valid():
            _discard_cache()
        for cache in (True, False):  # a cache that fails to load: compile without it
            try:
                _jit(numba, space, originals, cache)
                break
            except Exception:  # noqa: BLE001 - any failure of a cache entry or of numba
                space.update(originals)
                if not cache:
                    return False  # the plants run their numpy reference
                _discard_cache()
        _compiled = True
    try:  # mark this version's folder as in use (prune_cache keeps recently used ones)
        os.utime(cache_dir() / _DIGEST)
    except OSError:
        pass
    prune_cache()
    return True


def _jit(numba: Any, space: dict[str, Any], originals: dict[str, Any], cache: bool) -> None:
    """Compile every helper and kernel from its Python function (``cache``: through the
    on-disk cache); the eager kernels compile, or load their cache entries, here."""
    options = {**_OPTIONS, "cache": cache}
    for name in _HELPERS:
        space[name] = numba.njit(**options)(originals[name])
    for name, signature in _ENTRIES.items():
        space[name] = numba.njit(signature, **options)(originals[name])


# numba cache entries that only the process which wrote them can load: a function of a module
# that was not importable by name is pickled as the module '<dynamic>'
_UNLOADABLE = (b"<dynamic>",)


def _cache_entries_valid() -> bool:
    """False when this version's cache folder holds an entry no other process can load
    (:data:`_UNLOADABLE`) or an empty file; a garbled or truncated entry is found when numba
    fails to load it (see :func:`compile_kernels`)."""
    folder = cache_dir() / _DIGEST
    try:
        for entry in folder.iterdir():
            if entry.suffix in (".nbi", ".nbc"):
                data = entry.read_bytes()
                if not data or any(mark in data for mark in _UNLOADABLE):
                    return False
    except OSError:
        return True  # no folder yet (or unreadable: numba then uses no cache)
    return True


def _discard_cache() -> None:
    """Remove this version's numba cache files (they are rebuilt by the next compilation)."""
    folder = cache_dir() / _DIGEST
    try:
        for entry in folder.iterdir():
            if entry.suffix in (".nbi", ".nbc"):
                entry.unlink(missing_ok=True)
    except OSError:
        pass


def prune_cache(keep_days: float = 7.0) -> list[Path]:
    """Remove cache folders of other versions of this file not used for ``keep_days`` days
    (by the newest modification time inside; numba rewrites its index when it adds to a
    folder). Only folders named like a digest holding nothing but numba cache files are
    touched; errors (another process pruning, permissions) are ignored. Returns the removed."""
    import shutil
    import time

    root = cache_dir()
    removed: list[Path] = []
    try:
        folders = [f for f in root.iterdir() if f.is_dir() and f.name != _DIGEST
                   and len(f.name) == len(_DIGEST) and all(c in "0123456789abcdef"
                                                           for c in f.name)]
    except OSError:
        return removed
    limit = time.time() - keep_days * 86400.0
    for folder in folders:
        try:
            files = list(folder.iterdir())
            if any(f.suffix not in (".nbi", ".nbc") or not f.is_file() for f in files):
                continue
            newest = max([f.stat().st_mtime for f in files] + [folder.stat().st_mtime])
            if newest < limit:
                shutil.rmtree(folder)
                removed.append(folder)
        except OSError:
            continue
    return removed


# constants vector of the freight kernel (indices)
(C_STICTION, C_K, C_C, C_SLACK, C_MODEL, C_TAU, C_RAMP_RATE, C_F_MAX, C_P_MAX, C_ED_MAX,
 C_ED_P_MAX, C_ED_FADE, C_PMAX, C_FILL_T, C_FILL_E, C_REL_T, C_REL_E, C_R_FULL, C_R_MIN) = range(19)
N_CONST = 19
# scalar state vector (in/out)
S_TRACTION, S_ENERGY, S_PEAK_DRAFT, S_PEAK_BUFF, S_ACCEL, S_FIRST, S_HELD = range(7)


@njit
def shoe_friction(kmh):
    """Converted friction coefficient of high-friction composite brake shoes (TB/T 1407):
    ``phi = 0.322 (v + 150) / (2 v + 150)``, v in km/h (>= 0). The one definition: the plant's
    numpy path, the controllers and the compiled kernels all call it."""
    return 0.322 * (kmh + 150.0) / (2.0 * kmh + 150.0)


@njit
def _interp(x, xs, cum, slopes, j):
    """``np.interp(x, xs, cum)`` walking from segment hint ``j``; returns (value, segment)."""
    n = xs.size
    if x < xs[0]:
        return cum[0], 0
    if x >= xs[n - 1]:
        return cum[n - 1], n - 2
    while j < n - 2 and x >= xs[j + 1]:
        j += 1
    while j > 0 and x < xs[j]:
        j -= 1
    if xs[j] == x:
        return cum[j], j
    return slopes[j] * (x - xs[j]) + cum[j], j


@njit
def _target_pressure(r, cp):
    if r >= max(cp[C_R_MIN], 1e-9):
        return cp[C_PMAX] * min(r / cp[C_R_FULL], 1.0)
    return 0.0


@njit
def _pow(x, e):
    """``x ** e``; ``x`` itself for ``e = 1`` (what pow returns there, without the call: the
    default release curve is linear)."""
    if e == 1.0:
        return x
    return x ** e


@njit
def _evolve(pres, target, dt, cp):
    """FreightTrain.evolve_pressure for one vehicle."""
    pmax = cp[C_PMAX]
    frac = min(pres / pmax, 1.0)
    if pres < target:
        t_up = cp[C_FILL_T] * _pow(frac, 1.0 / cp[C_FILL_E])
        up = pmax * _pow(min((t_up + dt) / cp[C_FILL_T], 1.0), cp[C_FILL_E])
        return min(up, target)
    if pres > target:
        t_down = cp[C_REL_T] * _pow(1.0 - frac, 1.0 / cp[C_REL_E])
        down = pmax * (1.0 - _pow(min((t_down + dt) / cp[C_REL_T], 1.0), cp[C_REL_E]))
        return max(down, target)
    return pres


@njit
def _traction(f0, demand, v_head, h, cp):
    """FreightTrain._traction_step: (force at the end, mean force) over a sub-step."""
    speed = abs(v_head)
    if speed > 0:
        trac = min(cp[C_F_MAX], cp[C_P_MAX] / speed)
        ed = min(cp[C_ED_MAX], cp[C_ED_P_MAX] / speed)
    else:
        trac = cp[C_F_MAX]
        ed = cp[C_ED_MAX]
    if cp[C_ED_FADE] > 0 and speed < cp[C_ED_FADE]:
        ed *= speed / cp[C_ED_FADE]
    target = min(max(demand, -ed), trac)
    if cp[C_MODEL] == 0.0:
        tau = cp[C_TAU]
        decay = math.exp(-h / tau)
        return target + (f0 - target) * decay, target + (f0 - target) * tau / h * (1.0 - decay)
    rate = cp[C_RAMP_RATE]
    gap = target - f0
    step = rate * h
    if abs(gap) <= step:
        t_reach = abs(gap) / rate
        return target, target - gap * t_reach / (2.0 * h)
    f1 = f0 + math.copysign(step, gap)
    return f1, 0.5 * (f0 + f1)


@njit
def _coupler(gap, dv, cp):
    """(stiffness, damping, free play to subtract) of one coupler from its gap (m)."""
    k, c, slack = cp[C_K], cp[C_C], cp[C_SLACK]
    if slack > 0:
        half = 0.5 * slack
        if gap > half:
            return k, c, half
        if gap < -half:
            return k, c, -half
        return 0.0, 0.0, 0.0
    return k, c, 0.0


_F = "float64[::1]"  # C-contiguous: unit-stride loads, no stride arithmetic per access
_FREIGHT_SIGNATURE = (f"void({', '.join([_F] * 8)}, float64[:, ::1], {', '.join([_F] * 11)}, "
                      f"int64[::1], int64[::1], {_F}, float64[:, ::1])")
# rows of the freight kernel's work array (n columns; allocated once per train)
W_START, W_MEAN_P, W_Y, W_W, W_DIAG, W_CPRIME, W_RPRIME, W_V1 = range(8)
N_WORK = 8


@njit
def _freight_holds(traction, mean_p, braking, x, length, weight_per_kn, brake_scale, res_a,
                   xs, cum, slopes, hint_f, hint_r):
    """Static friction (``FreightTrain._holds``): can the brake shoes at their standstill
    friction coefficient (0.322) and the constant resistance terms hold the train at rest
    against traction and the grade/curve forces?"""
    if not braking:
        return False
    grade = 0.0
    capacity = 0.0
    for i in range(x.size):
        c_front, hint_f[i] = _interp(x[i], xs, cum, slopes, hint_f[i])
        c_rear, hint_r[i] = _interp(x[i] - length[i], xs, cum, slopes, hint_r[i])
        grade -= weight_per_kn[i] * ((c_front - c_rear) / length[i])
        capacity += brake_scale[i] * mean_p[i] * shoe_friction(0.0) + res_a[i]
    return abs(traction + grade) <= capacity


@njit
def _freight_brakes(pres, start, mean_p, t0, t1, arrivals, values, targets, first, cp):
    """Cylinder pressures over ``[t0, t1]`` (eq. 9), in place; ``mean_p`` their mean over the
    sub-step. Returns (any pressure applied, oldest command still travelling)."""
    n = pres.size
    K = values.size
    for i in range(n):
        start[i] = pres[i]
    if K - first == 1:
        target = targets[first]
        same = True
        for i in range(n):
            if pres[i] != target:
                same = False
                break
        if not same:
            for i in range(n):
                pres[i] = _evolve(pres[i], target, t1 - t0, cp)
    else:
        newest = K
        for i in range(n):
            idx0 = first
            idx1 = first
            for k in range(first + 1, K):
                if arrivals[k, i] <= t0:
                    idx0 = k
                if arrivals[k, i] <= t1:
                    idx1 = k
            switch = min(max(arrivals[idx1, i], t0), t1)
            mid = _evolve(pres[i], targets[idx0], switch - t0, cp)
            pres[i] = _evolve(mid, targets[idx1], t1 - switch, cp)
            newest = min(newest, idx1)
        if newest > first:
            first = newest
    braking = False
    for i in range(n):
        mean_p[i] = 0.5 * (start[i] + pres[i])
        if mean_p[i] != 0.0:
            braking = True
    return braking, first


@njit_eager(_FREIGHT_SIGNATURE)
def freight_steps(x, v, pres, sc, hs, t0s, t1s, demands, arrivals, values, m_eff, length,
                  res_a, res_b, res_c, weight_per_kn, brake_scale, xs, cum, slopes, hint_f,
                  hint_r, cp, work):
    """Advance the freight train over the sub-steps ``hs`` (s) from ``t0s`` to ``t1s``.

    ``x``, ``v``, ``pres`` (per vehicle) and ``sc`` (scalars, ``S_*``) are updated in place;
    ``demands`` is the delayed traction demand per sub-step; ``arrivals[k, i]`` the time the
    brake-pipe command ``k`` (reduction ``values[k]``) reaches vehicle ``i``; commands before
    ``sc[S_FIRST]`` are forgotten (all vehicles passed them). Peaks are reset by the caller.
    ``work`` (``N_WORK`` x n) is scratch space: nothing is allocated per sub-step.

    Per sub-step: one pass builds each vehicle's force (resistance, brake, route at the
    predicted mid-point, traction, couplers at the start) and runs the forward sweep of the
    Thomas algorithm on the trapezoidal system; one pass substitutes back; one updates the
    positions and momentum; one the speeds and coupler peaks. Without slack the system matrix
    depends only on the sub-step, so its factorisation (diagonal, ``c'``) is computed once per
    distinct sub-step length of the call. The floating-point operations are those of the
    numpy reference, in its order, except for the tridiagonal solve.
    """
    n = x.size
    K = values.size
    first = int(sc[S_FIRST])
    f_trac = sc[S_TRACTION]
    start = work[W_START]
    mean_p = work[W_MEAN_P]
    y = work[W_Y]
    w = work[W_W]
    diag = work[W_DIAG]
    cprime = work[W_CPRIME]
    rprime = work[W_RPRIME]
    v1 = work[W_V1]
    targets = np.empty(K)  # target pressure of every command, once per call
    for k in range(first, K):
        targets[k] = _target_pressure(values[k], cp)
    m_total = 0.0
    for i in range(n):
        m_total += m_eff[i]
    stiction = cp[C_STICTION]
    slackless = not cp[C_SLACK] > 0
    factored_h = -1.0  # sub-step length the cached factorisation is for
    for s in range(hs.size):
        h, t0, t1 = hs[s], t0s[s], t1s[s]
        f1, f_mean = _traction(f_trac, demands[s], v[0], h, cp)
        braking, first = _freight_brakes(pres, start, mean_p, t0, t1, arrivals, values,
                                         targets, first, cp)
        if sc[S_HELD] != 0.0:  # at rest: stays while the brakes hold it
            if _freight_holds(f_mean, mean_p, braking, x, length, weight_per_kn, brake_scale,
                              res_a, xs, cum, slopes, hint_f, hint_r):
                f_trac = f1
                sc[S_ACCEL] = 0.0
                continue
            sc[S_HELD] = 0.0
        # couplers: trapezoidal rule, engagement (slack) fixed at the sub-step start;
        # y_j enters vehicle j with - and j+1 with +, w_j couples their new speeds
        for j in range(n - 1):
            gap = x[j] - length[j] - x[j + 1]
            dv = v[j] - v[j + 1]
            k, c, off = _coupler(gap, dv, cp)
            y[j] = k * (gap - off) + (0.25 * h * k + 0.5 * c) * dv
            w[j] = 0.25 * h * h * k + 0.5 * h * c
        refactor = not slackless or h != factored_h
        factored_h = h
        # forces and forward sweep of (diag(m) + W-Laplacian) v1 = m v0 + h force
        for i in range(n):
            speed = abs(v[i])
            diss = res_a[i] + (res_b[i] + res_c[i] * speed) * speed
            if braking:
                kmh = abs(v[i]) / KMH
                diss = diss + brake_scale[i] * mean_p[i] * shoe_friction(kmh)
            direction = max(min(v[i] / stiction, 1.0), -1.0)
            front = x[i] + 0.5 * h * v[i]
            c_front, hint_f[i] = _interp(front, xs, cum, slopes, hint_f[i])
            c_rear, hint_r[i] = _interp(front - length[i], xs, cum, slopes, hint_r[i])
            force = -diss * direction - weight_per_kn[i] * ((c_front - c_rear) / length[i])
            if i == 0:
                force += f_mean
            if i < n - 1:
                force -= y[i]
            if i > 0:
                force += y[i - 1]
            rhs = m_eff[i] * v[i] + h * force
            if refactor:
                d = m_eff[i]
                if i > 0:
                    d += w[i - 1]
                if i < n - 1:
                    d += w[i]
                if i > 0:
                    d += w[i - 1] * cprime[i - 1]
                diag[i] = d
                cprime[i] = -w[i] / d if i < n - 1 else 0.0
            if i > 0:
                rhs += w[i - 1] * rprime[i - 1]
            rprime[i] = rhs / diag[i]
        v1[n - 1] = rprime[n - 1]
        for i in range(n - 2, -1, -1):
            v1[i] = rprime[i] - cprime[i] * v1[i + 1]
        sc[S_ENERGY] += f_mean * 0.5 * (v[0] + v1[0]) * h
        momentum = 0.0
        mean_v1 = 0.0
        for i in range(n):
            momentum += m_eff[i] * (v1[i] - v[i])
            mean_v1 += m_eff[i] * v1[i]
            x[i] = x[i] + 0.5 * h * (v[i] + v1[i])
        sc[S_ACCEL] = momentum / (h * m_total)
        f_trac = f1
        hold = abs(mean_v1 / m_total) <= stiction and _freight_holds(
            f1, mean_p, braking, x, length, weight_per_kn, brake_scale, res_a, xs, cum, slopes,
            hint_f, hint_r)
        if hold:
            sc[S_HELD] = 1.0
        peak_draft = sc[S_PEAK_DRAFT]
        peak_buff = sc[S_PEAK_BUFF]
        for i in range(n):  # the regularised friction alone would let a braked train creep
            v[i] = 0.0 if hold else v1[i]
            if i > 0:
                j = i - 1
                g = x[j] - length[j] - x[i]
                d = v[j] - v[i]
                k, c, off = _coupler(g, d, cp)
                fc = k * (g - off) + c * d
                if fc > peak_draft:
                    peak_draft = fc
                if -fc > peak_buff:
                    peak_buff = -fc
        sc[S_PEAK_DRAFT] = peak_draft
        sc[S_PEAK_BUFF] = peak_buff
    sc[S_TRACTION] = f_trac
    sc[S_FIRST] = first


# EMU kernel: constants vector and scalar state (in/out)
E_STANDSTILL, E_HAS_NEUTRAL, E_TOTAL_MASS, E_GRAVITY_KN, E_K, E_D = range(6)
EMU_HELD, EMU_TRACTION_ENERGY, EMU_REGEN_ENERGY = range(3)


@njit
def _step_value_positive(s, starts, values, j):
    """``values[searchsorted(starts, s, 'right') - 1] > 0`` walking from hint ``j``."""
    n = starts.size
    while j < n - 1 and s >= starts[j + 1]:
        j += 1
    while j > 0 and s < starts[j]:
        j -= 1
    return values[j] > 0, j


@njit
def _emu_route(x, offsets, lengths, m, xs, cum, slopes, hint_f, hint_r, g_kn, out):
    """Route force ``m g w / 1000`` per unit (w: additional resistance over its length)."""
    for i in range(x.size):
        front = x[i] - offsets[i]
        c_front, hint_f[i] = _interp(front, xs, cum, slopes, hint_f[i])
        c_rear, hint_r[i] = _interp(front - lengths[i], xs, cum, slopes, hint_r[i])
        out[i] = m[i] * (g_kn * ((c_front - c_rear) / lengths[i]))


@njit
def _emu_neutral(x, offsets, lengths, nstarts, nvalues, hint_n, cp, out):
    for i in range(x.size):
        if cp[E_HAS_NEUTRAL] != 0.0:
            out[i], hint_n[i] = _step_value_positive(x[i] - offsets[i] - 0.5 * lengths[i],
                                                     nstarts, nvalues, hint_n[i])
        else:
            out[i] = False


@njit
def _affine(phi, gamma, state, f, out):
    """out = phi state + gamma f (the exact ZOH step of the EMU chain), each row summed in
    index order: the same operations for the half and the whole step."""
    for r in range(phi.shape[0]):
        acc = 0.0
        for c in range(phi.shape[1]):
            acc += phi[r, c] * state[c]
        acc2 = 0.0
        for c in range(gamma.shape[1]):
            acc2 += gamma[r, c] * f[c]
        out[r] = acc + acc2


@njit
def _emu_limits(v, neutral, ft, pt, fb, pb, hi, lo):
    for i in range(v.size):
        va = max(abs(v[i]), 1e-9)
        hi[i] = 0.0 if neutral[i] else min(ft[i], pt[i] / va)
        lo[i] = min(fb[i], pb[i] / va)


@njit
def _emu_force(applied, v, route, noise, da, db, dc, standstill, out):
    for i in range(v.size):
        sign = min(max(v[i] * (1.0 / standstill), -1.0), 1.0)
        resist = da[i] * sign + db[i] * v[i] + dc[i] * v[i] * abs(v[i])
        out[i] = max(applied[i], 0.0) + min(applied[i], 0.0) * sign - resist - route[i] \
            + noise[i]


@njit
def _emu_holds(u, x, offsets, lengths, m, da, ft, pt, fb, pb, xs, cum, slopes, hint_f, hint_r,
               nstarts, nvalues, hint_n, cp, route, neutral, hi, lo):
    """Emu._holds at the positions ``x`` (speeds zero)."""
    n = x.size
    _emu_route(x, offsets, lengths, m, xs, cum, slopes, hint_f, hint_r, cp[E_GRAVITY_KN], route)
    _emu_neutral(x, offsets, lengths, nstarts, nvalues, hint_n, cp, neutral)
    zero = np.zeros(n)
    _emu_limits(zero, neutral, ft, pt, fb, pb, hi, lo)
    pos = 0.0
    neg = 0.0
    rf = 0.0
    dsum = 0.0
    for i in range(n):
        a = max(min(u[i], hi[i]), -lo[i])
        pos += max(a, 0.0)
        neg += -min(a, 0.0)
        rf += route[i]
        dsum += da[i]
    return abs(pos - rf) <= neg + dsum


_FA = "float64[:]"  # the EMU kernels take any layout (3 units: no gain)
_F2 = "float64[:, :]"
_EMU_SIGNATURE = (f"void({', '.join([_FA] * 4)}, float64, {', '.join([_F2] * 5)}, "
                  f"{', '.join([_FA] * 14)}, int64[:], int64[:], {_FA}, {_FA}, int64[:], {_FA})")


@njit_eager(_EMU_SIGNATURE)
def emu_steps(x, v, sc, u, h, noise, phi, gamma, hphi, hgamma, m, offsets, lengths, da, db,
              dc, ft, pt, fb, pb, motored, xs, cum, slopes, hint_f, hint_r, nstarts, nvalues,
              hint_n, cp):
    """Advance :class:`plants.emu.Emu` over ``noise.shape[0]`` sub-steps of ``h`` s (same
    propagator ``phi, gamma`` and half-step ``hphi, hgamma``), command ``u`` held; ``x``,
    ``v`` and ``sc`` (``EMU_*``) in place. Same equations and order as ``Emu._substep``."""
    n = x.size
    route = np.empty(n)
    neutral = np.empty(n, dtype=np.bool_)
    hi = np.empty(n)
    lo = np.empty(n)
    applied = np.empty(n)
    f = np.empty(n)
    state = np.empty(2 * n)
    mid = np.empty(2 * n)
    new = np.empty(2 * n)
    v_mid = np.empty(n)
    x_mid = np.empty(n)
    standstill = cp[E_STANDSTILL]
    all_le = True
    any_lt = False
    for i in range(n):
        if u[i] > 0.0:
            all_le = False
        if u[i] < 0.0:
            any_lt = True
    for s in range(noise.shape[0]):
        if sc[EMU_HELD] != 0.0:
            if _emu_holds(u, x, offsets, lengths, m, da, ft, pt, fb, pb, xs, cum, slopes,
                          hint_f, hint_r, nstarts, nvalues, hint_n, cp, route, neutral, hi, lo):
                continue
            sc[EMU_HELD] = 0.0
        for i in range(n):
            state[i] = x[i]
            state[n + i] = v[i]
            x_mid[i] = x[i] + 0.5 * h * v[i]
        _emu_route(x_mid, offsets, lengths, m, xs, cum, slopes, hint_f, hint_r,
                   cp[E_GRAVITY_KN], route)
        _emu_neutral(x_mid, offsets, lengths, nstarts, nvalues, hint_n, cp, neutral)
        _emu_limits(v, neutral, ft, pt, fb, pb, hi, lo)
        for i in range(n):
            applied[i] = max(min(u[i], hi[i]), -lo[i])
        _emu_force(applied, v, route, noise[s], da, db, dc, standstill, f)
        _affine(hphi, hgamma, state, f, mid)
        for i in range(n):
            v_mid[i] = mid[n + i]
        _emu_limits(v_mid, neutral, ft, pt, fb, pb, hi, lo)
        for i in range(n):
            applied[i] = max(min(u[i], hi[i]), -lo[i])
        _emu_force(applied, v_mid, route, noise[s], da, db, dc, standstill, f)
        _affine(phi, gamma, state, f, new)
        trac = 0.0
        regen = 0.0
        mv_before = 0.0
        mv_after = 0.0
        for i in range(n):
            trac += max(applied[i], 0.0) * v_mid[i]
            regen += min(-min(applied[i], 0.0), hi[i]) * motored[i] * max(v_mid[i], 0.0)
            mv_before += m[i] * v[i]
            mv_after += m[i] * new[n + i]
            x[i] = new[i]
            v[i] = new[n + i]
        sc[EMU_TRACTION_ENERGY] += h * trac
        sc[EMU_REGEN_ENERGY] += h * regen
        v_mean = mv_after / cp[E_TOTAL_MASS]
        creeping = v_mean <= standstill and all_le and any_lt
        if (v_mean <= 0.0 and mv_before > 0.0) or creeping:
            if _emu_holds(u, x, offsets, lengths, m, da, ft, pt, fb, pb, xs, cum, slopes,
                          hint_f, hint_r, nstarts, nvalues, hint_n, cp, route, neutral, hi,
                          lo):
                for i in range(n):
                    v[i] = 0.0
                sc[EMU_HELD] = 1.0


_EMU_OUT_SIGNATURE = (f"void({', '.join([_FA] * 4)}, float64, {', '.join([_FA] * 15)}, "
                      f"int64[:], int64[:], {_FA}, {_FA}, int64[:], {_FA}, "
                      f"{', '.join([_FA] * 6)})")


@njit_eager(_EMU_OUT_SIGNATURE)
def emu_outputs(x, v, command, noise, held, m, m_eff, offsets, lengths, da, db, dc, ft, pt, fb,
                pb, motored, xs, cum, slopes, hint_f, hint_r, nstarts, nvalues, hint_n, cp, a,
                fz, tl, bl, applied, sc):
    """Emu.outputs' arrays (``a``, ``fz``, ``tl``, ``bl``, ``applied``) and scalars ``sc`` =
    [v_mean, a_mean, power, max |fz|, sum tl, sum bl] at the current state."""
    n = x.size
    route = np.empty(n)
    neutral = np.empty(n, dtype=np.bool_)
    f = np.empty(n)
    _emu_neutral(x, offsets, lengths, nstarts, nvalues, hint_n, cp, neutral)
    _emu_limits(v, neutral, ft, pt, fb, pb, tl, bl)
    for i in range(n):
        applied[i] = max(min(command[i], tl[i]), -bl[i])
    k, d = cp[E_K], cp[E_D]
    max_fz = 0.0
    for j in range(n - 1):
        fz[j] = k * (x[j] - x[j + 1]) + d * (v[j] - v[j + 1])
        max_fz = max(max_fz, abs(fz[j]))
    if held != 0.0:
        for i in range(n):
            a[i] = 0.0
    else:
        _emu_route(x, offsets, lengths, m, xs, cum, slopes, hint_f, hint_r, cp[E_GRAVITY_KN],
                   route)
        _emu_force(applied, v, route, noise, da, db, dc, cp[E_STANDSTILL], f)
        for j in range(n - 1):
            f[j] -= fz[j]
        for j in range(n - 1):
            f[j + 1] += fz[j]
        for i in range(n):
            a[i] = f[i] / m_eff[i]
    mv = 0.0
    ma = 0.0
    m_sum = 0.0
    pos = 0.0
    regen = 0.0
    s_tl = 0.0
    s_bl = 0.0
    for i in range(n):
        mv += m[i] * v[i]
        ma += m_eff[i] * a[i]
        m_sum += m_eff[i]
        pos += max(applied[i] * v[i], 0.0)
        regen += min(-min(applied[i], 0.0), tl[i]) * motored[i] * v[i]
        s_tl += tl[i]
        s_bl += bl[i]
    sc[0] = mv / cp[E_TOTAL_MASS]
    sc[1] = ma / m_sum
    sc[2] = pos - regen
    sc[3] = max_fz
    sc[4] = s_tl
    sc[5] = s_bl
