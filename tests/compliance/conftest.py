"""Fixtures of the compliance suite: compliance results cached per FMU, the broken FMU."""

from __future__ import annotations

from pathlib import Path

import pytest

from cosim.interop.compliance import Options, check_fmu

HERE = Path(__file__).resolve().parent


@pytest.fixture(scope="session")
def compliance_results(built_fmus):
    """identifier -> problems, computed once per FMU on first use."""
    cache: dict[str, list] = {}

    def results(identifier: str) -> list:
        if identifier not in cache:
            cache[identifier] = check_fmu(built_fmus[identifier].path)
        return cache[identifier]

    return results


@pytest.fixture(scope="session")
def broken_fmu(tmp_path_factory) -> Path:
    """tests/compliance/broken_train.py built as an FMU (plain pythonfmu, planted faults)."""
    from pythonfmu.builder import FmuBuilder

    dest = tmp_path_factory.mktemp("broken") / "BrokenTrain.fmu"
    return Path(FmuBuilder.build_FMU(HERE / "broken_train.py", dest=dest))


@pytest.fixture(scope="session")
def broken_results(broken_fmu):
    # a short call limit: the planted (blocked) hang costs twice this much of a free core once
    return check_fmu(broken_fmu, Options(call_timeout=1.0))
