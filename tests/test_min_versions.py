"""The declared minimum versions (pyproject.toml) are the ones CI installs and tests
(.ci/constraints-min.txt, `.ci/run` second step)."""

from __future__ import annotations

import re
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parents[1]


def test_ci_pins_exactly_the_declared_minimums():
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    floors = {}
    for dep in deps:
        match = re.match(r"([A-Za-z0-9_.-]+)>=([0-9][0-9A-Za-z.]*)", dep)
        if match and "python_version" not in dep:
            floors[match[1].lower()] = match[2]
    pins = {}
    for line in (ROOT / ".ci" / "constraints-min.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, _, version = line.partition("==")
            pins[name.strip().lower()] = version.strip()
    assert pins == {name: _three(v) for name, v in floors.items()}, (floors, pins)
    assert ".ci/run-min-versions" in (ROOT / ".ci" / "run").read_text()


def _three(version: str) -> str:
    parts = version.split(".")
    return ".".join(parts + ["0"] * (3 - len(parts)))
