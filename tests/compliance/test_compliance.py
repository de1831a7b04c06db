"""FMI 2.0 compliance of every FMU the catalog builds (new FMUs are covered automatically),
and of all of them loaded together in one process."""

from __future__ import annotations

import pytest

from cosim.build.python import catalog
from cosim.interop.compliance import ALL_CHECKS, ERROR, Options, check_together, format_report
from tests.matrix import by_model

IDENTIFIERS = sorted(catalog())


@pytest.mark.parametrize("check", ALL_CHECKS)
@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_fmu_passes_check(identifier, check, compliance_results, built_fmus):
    problems = compliance_results(identifier)
    errors = [p for p in problems if p.check == check and p.severity == ERROR]
    assert not errors, format_report(built_fmus[identifier].path, problems)
    # every finding belongs to a check of the parametrisation (so none goes unseen)
    assert {p.check for p in problems} <= set(ALL_CHECKS), problems


def test_all_fmus_together_in_one_process(built_fmus):
    paths = [built_fmus[i].path for i in IDENTIFIERS]
    # each FMU twice: two instances of one FMU among all the others
    problems = check_together(paths + paths, Options(n_steps=20))
    assert not problems, "\n".join(map(str, problems))
