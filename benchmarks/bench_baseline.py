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
the same k of K with other statistics. The baseline's entry names no build, so this tree runs
it with the build its own entry for that paper names (``--build``: seed 004's online twin has
no native model, so python there). The user's design cache
(``$ATO_COSIM_CACHE``) is shared by the trees as in any campaign. Asserts nothing;
``benchmarks/run_all.py --only baseline`` records the figures.

    python benchmarks/bench_baseline.py [--baseline COMMIT] [--entries seed000 seed004]
        [--seeds K] [--repeat R] [--workers N] [--no-rounding] [--same-entry]
"""

from __future__ import annotations

import argparse
import contextlib
import csv
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

ROOT = Path(__file__).resolve().parent.parent

BASELINE = "8a1e303"  # the default --baseline: the commit the campaigns are compared with
ENTRIES = ("seed000", "seed004")
SEEDS = 5  # K, report seeds per claim
TARGET = 5.0  # baseline time / this tree's time (this tree at most a fifth of the baseline)
THIS, BASE = "this", "baseline"

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
        if same_entry:
            given.update({(THIS, e): str(base.entry_file(e)) for e in entries})
            if this.has_option("reproduce", "--build"):  # the build this tree's entry names
                builds = {e: ["--build", this.entry_build(e)] for e in entries}
        for tree, side in ((this, THIS), (base, BASE)):
            tree.build([given[side, e] for e in entries])
        for entry in entries:
            times: dict[str, list[tuple[float, float]]] = {THIS: [], BASE: []}
            claims: dict[str, dict[str, tuple[str, str]]] = {}
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
            wall = {s: statistics.median(w for w, _ in times[s]) for s in times}
            cpu = {s: statistics.median(c for _, c in times[s]) for s in times}
            diffs = verdict_differences(claims[THIS], claims[BASE])
            results[entry] = {
                "wall_s": wall, "cpu_s": cpu, "ratio_wall": wall[BASE] / wall[THIS],
                "ratio_cpu": cpu[BASE] / cpu[THIS],
                "claims": len(claims[THIS].keys() & claims[BASE].keys()),
                "same_verdicts": not diffs, "verdict_differences": diffs,
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
        for side, label in (("only_this", "this tree"), ("only_baseline", args.baseline)):
            if r[side]:
                print(f"  claims of {label} only: {', '.join(r[side])}")


if __name__ == "__main__":
    main()
