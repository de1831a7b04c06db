"""A reproduction entry ``papers/NAME/entry.toml`` as typed data, and its one loader.

An entry is an :class:`Entry` of parts, one dataclass per TOML table
(:mod:`cosim.reproduce.parts`: :class:`Run`, :class:`Metric`, :class:`PaperValue`,
:class:`Derived`, :class:`Ranking`, :class:`Sweep`, :class:`Figure`, :class:`Variant`,
:class:`Statement`), whose fields are the TOML keys (the key is the field's name, or its
``toml`` metadata) and document their meaning (``doc`` metadata). :func:`load_entry` checks an
entry against them: unknown keys (with the nearest known name), missing keys, types, ranges
and the names one part gives another; its errors name the file, the table and the key with
its value. The claims' own tables (``[ensemble]``, ``[[claims]]``) are checked by
:mod:`cosim.reproduce.ensemble` and :mod:`cosim.reproduce.claims`, whose ``*_KEYS`` tables
document their keys. The schema page ``docs/reproduce_schema.md`` is written from both
(:mod:`cosim.reproduce.schema`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cosim.reproduce.claims import CLAIM_KEYS, Claim, check_claims
from cosim.reproduce.ensemble import ENSEMBLE_KEYS, ClaimsError, Ensemble, check_ensemble
from cosim.reproduce.fields import ReproduceError, build, check_keys, check_table, doc, span_error
from cosim.reproduce.parts import (
    DERIVED_KINDS,
    FIGURE_KINDS,
    LINE_KINDS,
    Derived,
    Figure,
    Metric,
    PaperValue,
    Ranking,
    Run,
    Statement,
    Sweep,
    Variant,
)
from cosim.run.scenario import PAPERS_DIR, ROOT, entry_files, read_toml

__all__ = ["DERIVED_KINDS", "FIGURE_KINDS", "LINE_KINDS", "Derived", "Entry",
           "Figure", "Metric", "PaperValue", "Ranking", "ReproduceError", "Run", "Statement",
           "Sweep", "Variant", "check_statements", "check_variants", "entry_aliases",
           "entry_name", "entry_names", "load_entry", "resolve_name", "shipped", "slug"]


@dataclass(frozen=True, kw_only=True)
class Entry:
    """A reproduction entry: one paper's runs, its figures, and where ours meets the paper's."""

    name: str = doc("the entry's name: its paper's folder (``papers/NAME/entry.toml``), else "
                    "its file's stem", toml=False)
    path: Path = doc("the entry's file", toml=False)
    title: str = doc("the paper's name for a reader: \"Author et al. year, topic\" (the page's "
                     "title, the site's navigation, `cosim list` and `cosim reproduce`)")
    alias: str = doc("a short name `cosim reproduce` takes beside the file's stem: the first "
                     "author's surname and the year, e.g. `liu2022` (lower-case letters, digits "
                     "and '-')", default="")
    citation: str = doc("\"Authors. Title. Venue, year, vol(no): pages.\" as the paper gives it, "
                        "shown under the title", default="")
    doi: str = doc("the paper's DOI (e.g. `10.16383/j.aas.c200039`); empty: the page says the "
                   "paper gives none", default="")
    summary: str = doc("what the paper claims, in one paragraph of prose without our results "
                       "(the page's first paragraph)", default="")
    notes: str = doc("why our figures differ from the paper's (markdown, the page's last "
                     "section)", default="")
    table: str = doc("the table's file name without suffix (letters, digits, '_', '-')",
                     default="table")
    build: str = doc("the FMU builds its simulations run unless `cosim reproduce --build` says "
                     "otherwise: \"native\" (each FMU's native C build where it has one, the "
                     "others Python) or \"python\" (every FMU's Python build); a reason for "
                     "\"python\" belongs in a comment", default="native")
    overrides: dict[str, Any] = doc(
        "overrides of every run and sweep (e.g. the entry's disturbance); a run's own ``set`` "
        "wins", toml="set", default={})
    runs: list[Run] = doc("the runs: the table's rows")
    metrics: list[Metric] = doc("the table's columns", default=[])
    paper: list[PaperValue] = doc("the paper's figures", default=[])
    derived: list[Derived] = doc("figures computed from two runs", default=[])
    rankings: list[Ranking] = doc("the runs ordered by a metric", default=[])
    sweeps: list[Sweep] = doc("sweeps of scenarios over a grid", default=[])
    figures: list[Figure] = doc("figures of the runs' series", default=[])
    ensemble: Ensemble = doc("how a run is varied over seeds for the claims "
                             "(:class:`cosim.reproduce.ensemble.Ensemble`)", default=Ensemble())
    claims: list[Claim] = doc(
        "the paper's claims, tested over the ensemble (families expanded; "
        ":func:`cosim.reproduce.claims.check_claims`)", default=[])
    variants: list[Variant] = doc("every claim again with some runs replaced", default=[])
    statements: list[Statement] = doc(
        "each assertion of the paper with the claims that test it, or why it is untestable",
        default=[])

    def run_names(self) -> list[str]:
        """The ``[[runs]]`` names, in order."""
        return [r.name for r in self.runs]


PARTS: dict[str, type] = {"runs": Run, "metrics": Metric, "paper": PaperValue,
                          "derived": Derived, "rankings": Ranking, "sweeps": Sweep,
                          "figures": Figure}
CLAIM_PARTS = ("ensemble", "claims", "variants", "statements")  # read after the parts


def entry_names() -> list[str]:
    """The shipped entries: the folder names of ``papers/*/entry.toml``
    (:func:`cosim.run.scenario.entry_files`)."""
    return list(entry_files())


def shipped(entry: Entry) -> bool:
    """Whether ``entry`` was read from a shipped entry file (not from another path)."""
    return entry_files().get(entry.name) == entry.path


def entry_name(path: Path) -> str:
    """The name of the entry at ``path``: its paper's folder for ``papers/NAME/entry.toml``,
    else the file's stem."""
    in_papers = path.name == "entry.toml" and path.resolve().parent.parent == PAPERS_DIR.resolve()
    return path.parent.name if in_papers else path.stem


def entry_aliases() -> dict[str, str]:
    """Each shipped entry's ``alias`` -> its file's stem (entries without one left out)."""
    out: dict[str, str] = {}
    for name, path in entry_files().items():
        alias = read_toml(path, ReproduceError).get("alias", "")
        if alias:
            out[alias] = name
    return out


def resolve_name(name: str) -> str:
    """The file stem of the shipped entry called ``name`` (its stem or its ``alias``);
    :class:`ReproduceError` with the nearest known name otherwise."""
    import difflib

    names = entry_names()
    if name in names:
        return name
    aliases = entry_aliases()
    if name in aliases:
        return aliases[name]
    known = [*names, *aliases]
    near = difflib.get_close_matches(name, known, n=1)
    hint = f" (did you mean {near[0]!r}?)" if near else ""
    raise ReproduceError(f"no reproduction entry {name!r}{hint}; known: {', '.join(known)}")


def slug(name: str) -> str:
    """A run's or sweep's name as a folder name (lower case, runs of other characters as
    ``_``)."""
    return re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_").lower()


def _read(name: str | Path) -> tuple[Path, dict[str, Any]]:
    """The path of entry ``name`` (a shipped entry's name or alias, or a path) and its TOML."""
    path = Path(name)
    if not path.suffix:
        path = entry_files()[resolve_name(str(name))]
    if not path.is_file():
        raise ReproduceError(f"no reproduction entry {str(name)!r} (known: {entry_names()})")
    return path, read_toml(path, ReproduceError)


def _part(cls: type, path: Path, key: str, data: dict[str, Any], i: int) -> Any:
    """Part ``i`` of ``[[key]]`` built as ``cls`` (keys and types checked)."""
    return build(cls, f"{path}: [[{key}]] #{i + 1}", data)


def _cross(where: str, what: str, value: Any, names: list[str], table: str = "[[runs]]"
           ) -> None:
    """Refuse ``value`` of key ``what`` unless it is one of ``names`` (the names of ``table``)."""
    if value not in names:
        raise ReproduceError(f"{where}: {what} {value!r} is not one of {table} {names}")


def load_entry(name: str | Path) -> Entry:
    """Read and check an entry by name (its paper's folder, ``papers/NAME/entry.toml``) or
    path; :class:`ReproduceError` names the file, table and key of anything wrong."""
    path, data = _read(name)
    top = check_table(Entry, str(path), data, skip=(*PARTS, *CLAIM_PARTS))
    if not re.fullmatch(r"[A-Za-z0-9_-]+", top["table"]):
        raise ReproduceError(f"{path}: table = {top['table']!r} must be a file name without "
                             "folder or suffix (letters, digits, '_', '-')")
    if top["alias"] and not re.fullmatch(r"[a-z0-9-]+", top["alias"]):
        raise ReproduceError(f"{path}: alias = {top['alias']!r} must be lower-case letters, "
                             "digits and '-'")
    if top["build"] not in ("native", "python"):
        raise ReproduceError(f"{path}: build = {top['build']!r} must be \"native\" or "
                             "\"python\"")
    common = top["overrides"]
    lists = {key: _tables(str(path), key, data.get(key, [])) for key in PARTS}
    runs = [_part(Run, path, "runs", r, i) for i, r in enumerate(lists["runs"])]
    runs = [Run(name=r.name, scenario=r.scenario,
                overrides={**common, **_tuned(f"{path}: [[runs]] #{i + 1}", r.tuned),
                           **r.overrides}, tuned=r.tuned, repeat=r.repeat)
            for i, r in enumerate(runs)]
    for i, run in enumerate(runs):
        if run.repeat < 1:
            raise ReproduceError(f"{path}: [[runs]] #{i + 1}: repeat = {run.repeat!r} must be "
                                 "an integer >= 1")
    names = [r.name for r in runs]
    if len(set(names)) != len(names):
        raise ReproduceError(f"{path}: [[runs]] names repeat: {names}")
    metrics = [_part(Metric, path, "metrics", m, i) for i, m in enumerate(lists["metrics"])]
    for i, metric in enumerate(metrics):
        if metric.ratio_to is not None:
            _cross(f"{path}: [[metrics]] #{i + 1}", "ratio_to", metric.ratio_to, names)
    keys = [m.key for m in metrics]
    paper = [_check_paper(_part(PaperValue, path, "paper", p, i), f"{path}: [[paper]] #{i + 1}",
                          names, keys) for i, p in enumerate(lists["paper"])]
    derived = [_check_derived(_part(Derived, path, "derived", d, i),
                              f"{path}: [[derived]] #{i + 1}", names)
               for i, d in enumerate(lists["derived"])]
    rankings = [_check_ranking(_part(Ranking, path, "rankings", r, i),
                               f"{path}: [[rankings]] #{i + 1}", names, keys)
                for i, r in enumerate(lists["rankings"])]
    sweeps = [_check_sweep(_part(Sweep, path, "sweeps", s, i), f"{path}: [[sweeps]] #{i + 1}",
                           common) for i, s in enumerate(lists["sweeps"])]
    figures = [_figure(path, f, i, names) for i, f in enumerate(lists["figures"])]
    _claim_keys(path, data)
    try:
        ensemble = check_ensemble(str(path), data.get("ensemble"))
        claims = check_claims(str(path), data.get("claims", []), names, ensemble)
    except ClaimsError as err:
        raise ReproduceError(str(err)) from err
    variants = check_variants(str(path), data.get("variants", []), names)
    statements = check_statements(str(path), data.get("statements", []),
                                  [c.id for c in claims])
    return Entry(name=entry_name(path), path=path, **top, runs=runs, metrics=metrics, paper=paper,
                 derived=derived, rankings=rankings, sweeps=sweeps, figures=figures,
                 ensemble=ensemble, claims=claims, variants=variants, statements=statements)


def _tuned(where: str, tuned: dict[str, str]) -> dict[str, Any]:
    """The overrides a run's ``tuned`` key names: ``FMU.PARAMETER`` -> value for every key of
    each named table."""
    out: dict[str, Any] = {}
    for fmu, ref in tuned.items():
        at = f"{where}: tuned.{fmu} = {ref!r}"
        file, sep, table = str(ref).partition("#")
        if not (sep and file and table):
            raise ReproduceError(f"{at}: expected \"FILE#TABLE\" (a TOML file from the "
                                 "repository root and one of its tables)")
        path = ROOT / file
        if not path.is_file():
            raise ReproduceError(f"{at}: no file {path}")
        data = read_toml(path, ReproduceError)
        values = data.get(table)
        if not isinstance(values, dict) or not values:
            raise ReproduceError(f"{at}: {path} has no table [{table}] of values (its tables: "
                                 f"{sorted(k for k, v in data.items() if isinstance(v, dict))})")
        out.update({f"{fmu}.{key}": value for key, value in values.items()})
    return out


def _claim_keys(path: Path, data: dict[str, Any]) -> None:
    """The keys of the claims' tables (checked further by :mod:`cosim.reproduce.claims`)."""
    if "ensemble" in data:
        check_keys(f"{path}: [ensemble]", data["ensemble"], list(ENSEMBLE_KEYS))
    for i, table in enumerate(_tables(str(path), "claims", data.get("claims", []))):
        check_keys(f"{path}: [[claims]] #{i + 1}", table, list(CLAIM_KEYS))


def _tables(where: str, key: str, tables: Any) -> list[dict[str, Any]]:
    """The value of ``key`` checked to be a list of tables (``[[key]]``)."""
    if not (isinstance(tables, list) and all(isinstance(t, dict) for t in tables)):
        raise ReproduceError(f"{where}: {key} = {tables!r}: expected [[{key}]] tables")
    return tables


def check_variants(where: str, tables: Any, run_names: list[str]) -> list[Variant]:
    """The ``[[variants]]`` tables of the entry at ``where``: each names the runs that replace
    others in every claim, checked against the entry's runs."""
    out: list[Variant] = []
    for i, data in enumerate(_tables(where, "variants", tables)):
        at = f"{where}: [[variants]] #{i + 1}"
        var = build(Variant, at, data)
        if var.name in {v.name for v in out} or var.name == "main":
            raise ReproduceError(f"{at}: name = {var.name!r}: a new name other than 'main'")
        if not var.replace:
            raise ReproduceError(f"{at}: replace = {var.replace!r}: expected a table run -> run")
        for run in (r for pair in var.replace.items() for r in pair):
            if run not in run_names:
                raise ReproduceError(f"{at}: replace: {run!r} is not one of the entry's "
                                     f"[[runs]] {run_names}")
        if var.seeds is not None and var.seeds < 1:
            raise ReproduceError(f"{at}: seeds = {var.seeds!r}: expected an integer >= 1 (the "
                                 "first report seeds, at most --seeds)")
        out.append(var)
    return out


def check_statements(where: str, tables: Any, claim_ids: list[str]) -> list[Statement]:
    """The ``[[statements]]`` tables of the entry at ``where``: each of the paper's assertions
    with the claims that test it (checked against the entry's claim ids), or why it is
    untestable."""
    out: list[Statement] = []
    for i, data in enumerate(_tables(where, "statements", tables)):
        at = f"{where}: [[statements]] #{i + 1}"
        st = build(Statement, at, data)
        if not st.text.strip():
            raise ReproduceError(f"{at}: text: the paper's statement is missing")
        if (st.claims is None) == (st.untestable is None):
            raise ReproduceError(f"{at} ({st.text[:40]!r}): give claims = [ids] or "
                                 "untestable = \"why\", one of them")
        for cid in st.claims or []:
            if cid not in claim_ids:
                raise ReproduceError(f"{at}: claims: {cid!r} is not one of the entry's claim "
                                     "ids")
        if st.headline and st.claims is None:
            raise ReproduceError(f"{at} ({st.text[:40]!r}): headline = true needs claims that "
                                 "test it")
        out.append(st)
    return out


def _check_verdict(where: str, value: float | None, band: list[float] | None,
                   tolerance: float | None) -> None:
    """The paper's value / range / tolerance of a ``[[paper]]`` or ``[[derived]]`` row."""
    if band is not None and not (len(band) == 2 and band[0] <= band[1]):
        raise ReproduceError(f"{where}: range {band!r} must be [low, high]")
    if tolerance is not None and value is None:
        raise ReproduceError(f"{where}: a tolerance needs a value")
    if tolerance is not None and tolerance < 0:
        raise ReproduceError(f"{where}: tolerance = {tolerance!r} must be >= 0")


def _check_paper(ref: PaperValue, where: str, names: list[str], keys: list[str]) -> PaperValue:
    """A ``[[paper]]`` figure checked: a value or a range, and the run and metric it names."""
    if ref.value is None and ref.band is None:
        raise ReproduceError(f"{where}: needs a value or a range")
    _check_verdict(where, ref.value, ref.band, ref.tolerance)
    _cross(where, "run", ref.run, names)
    if ref.metric not in keys:
        raise ReproduceError(f"{where}: metric {ref.metric!r} is not in [[metrics]] {keys}")
    return ref


def _check_derived(der: Derived, where: str, names: list[str]) -> Derived:
    """A ``[[derived]]`` figure checked: its kind, the runs it names, the paper's figure."""
    if der.kind not in DERIVED_KINDS:
        raise ReproduceError(f"{where}: kind {der.kind!r} (known: {DERIVED_KINDS})")
    _cross(where, "run", der.run, names)
    _cross(where, "baseline", der.baseline, names)
    _check_verdict(where, der.value, der.band, der.tolerance)
    return der


def _check_ranking(rank: Ranking, where: str, names: list[str], keys: list[str]) -> Ranking:
    """A ``[[rankings]]`` checked: its metric, distinct runs, the paper's order of them."""
    if rank.metric not in keys:
        raise ReproduceError(f"{where}: metric {rank.metric!r} is not in [[metrics]] {keys}")
    unknown = sorted(set(rank.runs) - set(names))
    if unknown or len(set(rank.runs)) != len(rank.runs) or not rank.runs:
        raise ReproduceError(f"{where}: runs {rank.runs!r} must be distinct [[runs]] names "
                             f"(unknown: {unknown})")
    if rank.paper is not None and sorted(rank.paper) != sorted(rank.runs):
        raise ReproduceError(f"{where}: paper {rank.paper!r} must order the same runs as runs "
                             f"{rank.runs!r}")
    return rank


def _check_sweep(sweep: Sweep, where: str, common: dict[str, Any]) -> Sweep:
    """A ``[[sweeps]]`` checked (labels of its scenarios), with the entry's ``set`` added to its
    grid."""
    unnamed = sorted(set(sweep.labels) - {Path(s).stem for s in sweep.scenarios})
    if unnamed:
        raise ReproduceError(f"{where}: labels name scenarios {unnamed} that are not in its "
                             f"scenarios {sweep.scenarios!r}")
    if not sweep.scenarios or not sweep.grid:
        raise ReproduceError(f"{where}: scenarios and grid must not be empty")
    # the sweep's own keys first (the first is its figure's x axis), then the entry's
    grid = {**sweep.grid, **{k: v for k, v in common.items() if k not in sweep.grid}}
    return Sweep(name=sweep.name, scenarios=sweep.scenarios, grid=grid, labels=sweep.labels)


_CLASS_REQUIRED = ("ref", "classes", "limit_kmh", "limit_below_kmh", "limit_fraction")


def _figure(path: Path, data: dict[str, Any], i: int, names: list[str]) -> Figure:
    """Figure ``i`` of ``[[figures]]`` built and checked against its kind and the runs ``names``."""
    where = f"{path}: [[figures]] #{i + 1}"
    kind = data.get("kind", "overlay")
    if kind not in FIGURE_KINDS:
        raise ReproduceError(f"{where}: kind {kind!r} (known: {FIGURE_KINDS})")
    fig = build(Figure, where, data, {}, kind=kind)
    if kind == "speed_classes":
        missing = [k for k in _CLASS_REQUIRED if getattr(fig, k) is None]
        if missing:
            raise ReproduceError(f"{where}: missing key(s) {missing}")
        edges = fig.classes or []
        if len(edges) < 2 or any(b <= a for a, b in zip(edges[:-1], edges[1:], strict=True)):
            raise ReproduceError(f"{where}: classes {edges!r} must be increasing edges")
    else:
        if fig.x is None:
            raise ReproduceError(f"{where}: missing key(s) ['x']")
        if fig.y_reduce not in (None, "mean"):
            raise ReproduceError(f"{where}: y_reduce {fig.y_reduce!r} (known: 'mean')")
        for key in ("xlim", "ylim", "band_x"):
            value = getattr(fig, key)
            if value is not None and (error := span_error(value, key == "band_x")):
                raise ReproduceError(f"{where}: {key} = {value!r}: {error}")
    for key in ("limit_kmh", "limit_below_kmh", "limit_fraction"):
        value = getattr(fig, key)
        if value is not None and value < 0:
            raise ReproduceError(f"{where}: {key} = {value!r} must be >= 0")
    unknown_runs = sorted(set(fig.runs or names) - set(names))
    if unknown_runs:
        raise ReproduceError(f"{where}: runs {unknown_runs} are not in [[runs]] {names}")
    return fig
