"""On-disk cache of offline design results (DARE solutions, invariant sets, ZOH models).

A controller's design is a pure function of its data; computing it needs scipy (about 0.45 s
of imports per process: scipy.linalg, scipy.optimize, scipy.spatial) and, for a tube MPC's
terminal set, a few LPs. :func:`cached_arrays` keeps each result as a ``.npz`` file keyed by
the SHA-256 of its kind, the caller's code version, the numpy and scipy versions and the exact
bytes of its inputs, so a further process (a sweep worker, a second ``cosim run``, an FMU
extracted to a fresh temporary directory) loads the same floats without importing scipy. The
arrays round-trip exactly (float64 in ``.npz``), so a result does not depend on whether it
came from the cache.

Location: ``$ATO_COSIM_CACHE`` or ``$XDG_CACHE_HOME/ato-cosim`` (default ``~/.cache``), folder
``designs``. ``ATO_COSIM_CACHE=off`` disables it. An unreadable or unwritable cache is not an
error: the result is computed (and, where possible, written). At most ``MAX_FILES`` files are
kept (the least recently used beyond that are removed).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

MAX_FILES = 4000
_VERSIONS: str | None = None


def cache_root() -> Path | None:
    """The project's cache folder (None when disabled with ``ATO_COSIM_CACHE=off``)."""
    env = os.environ.get("ATO_COSIM_CACHE", "")
    if env.lower() == "off":
        return None
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ato-cosim"


def source_digest(*files: str | Path) -> str:
    """A code version for :func:`cached_arrays`: the digest of the source files that compute
    the result (a changed file gives new keys)."""
    h = hashlib.sha256()
    for f in files:
        h.update(Path(f).read_bytes())
    return h.hexdigest()[:16]


def _library_versions() -> str:
    global _VERSIONS
    if _VERSIONS is None:
        parts = []
        for name in ("numpy", "scipy"):
            try:
                parts.append(f"{name}={metadata.version(name)}")
            except metadata.PackageNotFoundError:
                parts.append(f"{name}=?")
        _VERSIONS = ",".join(parts)
    return _VERSIONS


def _digest(kind: str, version: str, inputs: Sequence[Any]) -> str:
    h = hashlib.sha256(f"{kind}\0{version}\0{_library_versions()}".encode())
    for item in inputs:
        if isinstance(item, np.ndarray) or isinstance(item, (list, tuple)):
            a = np.ascontiguousarray(item, dtype=float)
            h.update(f"\0a{a.shape}".encode())
            h.update(a.tobytes())
        elif isinstance(item, (bool, int, float, str)) or item is None:
            h.update(f"\0{type(item).__name__}:{item!r}".encode())
        else:
            raise TypeError(f"cached_arrays: cannot key an input of type {type(item).__name__}")
    return h.hexdigest()[:32]


def cached_arrays(kind: str, version: str, inputs: Sequence[Any],
                  compute: Callable[[], Sequence[np.ndarray]]) -> tuple[np.ndarray, ...]:
    """``compute()`` (a tuple of arrays), or the same arrays from an earlier call with equal
    ``kind``, ``version`` and ``inputs`` (arrays, lists of numbers, scalars, strings) in any
    process. Exceptions of ``compute`` pass through and nothing is stored."""
    root = cache_root()
    if root is None:
        return tuple(np.asarray(a) for a in compute())
    folder = root / "designs"
    path = folder / f"{kind}-{_digest(kind, version, inputs)}.npz"
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = tuple(data[f"a{i}"] for i in range(len(data.files)))
        os.utime(path)  # recently used: kept by the pruning
        return arrays
    except (OSError, ValueError, KeyError):
        pass  # not there yet (or damaged): compute it
    arrays = tuple(np.asarray(a) for a in compute())
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
    except OSError:
        return arrays  # read-only: the result is still returned
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **{f"a{i}": a for i, a in enumerate(arrays)})
        os.replace(tmp, path)  # atomic: a concurrent reader sees the whole file or none
        _prune(folder)
    except OSError:
        Path(tmp).unlink(missing_ok=True)  # disk full: the result is still returned
    return arrays


def _prune(folder: Path) -> None:
    """Keep at most ``MAX_FILES`` results, removing the least recently used."""
    try:
        files = [f for f in folder.iterdir() if f.suffix == ".npz"]
        if len(files) <= MAX_FILES:
            return
        files.sort(key=lambda f: f.stat().st_mtime)
        for f in files[:len(files) - MAX_FILES]:
            f.unlink(missing_ok=True)
    except OSError:
        pass
