"""A campaign on this tree against an earlier commit checked out beside it, in one run.

For each entry (default seed 000 and seed 004) runs ``cosim reproduce ENTRY --seeds K --out
TMP`` through each tree's own CLI (a subprocess with ``PYTHONPATH`` set to that tree, cwd the
tree), alternating the two trees (baseline, this; then this, baseline; ...) so a change of the
machine's load hits both alike. The baseline commit (default 8a1e303) is checked out beside
this tree with ``git worktree add --detach`` (a ``git clone`` when the repository cannot hold a
worktree) and removed afterwards; each tree builds its FMUs first with its own ``cosim build``,
and ``cosim build --native`` where its entry's build is native, outside the timed runs.

Reports per entry and tree the wall time and the CPU time of the CLI and its descendants
(``RUSAGE_CHILDREN``: user + system of every finished child process, pool workers included),
medians over the repetitions, the ratio baseline / this tree (target: this tree takes at most a
fifth of the baseline's time), and whether the verdicts are the same: ``claims.csv``'s
``verdict`` and ``k`` of ``K`` of every claim id both trees have, compared (the differences
listed, and the claims of one tree only). Both trees get the same options (``--no-rounding``
on both when given, and only if both CLIs have it).

With ``--same-entry`` this tree runs the baseline's own entry file (read from the baseline
checkout, e.g. 8a1e303's ``scenarios/reproduce/seed001.toml``) instead of its current entry,
which later issues gave more claims, variants and rounding paths: the same claims and members
on both trees, so the times compare the same work, and the k of K of every claim compare the
simulations (a difference there is a change of the scenarios, plants or controllers the
entry names since the baseline); the verdict's label can still differ where this tree reads
the same k of K with other statistics. The baseline's entry leaves most FMU parameters at their
defaults, and the two trees' defaults can differ (seed 001's and seed 002's tuned laws): so
this tree runs a copy of that entry whose every ``[[runs]]`` sets each parameter
whose default differs between the two trees' builds of its FMU to the baseline's default (the
run's own ``set`` wins), read from both trees' ``modelDescription.xml`` (:func:`pins`), and the
campaigns run the same controllers; the pinned parameters are reported. The baseline's entry
names no build, so this tree runs it with the build its own entry for that paper names
(``--build``: seed 004's online twin has no native model, so python there). Beside the
verdicts, the claims' medians over the members (``median``, ``worst``, ``a_median``,
``b_median`` where both trees write them) are compared: equal numbers from both trees say the
simulations are the same, whatever the labels. Where this tree's build is native, it runs the
entry once more on its Python builds, the baseline's, after the timed pairs and outside the
ratio (``python_check``): its claims against the baseline's say whether the tree changed the
simulations, and against the native run's what the native builds (which differ at rounding
level) change in k of K and in the verdicts. The user's design cache
(``$ATO_COSIM_CACHE``) is shared by the trees as in any campaign. Asserts nothing;
``benchmarks/run_all.py --only baseline`` records the figures.

    python benchmarks/bench_baseline.py [--baseline COMMIT] [--entries seed000 seed004]
        [--seeds K] [--repeat R] [--workers N] [--no-rounding] [--same-entry]
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import functools
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from fmpy import read_model_description

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parent.parent

BASELINE = "8a1e303"  # the default --baseline: the commit the campaigns are compared with
ENTRIES = ("seed000", "seed004")
SEEDS = 5  # K, report seeds per claim
TARGET = 5.0  # baseline time / this tree's time (this tree at most a fifth of the baseline)
THIS, BASE = "this", "baseline"
# claims.csv columns that are functions of the members' values alone (not of the verdict rules)
NUMBERS = ("median", "worst", "a_median", "b_median")

# the build of a tree's entry: "native" or "python" (trees without native campaigns: python)
_ENTRY_BUILD = """
import sys
try:
    from cosim.reproduce.entry import load_entry
except ImportError:
    print("python")
else:
    print(getattr(load_entry(sys.argv[1]), "build", "python"))
"""


# the path of an entry's file in a tree: its entry module's resolver where it has one, else the
# older layout (scenarios/reproduce/NAME.toml, as at 8a1e303)
_ENTRY_FILE = """
import sys
from pathlib import Path
try:
    from cosim.reproduce.entry import load_entry
except ImportError:
    from cosim.run.reproduce import load_entry
print(Path(load_entry(sys.argv[1]).path).resolve())
"""


class Tree:
    """A checkout of the package: its CLI run as a subprocess with ``PYTHONPATH`` = the tree."""

    def __init__(self, root: Path, label: str) -> None:
        self.root = root
        self.label = label
        self.env = {**os.environ, "PYTHONPATH": str(root)}

    def command(self, *args: str) -> list[str]:
        return [sys.executable, "-m", "cosim.cli", *args]

    def run(self, args: list[str]) -> str:
        """Run ``args`` in the tree; its stdout. A failure raises with the tree and its stderr."""
        done = subprocess.run(args, cwd=self.root, env=self.env, capture_output=True,
                              text=True)
        if done.returncode != 0:
            raise RuntimeError(f"{self.label} tree ({self.root}): {' '.join(args[1:])} exited "
                               f"{done.returncode}:\n{done.stderr[-3000:]}")
        return done.stdout

    def has_option(self, command: str, option: str) -> bool:
        return option in self.run(self.command(command, "--help"))

    def entry_build(self, entry: str) -> str:
        return self.run([sys.executable, "-c", _ENTRY_BUILD, entry]).strip()

    def entry_file(self, entry: str) -> Path:
        """The file of ``entry`` in this tree."""
        return Path(self.run([sys.executable, "-c", _ENTRY_FILE, entry]).strip())

    def build(self, entries: list[str]) -> None:
        """The FMUs the entries' campaigns run: every Python FMU, and the native ones when an
        entry's build is native."""
        self.run(self.command("build"))
        if any(self.entry_build(e) == "native" for e in entries):
            self.run(self.command("build", "--native"))


@contextlib.contextmanager
def checkout(commit: str) -> Iterator[Path]:
    """``commit`` checked out in a temporary folder beside this tree (removed on exit)."""
    tmp = Path(tempfile.mkdtemp(prefix="ato-baseline-"))
    tree = tmp / commit
    added = subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree),
                            commit], capture_output=True, text=True).returncode == 0
    try:
        if not added:
            subprocess.run(["git", "clone", "-q", "--no-checkout", str(ROOT), str(tree)],
                           check=True)
            subprocess.run(["git", "-C", str(tree), "checkout", "-q", "--detach", commit],
                           check=True)
        yield tree
    finally:
        if added:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                           capture_output=True)
        shutil.rmtree(tmp, ignore_errors=True)


def _children_cpu_s() -> float:
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return kids.ru_utime + kids.ru_stime


def timed_campaign(tree: Tree, entry: str, out: Path, options: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of ``cosim reproduce ENTRY --out OUT OPTIONS`` in ``tree``."""
    cpu, start = _children_cpu_s(), time.perf_counter()
    tree.run(tree.command("reproduce", entry, "--out", str(out), *options))
    return time.perf_counter() - start, _children_cpu_s() - cpu


@functools.cache
def parameter_defaults(fmu: Path) -> dict[str, Any]:
    """Parameter name -> its start value, typed (float, int, bool or str), of the FMU."""
    cast = {"Real": float, "Float64": float, "Integer": int, "Int32": int, "Int64": int,
            "Enumeration": int, "Boolean": lambda s: s in ("true", "1"), "String": str}
    return {v.name: cast[v.type](v.start) for v in read_model_description(str(fmu)).modelVariables
            if v.causality == "parameter" and v.start is not None and v.type in cast}


def changed_defaults(this_fmu: Path, base_fmu: Path) -> dict[str, Any]:
    """Parameter -> the baseline's default, for every parameter of both builds whose default
    differs."""
    this, base = parameter_defaults(this_fmu), parameter_defaults(base_fmu)
    return {name: base[name] for name in sorted(this.keys() & base.keys())
            if this[name] != base[name]}


def pins(entry_file: Path, base_root: Path) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """The baseline's entry with the baseline's defaults set in every ``[[runs]]``, and what was
    set: run name -> {"component.parameter": the baseline's default}. The run's scenario is
    this tree's (the one this tree will run); each component's Python build in this tree's
    ``fmus/`` is compared with the same file in the baseline's."""
    from cosim.run.scenario import load_scenario  # this tree's (the benchmark runs in it)

    @functools.cache
    def scenario_pins(name: str) -> dict[str, Any]:
        """"component.parameter" -> the baseline's default, of scenario ``name``."""
        pins: dict[str, Any] = {}
        for c in load_scenario(name).components.values():
            this, base = (root / "fmus" / f"{c.fmu}.fmu" for root in (ROOT, base_root))
            if this.is_file() and base.is_file():
                pins.update({f"{c.name}.{k}": v for k, v in changed_defaults(this, base).items()})
        return pins

    entry = tomllib.loads(entry_file.read_text())
    pinned: dict[str, dict[str, Any]] = {}
    for run in entry.get("runs", []):
        extra = {k: v for k, v in scenario_pins(run["scenario"]).items()
                 if k not in run.get("set", {})}
        if extra:
            run["set"] = {**extra, **run.get("set", {})}
            pinned[run["name"]] = extra
    return entry, pinned


def write_pinned(entry_file: Path, base_root: Path, folder: Path
                 ) -> tuple[Path, dict[str, dict[str, Any]]]:
    """The pinned copy of the baseline's entry (:func:`pins`), written as ``folder`` / the
    entry's file name (an entry is named by its file's stem), and what was set."""
    import tomli_w  # the test extra's; only this writes TOML (read back and compared)

    entry, pinned = pins(entry_file, base_root)
    text = tomli_w.dumps(entry)
    if tomllib.loads(text) != entry:
        raise RuntimeError(f"{entry_file}: the pinned copy does not read back as written")
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / entry_file.name
    path.write_text(text)
    return path, pinned


def claim_numbers(out: Path) -> dict[str, dict[str, str]]:
    """claim id -> {column: value} of :data:`NUMBERS` in a campaign's ``claims.csv``."""
    with open(out / "claims.csv", newline="") as f:
        return {r["id"]: {c: r[c] for c in NUMBERS if c in r} for r in csv.DictReader(f)}


def number_differences(this: dict[str, dict[str, str]], base: dict[str, dict[str, str]]
                       ) -> list[str]:
    """The claims of both trees whose :data:`NUMBERS` (the columns both write) differ."""
    return [claim for claim in sorted(this.keys() & base.keys())
            if not all(_same_number(this[claim][c], base[claim][c])
                       for c in this[claim].keys() & base[claim].keys())]


def _same_number(a: str, b: str) -> bool:
    """Two cells of claims.csv hold the same number (both empty or both NaN count as same)."""
    try:
        x, y = float(a or "nan"), float(b or "nan")
    except ValueError:
        return a == b
    return x == y or (x != x and y != y)


def verdicts(out: Path) -> dict[str, tuple[str, str]]:
    """claim id -> (verdict, "k of K") from a campaign's ``claims.csv``."""
    with open(out / "claims.csv", newline="") as f:
        return {r["id"]: (r["verdict"], f"{r['k']} of {r['K']}") for r in csv.DictReader(f)}


def verdict_differences(this: dict[str, tuple[str, str]], base: dict[str, tuple[str, str]]
                        ) -> list[dict[str, object]]:
    """The claims of both trees whose verdict or k of K differ between them."""
    return [{"id": claim, THIS: this[claim], BASE: base[claim]}
            for claim in sorted(this.keys() & base.keys()) if this[claim] != base[claim]]


def compare(entries: list[str], commit: str = BASELINE, seeds: int = SEEDS, repeat: int = 1,
            workers: int | None = None, rounding: bool = True, same_entry: bool = False
            ) -> dict[str, dict]:
    """Per entry: the medians of wall and CPU seconds per tree over ``repeat`` alternating
    pairs, the ratios baseline / this tree, and the verdicts compared by claim id
    (``same_entry``: this tree runs the baseline's entry file)."""
    options = ["--seeds", str(seeds)] + ([] if workers is None else ["--workers", str(workers)])
    this = Tree(ROOT, THIS)
    results: dict[str, dict] = {}
    with checkout(commit) as base_root, tempfile.TemporaryDirectory() as tmp:
        base = Tree(base_root, f"{BASE} {commit}")
        if not rounding:
            missing = [t.label for t in (this, base) if not t.has_option("reproduce",
                                                                         "--no-rounding")]
            if missing:
                raise SystemExit(f"--no-rounding: not an option of {', '.join(missing)}")
            options.append("--no-rounding")
        # what each tree's CLI is given for an entry: its name, or the baseline's entry file
        given = {(side, e): e for side in (THIS, BASE) for e in entries}
        builds: dict[str, list[str]] = {e: [] for e in entries}  # this tree's --build
        if same_entry and this.has_option("reproduce", "--build"):
            builds = {e: ["--build", this.entry_build(e)] for e in entries}
        for tree, side in ((this, THIS), (base, BASE)):
            tree.build(entries if same_entry else [given[side, e] for e in entries])
        pinned: dict[str, dict[str, dict[str, Any]]] = {e: {} for e in entries}
        if same_entry:  # the baseline's entry, its parameter defaults pinned (after the builds)
            for e in entries:
                path, pinned[e] = write_pinned(base.entry_file(e), base_root,
                                               Path(tmp) / "pinned" / e)
                given[THIS, e] = str(path)
        for entry in entries:
            times: dict[str, list[tuple[float, float]]] = {THIS: [], BASE: []}
            claims: dict[str, dict[str, tuple[str, str]]] = {}
            numbers: dict[str, dict[str, dict[str, str]]] = {}
            load_before = os.getloadavg()[0]
            for i in range(repeat):
                order = (base, this) if i % 2 == 0 else (this, base)
                for tree in order:
                    side = THIS if tree is this else BASE
                    out = Path(tmp) / f"{entry}_{side}_{i}"
                    extra = builds[entry] if side == THIS else []
                    times[side].append(timed_campaign(tree, given[side, entry], out,
                                                      options + extra))
                    claims.setdefault(side, verdicts(out))
                    numbers.setdefault(side, claim_numbers(out))
            wall = {s: statistics.median(w for w, _ in times[s]) for s in times}
            cpu = {s: statistics.median(c for _, c in times[s]) for s in times}
            diffs = verdict_differences(claims[THIS], claims[BASE])
            python_check = None
            if same_entry and builds[entry] == ["--build", "native"]:
                # the baseline runs Python builds: this tree once more on its Python builds
                # (after the timed pairs, not in the ratio) separates what the native builds
                # change (rounding) from what the tree changed since the baseline
                out = Path(tmp) / f"{entry}_{THIS}_python"
                time_python = timed_campaign(this, given[THIS, entry], out,
                                             options + ["--build", "python"])
                python_claims, python_numbers = verdicts(out), claim_numbers(out)
                from_native = verdict_differences(claims[THIS], python_claims)
                python_check = {
                    "wall_s": time_python[0], "cpu_s": time_python[1],
                    "verdict_differences_from_baseline": verdict_differences(python_claims,
                                                                             claims[BASE]),
                    "number_differences_from_baseline": number_differences(python_numbers,
                                                                           numbers[BASE]),
                    "verdict_differences_from_native": from_native,
                    "label_differences_from_native": sum(d[THIS][0] != d[BASE][0]
                                                         for d in from_native)}
            results[entry] = {
                "wall_s": wall, "cpu_s": cpu, "ratio_wall": wall[BASE] / wall[THIS],
                "ratio_cpu": cpu[BASE] / cpu[THIS],
                "claims": len(claims[THIS].keys() & claims[BASE].keys()),
                "same_verdicts": not diffs, "verdict_differences": diffs,
                "number_differences": number_differences(numbers[THIS], numbers[BASE]),
                "numbers_compared": [c for c in NUMBERS
                                     if all(any(c in row for row in numbers[side].values())
                                            for side in (THIS, BASE))],
                "pinned": pinned[entry], "python_check": python_check,
                "only_this": sorted(claims[THIS].keys() - claims[BASE].keys()),
                "only_baseline": sorted(claims[BASE].keys() - claims[THIS].keys()),
                "load_average": [load_before, os.getloadavg()[0]], "seeds": seeds,
                "repeat": repeat, "baseline": commit, "rounding": rounding,
                "same_entry": same_entry}
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default=BASELINE, help=f"commit (default {BASELINE})")
    parser.add_argument("--entries", nargs="+", default=list(ENTRIES))
    parser.add_argument("--seeds", type=int, default=SEEDS, help=f"K (default {SEEDS})")
    parser.add_argument("--repeat", type=int, default=1, help="pairs of runs per entry")
    parser.add_argument("--workers", type=int, default=None,
                        help="--workers of both CLIs (default: theirs)")
    parser.add_argument("--no-rounding", action="store_true",
                        help="no perturbed floating-point rerun, on both trees")
    parser.add_argument("--same-entry", action="store_true",
                        help="this tree runs the baseline's entry file (the same claims and "
                        "members on both trees)")
    args = parser.parse_args()
    results = compare(args.entries, args.baseline, args.seeds, args.repeat, args.workers,
                      not args.no_rounding, args.same_entry)
    for entry, r in results.items():
        print(f"{entry}{' (the baseline entry file on both)' if r['same_entry'] else ''} "
              f"K = {r['seeds']}: this tree {r['wall_s'][THIS]:.1f} s wall, "
              f"{r['cpu_s'][THIS]:.1f} s CPU; {args.baseline} {r['wall_s'][BASE]:.1f} s wall, "
              f"{r['cpu_s'][BASE]:.1f} s CPU; {args.baseline} / this: wall "
              f"{r['ratio_wall']:.2f}x, CPU {r['ratio_cpu']:.2f}x (target >= {TARGET:g}x); "
              f"load {r['load_average'][0]:.1f} -> {r['load_average'][1]:.1f}")
        print(f"  {r['claims']} claims on both trees, same verdicts and k of K: "
              f"{r['same_verdicts']}")
        for d in r["verdict_differences"]:
            print(f"  {d['id']}: this {d[THIS]}, {args.baseline} {d[BASE]}")
        print(f"  claims whose members' medians ({', '.join(r['numbers_compared'])}) differ: "
              f"{', '.join(r['number_differences']) or 'none'}")
        check = r["python_check"]
        if check is not None:
            print(f"  this tree on its Python builds (as the baseline; {check['wall_s']:.1f} s "
                  f"wall, not timed in the ratio): k of K or verdict differ from the "
                  f"baseline's in {len(check['verdict_differences_from_baseline'])} claims, "
                  f"medians in {len(check['number_differences_from_baseline'])}; from the "
                  f"native run's in {len(check['verdict_differences_from_native'])} claims, "
                  f"the verdict's label in {check['label_differences_from_native']}")
        for run, values in r["pinned"].items():
            print(f"  pinned in {run}: " + ", ".join(f"{k} = {v!r}" for k, v in values.items()))
        for side, label in (("only_this", "this tree"), ("only_baseline", args.baseline)):
            if r[side]:
                print(f"  claims of {label} only: {', '.join(r[side])}")


if __name__ == "__main__":
    main()
