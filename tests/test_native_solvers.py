"""The solvers' C sources of the native FMUs (cosim/build/solvers.py): taken from the
registry's source distribution at the installed version, never from the repository; a model
that links one ships its sources and licence; the C build solves as the Python wheel does."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from dataclasses import replace
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest

from cosim.build import native as native_build
from cosim.build import solvers as native_solvers
from cosim.build.solvers import SOLVERS, SolverUnavailable, solver_files

ROOT = Path(__file__).resolve().parents[1]


def _daqp_files():
    try:
        return solver_files("daqp")
    except SolverUnavailable as err:  # no registry reachable and nothing cached
        pytest.skip(str(err).splitlines()[0])


def test_no_solver_source_is_in_the_repository():
    """What the native builds take from the sdists is never committed."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout.split()
    names = {Path(t).name for t in tracked}
    files = _daqp_files()
    assert not names & {f.name for f in files.sources if f.name != "CMakeLists.txt"}


def test_daqp_sources_are_the_installed_release_with_its_mit_licence():
    from importlib import metadata

    files = _daqp_files()
    assert files.version == metadata.version("daqp")
    assert {"daqp.c", "api.c", "api.h", "types.h"} <= {f.name for f in files.sources}
    assert "MIT License" in files.license.read_text()
    record = files.license.parent.parent / f"daqp-{files.version}.tar.gz.sha256"
    assert record.read_text().split()[0] == native_solvers._sha256(
        record.with_name(f"daqp-{files.version}.tar.gz"))


def test_a_failed_download_names_the_package_and_the_command(tmp_path, monkeypatch):
    monkeypatch.setenv("ATO_COSIM_CACHE", str(tmp_path))
    failing = [sys.executable, "-c", "import sys; sys.exit('no network')"]
    monkeypatch.setattr(native_solvers.SolverSource, "download_command",
                        lambda self, dest: failing)
    with pytest.raises(SolverUnavailable) as err:
        solver_files("daqp")
    text = str(err.value)
    assert "daqp" in text and " ".join(failing) in text and "no network" in text


def test_a_changed_sdist_is_refused(tmp_path, monkeypatch):
    files = _daqp_files()
    folder = files.license.parent.parent
    monkeypatch.setenv("ATO_COSIM_CACHE", str(tmp_path))
    copy = tmp_path / "solvers" / folder.name
    copy.mkdir(parents=True)
    archive = f"daqp-{files.version}.tar.gz"
    (copy / archive).write_bytes((folder / archive).read_bytes() + b"\0")
    shutil.copy2(folder / f"{archive}.sha256", copy)
    with pytest.raises(SolverUnavailable, match="SHA-256"):
        solver_files("daqp")


HARNESS = r"""
#include <stdio.h>
#include <stdlib.h>
#include "api.h"
int main(void) {
    int n, m, ms, i;
    if (scanf("%d %d %d", &n, &m, &ms) != 3) return 2;
    double *H = malloc(sizeof(double) * n * n), *f = malloc(sizeof(double) * n);
    double *A = malloc(sizeof(double) * (m - ms) * n + 1);
    double *bu = malloc(sizeof(double) * m), *bl = malloc(sizeof(double) * m);
    double *x = malloc(sizeof(double) * n), *lam = malloc(sizeof(double) * m);
    int* sense = calloc(m, sizeof(int));
    for (i = 0; i < n * n; i++) scanf("%lf", &H[i]);
    for (i = 0; i < n; i++) scanf("%lf", &f[i]);
    for (i = 0; i < (m - ms) * n; i++) scanf("%lf", &A[i]);
    for (i = 0; i < m; i++) scanf("%lf", &bu[i]);
    for (i = 0; i < m; i++) scanf("%lf", &bl[i]);
    DAQPProblem qp = {n, m, ms, H, f, A, bu, bl, sense, NULL, 0, 0};
    DAQPSettings settings;
    daqp_default_settings(&settings);
    DAQPResult res = {x, lam, 0, 0, 0, 0, 0, 0, 0};
    daqp_quadprog(&res, &qp, &settings);
    printf("%d\n", res.exitflag);
    for (i = 0; i < n; i++) printf("%a\n", x[i]);
    return 0;
}
"""


def test_daqp_built_with_the_native_flags_solves_as_the_python_wheel(tmp_path):
    """A QP with active bounds and rows: the C build of the sdist and the wheel agree to the
    solver's tolerances (primal_tol on the active constraints' residual, scaled by the
    condition number of H for the solution)."""
    import daqp

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed")
    files = _daqp_files()
    src = tmp_path / "src"
    src.mkdir()
    for f in files.sources:
        shutil.copy2(f, src)
    (src / "harness.c").write_text(HARNESS)
    exe = tmp_path / "harness"
    subprocess.run(["gcc", *native_build.CC_FLAGS, f"-I{src}", "-o", str(exe),
                    *sorted(str(p) for p in src.glob("*.c")), "-lm"], check=True)
    rng = np.random.default_rng(3)
    n, rows, ms = 6, 5, 6
    M = rng.standard_normal((n, n))
    H = M @ M.T + n * np.eye(n)
    f = 10.0 * rng.standard_normal(n)
    A = rng.standard_normal((rows, n))
    bu = np.concatenate([np.full(ms, 0.5), np.full(rows, 0.3)])
    bl = -bu
    text = " ".join(str(v) for v in (n, n + rows, ms)) + "\n" + " ".join(
        repr(float(v)) for v in np.concatenate([H.ravel(), f, A.ravel(), bu, bl]))
    out = subprocess.run([str(exe)], input=text, capture_output=True, text=True,
                         check=True).stdout.split()
    x_py, _, flag_py, _ = daqp.solve(H, f, A, bu, bl, np.zeros(n + rows, dtype=np.int32))
    assert int(out[0]) == flag_py == 1
    x_c = np.array([float.fromhex(v) for v in out[1:]])
    # both are the exact KKT point of the same active set up to rounding: the difference is
    # bounded by cond(H) eps |x| per factorisation step, n of them, plus the primal tolerance
    tol = np.linalg.cond(H) * n * np.finfo(float).eps * (1.0 + np.abs(x_py).max()) + \
        daqp.Model().settings["primal_tol"]
    assert np.abs(x_c - x_py).max() <= tol
    unconstrained = np.linalg.solve(H, -f)  # outside the box: constraints are active
    assert np.abs(unconstrained).max() > 0.5 or np.abs(A @ unconstrained).max() > 0.3


def test_a_native_fmu_linking_daqp_ships_its_sources_and_licence(tmp_path, monkeypatch):
    """A model whose spec names DAQP (here StopPid's, with the solver added) carries the
    solver's C files in sources/ and buildDescription.xml, its licence under
    documentation/licenses, and builds and runs."""
    from fmpy import simulate_fmu

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed")
    files = _daqp_files()
    spec = replace(native_build.NATIVE["StopPid"], solvers=("daqp",))
    monkeypatch.setitem(native_build.NATIVE, "StopPid", spec)
    path = native_build.build_native("StopPid", dest=tmp_path, windows=False)
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
        described = ElementTree.fromstring(z.read("sources/buildDescription.xml"))
        licence = z.read("documentation/licenses/daqp-LICENSE.txt").decode()
    listed = {e.get("name") for e in described.iter("SourceFile")}
    c_files = {f.name for f in files.sources if f.suffix == ".c"}
    assert c_files <= listed
    assert {f"sources/{f.name}" for f in files.sources} <= names
    assert licence == files.license.read_text()
    assert "binaries/linux64/StopPid.so" in names
    result = simulate_fmu(str(path), stop_time=1.0, output_interval=0.2)
    assert np.all(np.isfinite(result["brake_command"]))
    assert set(SOLVERS) == {"daqp"}
