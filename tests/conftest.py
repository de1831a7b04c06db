"""Shared fixtures: FMUs are built once per session (only those missing or out of date)."""

from __future__ import annotations

import pytest

from cosim.fmu.build import build_stale, catalog


@pytest.fixture(scope="session")
def built_fmus() -> dict:
    """Every catalog FMU, built and up to date: identifier -> FmuSpec (``.path``)."""
    build_stale()
    return catalog()


@pytest.fixture(scope="session")
def built_fmus_fmi3(built_fmus) -> dict:
    """Every catalog FMU's FMI 3.0 build, up to date: identifier -> FmuSpec (``.path_fmi3``)."""
    build_stale(fmi_version=3)
    return built_fmus

