"""The multi-model ARX set of seed 003 (section 2, eqs. 10-13) and its switching index (eqs.
27-28).

Model ``i`` (T = 1 s; ``y`` speed in km/h, ``u`` unit force in daN/kN, i.e. per cent of the
train's weight; see :data:`PAPER_A`)::

    y(k) = a_i y(k-1) + b_i u(k-1) + c_i + xi(k)                               (eq. 13)

The paper prints ``y(k) + a_i y(k-1)`` in eq. 13 but lists its models as ``y(k) - a_i y(k-1)``:
``a_i`` here is the coefficient of the listed models (close to 1). ``c_i`` (0 in the paper's
list) is the mean of the disturbance ``xi`` in region ``i``: the constant part of the running
resistance linearised about the region's speed, which a model fitted to our plant needs.

Identification (:func:`identify`): fuzzy c-means clustering of the logged speeds into ``c``
operating regions (eqs. 10-12, ``skfuzzy.cluster.cmeans``), each sample assigned to the region
of its largest membership, then least squares per region (eq. 13; one ``b`` shared by all
regions when ``shared_b``, as the paper's list has).

Switching (:class:`SwitchingIndex`): with ``e_i(k) = y(k) - y_i(k)`` the one-step mismatch of
model ``i``, ``J_i(k) = alpha e_i(k)^2 + beta sum_{j=1..l} rho^j e_i(k-j)^2`` (eq. 27) and the
active model is ``argmin_i J_i`` (eq. 28).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cosim.fmu.state import StatefulCore

# The paper's set (section 2): y(k) - a_i y(k-1) = 0.318 u(k-1), T = 1 s. The a_i fit our
# reading of the units: 1 - a_i = c T dw0/dv at the region's speed with c = 3.6 g / 1000 /
# (1 + gamma) (km/h per s per N/kN) gives region speeds of about 0, 38, 116, 181, 246 and
# 286 km/h on w0 = 0.76 + 0.00636 v + 0.000115 v^2, and b = 0.318 is c T for u in daN/kN
# (10 N/kN) with gamma ~ 0.11.
PAPER_A = (0.9998, 0.9995, 0.9989, 0.9984, 0.9979, 0.9976)
PAPER_B = 0.318
N_PER_KN_PER_UNIT = 10.0  # the model's input unit (daN/kN) in N/kN


@dataclass(frozen=True)
class ArxSet:
    """First-order ARX models ``y(k) = a_i y(k-1) + b_i u(k-1) + c_i`` (eq. 13), ordered by
    their operating speed ``centres`` (km/h; NaN when unknown)."""

    a: tuple[float, ...]
    b: tuple[float, ...]
    c: tuple[float, ...]
    centres: tuple[float, ...]
    sample_time: float = 1.0

    def __post_init__(self) -> None:
        n = len(self.a)
        if n < 1 or not len(self.b) == len(self.c) == len(self.centres) == n:
            raise ValueError(f"ARX set: a, b, c, centres must have one entry per model "
                             f"(got {len(self.a)}, {len(self.b)}, {len(self.c)}, "
                             f"{len(self.centres)})")
        if not all(bi > 0 for bi in self.b):
            raise ValueError(f"ARX set: every b_i must be > 0, got {self.b}")

    @property
    def size(self) -> int:
        return len(self.a)

    @classmethod
    def paper(cls) -> ArxSet:
        """The six models printed in section 2 (c_i = 0, centres unknown)."""
        n = len(PAPER_A)
        return cls(PAPER_A, (PAPER_B,) * n, (0.0,) * n, (float("nan"),) * n)

    def predict(self, y_prev: float, u_prev: float) -> np.ndarray:
        """One-step prediction ``y_i(k)`` of every model."""
        return (np.asarray(self.a) * y_prev + np.asarray(self.b) * u_prev
                + np.asarray(self.c))

    def to_toml(self, comment: str = "") -> str:
        """The set as a TOML document (read back by :meth:`from_toml`)."""
        lines = [f"# {line}" for line in comment.splitlines()]
        lines += [f"sample_time = {self.sample_time!r}",
                  "# y(k) = a y(k-1) + b u(k-1) + c; y km/h, u daN/kN (eq. 13)"]
        for a, b, c, v in zip(self.a, self.b, self.c, self.centres, strict=True):
            lines += ["[[model]]", f"a = {a!r}", f"b = {b!r}", f"c = {c!r}",
                      f"centre_kmh = {v!r}"]
        return "\n".join(lines) + "\n"

    @classmethod
    def from_toml(cls, data: dict, source: str = "model set") -> ArxSet:
        try:
            models = data["model"]
            return cls(tuple(float(m["a"]) for m in models),
                       tuple(float(m["b"]) for m in models),
                       tuple(float(m.get("c", 0.0)) for m in models),
                       tuple(float(m.get("centre_kmh", float("nan"))) for m in models),
                       float(data.get("sample_time", 1.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{source}: not an ARX set ([[model]] tables with a, b, c): "
                             f"{exc}") from exc


def fuzzy_regions(speeds: np.ndarray, n_regions: int, m: float = 2.0, seed: int = 0,
                  error: float = 1e-6, maxiter: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Fuzzy c-means (eqs. 10-12) of the speeds: (centres ascending, membership n_regions x N
    in the same order)."""
    import skfuzzy  # only the identification needs it

    data = np.asarray(speeds, float).reshape(1, -1)
    if data.shape[1] < n_regions:
        raise ValueError(f"{data.shape[1]} samples cannot make {n_regions} regions")
    cntr, u, *_ = skfuzzy.cluster.cmeans(data, n_regions, m, error=error, maxiter=maxiter,
                                         seed=seed)
    order = np.argsort(cntr[:, 0])
    return cntr[order, 0], u[order]


def identify(y: Sequence[float], u: Sequence[float], n_models: int = 6, m: float = 2.0,
             seed: int = 0, shared_b: bool = True, affine: bool = True,
             sample_time: float = 1.0, valid: Sequence[bool] | None = None) -> ArxSet:
    """Identify the multi-model set from a log sampled every ``sample_time``: ``y[k]`` speed
    (km/h), ``u[k]`` input applied over ``[k, k+1)`` (daN/kN). Clusters on ``y(k-1)`` (fuzzy
    c-means, eqs. 10-12), hard assignment by largest membership, least squares (eq. 13).
    ``valid[k]`` (length ``len(y) - 1``) false drops the transition ``k -> k+1`` (e.g. where
    logs of several runs are joined)."""
    y, u = np.asarray(y, float), np.asarray(u, float)
    if y.shape != u.shape or y.ndim != 1:
        raise ValueError(f"y and u must be 1-D of one length (got {y.shape}, {u.shape})")
    yk, yp, up = y[1:], y[:-1], u[:-1]
    if valid is not None:
        keep = np.asarray(valid, bool)
        if keep.shape != yk.shape:
            raise ValueError(f"valid has {keep.shape[0]} entries, expected {yk.shape[0]}")
        yk, yp, up = yk[keep], yp[keep], up[keep]
    centres, member = fuzzy_regions(yp, n_models, m, seed)
    region = np.argmax(member, axis=0)
    counts = np.bincount(region, minlength=n_models)
    if counts.min() < 3:
        raise ValueError(f"a region has {counts.min()} samples: too few for least squares "
                         f"(counts {counts.tolist()})")
    # unknowns: a_1..a_n, [c_1..c_n], b (shared) or b_1..b_n
    n = n_models
    cols = n * (2 if shared_b is False else 1) + (n if affine else 0) + (1 if shared_b else 0)
    X = np.zeros((len(yk), cols))
    rows = np.arange(len(yk))
    X[rows, region] = yp
    col = n
    if affine:
        X[rows, col + region] = 1.0
        col += n
    if shared_b:
        X[:, col] = up
    else:
        X[rows, col + region] = up
    theta, *_ = np.linalg.lstsq(X, yk, rcond=None)
    a = theta[:n]
    c = theta[n:2 * n] if affine else np.zeros(n)
    bcol = theta[col:]
    b = np.full(n, bcol[0]) if shared_b else bcol
    return ArxSet(tuple(map(float, a)), tuple(map(float, b)), tuple(map(float, c)),
                  tuple(map(float, centres)), sample_time)


class SwitchingIndex(StatefulCore):
    """Eqs. 27-28: weighted current and past squared one-step mismatch of every model."""

    state_fields = ("history", "selected", "index")

    def __init__(self, models: ArxSet, alpha: float = 1.0, beta: float = 1.0,
                 rho: float = 0.9, horizon: int = 10, initial: int = 0) -> None:
        if not (alpha > 0 and beta > 0):
            raise ValueError(f"switching weights alpha = {alpha}, beta = {beta} must be > 0")
        if not 0 < rho < 1:
            raise ValueError(f"forgetting factor rho = {rho} must be in (0, 1)")
        if int(horizon) != horizon or horizon < 0:
            raise ValueError(f"switching horizon l = {horizon} must be an integer >= 0")
        if not 0 <= initial < models.size:
            raise ValueError(f"initial model {initial} not in 0..{models.size - 1}")
        self.models, self.alpha, self.beta, self.rho = models, alpha, beta, rho
        self.l = int(horizon)
        self.weights = rho ** np.arange(1, self.l + 1)
        self.history: list[list[float]] = []  # e_i(k-1)^2, e_i(k-2)^2, ... (newest first)
        self.selected = initial
        self.index = [0.0] * models.size

    def update(self, y: float, y_prev: float, u_prev: float) -> int:
        """New sample ``y(k)`` after ``y(k-1)``, ``u(k-1)``: the active model (eq. 28)."""
        e2 = (y - self.models.predict(y_prev, u_prev)) ** 2
        past = np.asarray(self.history[:self.l], float).reshape(-1, self.models.size)
        J = self.alpha * e2 + self.beta * (self.weights[:len(past)] @ past)
        self.history = [list(map(float, e2)), *self.history[:max(self.l - 1, 0)]]
        self.index = list(map(float, J))
        self.selected = int(np.argmin(J))
        return self.selected
