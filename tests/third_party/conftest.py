"""The C test FMUs of tests/third_party, built once per test session."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from third_party_fmus import build_all


@pytest.fixture(scope="session")
def c_fmus(tmp_path_factory) -> dict[str, Path]:
    """Name -> path of every C test FMU (gcc + fmpy's FMI 2 headers), built once."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: the C test FMUs cannot be built")
    return build_all(tmp_path_factory.mktemp("c_fmus"))


@pytest.fixture(scope="session")
def c_fmus3(tmp_path_factory) -> dict[str, Path]:
    """Name -> path of every C FMI 3.0 test FMU (gcc + fmpy's FMI 3 headers), built once."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: the C test FMUs cannot be built")
    from third_party_fmus3 import build_all3

    return build_all3(tmp_path_factory.mktemp("c_fmus3"))


@pytest.fixture(scope="session")
def hostile_fmus(tmp_path_factory) -> dict[str, Path]:
    """Name -> path of every hostile C test FMU (third_party_fmus.HOSTILE), built once."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: the C test FMUs cannot be built")
    from third_party_fmus import build_hostile

    return build_hostile(tmp_path_factory.mktemp("hostile_fmus"))


@pytest.fixture(scope="session")
def reference_clocks(tmp_path_factory) -> Path:
    """The Modelica Reference FMU Clocks (FMI 3.0 Scheduled Execution), built with gcc from
    the Reference-FMUs sources (github.com/modelica/Reference-FMUs, a checkout or its git
    directory) named by the environment variable REFERENCE_FMUS_SOURCE."""
    import os

    source = os.environ.get("REFERENCE_FMUS_SOURCE")
    if not source or not Path(source).is_dir():
        pytest.skip("REFERENCE_FMUS_SOURCE does not name the Reference-FMUs sources")
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: the Reference FMUs cannot be built")
    from third_party_fmus3 import build_reference

    return build_reference("Clocks", Path(source), tmp_path_factory.mktemp("reference"))
