"""Infeasible control is loud: a warning with the count and the first time, ``warnings`` in
summary.json, ``--strict`` turns a warning into exit status 1."""

from __future__ import annotations

import json
import re

from typer.testing import CliRunner

from cosim.cli import app
from cosim.run.simulate import run_scenario


def test_impossible_task_warns_and_strict_fails(built_fmus, tmp_path):
    """seed000 RMPC starting at 40 m/s (twice the design speed): the constraints cannot hold."""
    out = tmp_path / "run"
    result = CliRunner().invoke(app, ["run", "seed000_stop_rmpc", "--set", "plant.v0=40",
                                      "--out", str(out), "--no-plot", "--strict"])
    assert result.exit_code == 1, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is True and summary["qp_infeasible"] > 0
    (warning,) = summary["warnings"]
    match = re.match(r"controller: infeasible QP at (\d+) events, first by t = ([\d.]+) s",
                     warning)
    assert match and int(match[1]) == summary["qp_infeasible"], warning
    assert "warning: controller: infeasible QP at" in result.output


def test_a_clean_run_has_no_warnings(built_fmus):
    summary = run_scenario("seed000_stop_pid", build=False).summary
    assert summary["warnings"] == []
    # a stopping scenario is not judged by the CTCS-3 speed-tracking rule (seeds 001/004 are)
    assert "ctcs3_speed_error_ok" not in summary
