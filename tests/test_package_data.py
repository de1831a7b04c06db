"""An installed (non-editable) package carries every file its code reads beside its modules:
each tracked non-Python file under the packages (``cosim``, ``plants``, ``controllers``) matches
a ``[tool.setuptools.package-data]`` pattern of ``pyproject.toml``, so a wheel holds it (the C
sources and headers the native builder copies into an FMU's ``sources/``, the routes, the
data tables)."""

from __future__ import annotations

import fnmatch
import subprocess
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTATION = {".md"}  # read by people in the repository, not by the code


def test_every_file_the_packages_read_is_package_data() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    patterns = config["package-data"]["*"]
    listed = subprocess.run(["git", "ls-files", "cosim", "plants", "controllers"], cwd=ROOT,
                            capture_output=True, text=True)
    if listed.returncode != 0:
        pytest.skip("not a git checkout: the tracked files are unknown")
    files = [Path(f) for f in listed.stdout.split()]
    data = [f for f in files if f.suffix not in {".py", *DOCUMENTATION}]
    assert any(f.suffix == ".h" for f in data)  # the native builder's headers are among them
    missing = [f.as_posix() for f in data
               if not any(fnmatch.fnmatch(f.name, p) for p in patterns)]
    assert not missing, f"pyproject.toml package-data '*' lacks a pattern for {missing}"
