"""benchmarks/bench_baseline.py's same-entry copy: the baseline's parameter defaults set where
the two trees' builds differ, and the claims' numbers compared as numbers."""

from __future__ import annotations

import re
import sys
import zipfile
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import bench_baseline  # noqa: E402

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]


def _with_start(source: Path, dest: Path, variable: str, start: str) -> Path:
    """A copy of the FMU ``source`` whose ``variable`` has the start value ``start``."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(dest, "w") as new:
        for item in old.infolist():
            data = old.read(item)
            if item.filename == "modelDescription.xml":
                text, n = re.subn(rf'(name="{variable}"[^>]*>\s*<Real[^>]*start=")[^"]*',
                                  rf"\g<1>{start}", data.decode())
                assert n == 1
                data = text.encode()
            new.writestr(item, data)
    return dest


def test_the_copy_sets_the_baselines_defaults_where_the_builds_differ(built_fmus, tmp_path):
    """A run without its own value of a parameter whose default differs gets the baseline's;
    a run's own ``set`` wins; a component whose FMU the baseline lacks is left alone."""
    this = built_fmus["EmuMfac3"].path
    base_root = tmp_path / "base"
    _with_start(this, base_root / "fmus" / this.name, "delta", "0.25")
    defaults = bench_baseline.parameter_defaults(this)
    assert defaults["delta"] != 0.25
    assert bench_baseline.changed_defaults(this, base_root / "fmus" / this.name) == {
        "delta": 0.25}
    entry = tmp_path / "old" / "seed001.toml"
    entry.parent.mkdir()
    entry.write_text('title = "t"\n\n[[runs]]\nname = "a"\nscenario = "seed001_emu_mfac"\n\n'
                     '[[runs]]\nname = "b"\nscenario = "seed001_emu_mfac"\n'
                     'set = { "controller.delta" = 5.0 }\n')
    path, pinned = bench_baseline.write_pinned(entry, base_root, tmp_path / "pinned")
    assert path.name == "seed001.toml"  # an entry is named by its file's stem
    assert pinned == {"a": {"controller.delta": 0.25}}
    runs = tomllib.loads(path.read_text())["runs"]
    assert runs[0]["set"] == {"controller.delta": 0.25}
    assert runs[1]["set"] == {"controller.delta": 5.0}


def test_claim_numbers_compare_as_numbers() -> None:
    same = bench_baseline._same_number
    assert same("0.5", "5e-1") and same("", "") and same("nan", "") and same("n/a", "n/a")
    assert not same("0.5", "0.5000000000000001") and not same("1", "")
    this = {"c1": {"median": "1.0", "a_median": "2"}, "c2": {"median": "3"}}
    base = {"c1": {"median": "1", "a_median": "2.0", "worst": "9"}, "c2": {"median": "4"},
            "c3": {"median": "0"}}
    assert bench_baseline.number_differences(this, base) == ["c2"]
