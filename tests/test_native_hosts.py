"""Every native FMU (each model of ``cosim.build.native.NATIVE``, FMI 2.0 and FMI 3.0) in
hosts without Python: the C hosts of tests/c_host in an empty environment with no libpython
loaded (the dynamic loader's own trace says which libraries it loaded), fmpy, libcosim (FMI
2), the compliance suite, fmpy's build from the FMU's sources, and the Windows binaries under
Wine (slow).

Every equality asserted here is exact: the hosts run the same binary (or, FMI 2 against FMI 3,
the same model sources compiled by the same compiler with the same flags, behind another front
that forwards every value unchanged) with the same libm in the same calling sequence, so the
IEEE results are the same."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.model_description import read_build_description
from matrix import by_model

from cosim.build.native import FMI_VERSIONS, NATIVE, build_natives, native_path

ROOT = Path(__file__).resolve().parents[1]
HOSTS = ROOT / "tests" / "c_host"
HEADERS = Path(fmpy.__file__).parent / "c-code"
IDENTIFIERS = sorted(NATIVE)
VERSIONS = FMI_VERSIONS
PLATFORM = {2: "linux64", 3: "x86_64-linux"}  # binaries/<...>/<id>.so
N_STEPS = 40


@pytest.fixture(scope="module")
def native(native_builds):
    """identifier -> {FMI version: path}, each model built once per test run (Linux binaries)."""
    return native_builds


def probe(md) -> tuple[dict[int, float], list[int]]:
    """The inputs a host holds: every Real input at the midpoint of its declared range, else at
    its start; the outputs it reads: every Real output (value references of the FMI 2 build,
    which the FMI 3 build keeps)."""
    inputs, outputs = {}, []
    for v in md.modelVariables:
        if v.type not in ("Real", "Float64"):
            continue
        if v.causality == "input":
            lo, hi = v.min, v.max
            inputs[v.valueReference] = (0.5 * (float(lo) + float(hi))
                                        if lo is not None and hi is not None
                                        else float(v.start or 0.0))
        elif v.causality == "output":
            outputs.append(v.valueReference)
    return inputs, outputs[:64]  # the hosts' limit


def step_size(md) -> float:
    return float(md.defaultExperiment.stepSize)


def fmpy_rows(path: Path, unzipdir: str) -> np.ndarray:
    """The FMI 2 build under fmpy, in the C hosts' calling sequence."""
    md = read_model_description(str(path))
    inputs, outputs = probe(md)
    h = step_size(md)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, instanceName="fmpy",
                    modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    if inputs:
        fmu.setReal(list(inputs), list(inputs.values()))
    fmu.exitInitializationMode()
    rows = []
    for k in range(N_STEPS):
        fmu.doStep(k * h, h)
        rows.append([(k + 1) * h, *fmu.getReal(outputs)])
    fmu.terminate()
    fmu.freeInstance()
    return np.array(rows)


def compile_host(source: str, out: Path, windows: bool = False) -> Path:
    cc = "x86_64-w64-mingw32-gcc" if windows else "gcc"
    cmd = [cc, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror", f"-I{HEADERS}", "-o", str(out),
           str(HOSTS / source)]
    if not windows:
        cmd[2:2] = ["-D_DEFAULT_SOURCE"]
        cmd += ["-ldl", "-lm"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out


@pytest.fixture(scope="module")
def hosts(c_hosts) -> dict[int, Path]:
    """FMI version -> its C host for Linux (the root conftest's ``c_hosts``)."""
    return {2: c_hosts("fmu_host"), 3: c_hosts("fmu3_host")}


def host_args(version: int, unzipdir: str, md2, token: str) -> list[str]:
    inputs, outputs = probe(md2)
    args = [unzipdir, md2.coSimulation.modelIdentifier, token, repr(step_size(md2)),
            str(N_STEPS)]
    if version == 3:
        args.append("0")  # eventModeUsed = false: the FMI 2 calling sequence
    return [*args, *[f"in:{vr}={value!r}" for vr, value in inputs.items()],
            *[f"out:{vr}" for vr in outputs]]


def parse_rows(stdout: str, version: int) -> np.ndarray:
    rows = np.array([[float(x) for x in line.split(",")] for line in stdout.split()])
    return rows[:, :-1] if version == 3 else rows  # the FMI 3 host adds nextEventTime


def run_bare(exe: Path, args: list[str], tmp: Path, env: dict[str, str] | None = None
             ) -> tuple[str, list[str]]:
    """Run a C host with an empty environment (``env -i``; ``env``: only these variables) but
    for the dynamic loader's trace (LD_DEBUG=libs, to a file in ``tmp``); returns its stdout
    and every library the loader initialised."""
    trace = tmp / "ld"
    done = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=120,
                          env={**(env or {}), "LD_DEBUG": "libs", "LD_DEBUG_OUTPUT": str(trace),
                               "FMU_HOST_PLAIN_EXIT": "1"})
    assert done.returncode == 0, done.stderr
    assert "freed" in done.stderr
    loaded = []
    for log in tmp.glob("ld.*"):
        for line in log.read_text().splitlines():
            if "calling init:" in line:
                loaded.append(line.split("calling init:", 1)[1].strip())
    return done.stdout, loaded


@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_c_hosts_run_both_builds_without_python(native, hosts, identifier, tmp_path):
    """The FMI 2 and FMI 3 hosts, started with no environment (no PYTHONPATH, no PYTHONHOME,
    no LD_PRELOAD), load the FMU's binary and no libpython; the FMI 2 host's results equal
    fmpy's, the FMI 3 host's the FMI 2 host's."""
    paths = native(identifier)
    md2 = read_model_description(str(paths[2]))
    md3 = read_model_description(str(paths[3]))
    assert md3.fmiVersion == "3.0" and md3.instantiationToken == md2.guid
    results = {}
    for version, path in paths.items():
        unzipdir = extract(str(path), unzipdir=str(tmp_path / f"fmi{version}"))
        log_dir = tmp_path / f"ld{version}"
        log_dir.mkdir()
        stdout, loaded = run_bare(hosts[version], host_args(version, str(unzipdir), md2, md2.guid),
                                  log_dir)
        binary = Path(unzipdir) / "binaries" / PLATFORM[version] / f"{identifier}.so"
        assert any(Path(lib).resolve() == binary.resolve() for lib in loaded), loaded
        assert not [lib for lib in loaded if "libpython" in lib], loaded
        results[version] = parse_rows(stdout, version)
        if version == 2:
            np.testing.assert_array_equal(results[2], fmpy_rows(path, unzipdir))
    assert results[2].shape == (N_STEPS, 1 + len(probe(md2)[1]))
    np.testing.assert_array_equal(results[3], results[2])


def test_the_loader_trace_lists_libpython_for_a_python_fmu(hosts, tmp_path):
    """The trace the test above reads does see libpython where it is loaded: our Python FMI 3
    build of the first native model, in the FMI 3 host, given only the PYTHONPATH it needs."""
    import site

    from cosim.build.python import build_stale, catalog

    spec = catalog()[IDENTIFIERS[0]]
    build_stale([spec], fmi_version=3)
    md = read_model_description(str(spec.path_fmi3))
    unzipdir = extract(str(spec.path_fmi3), unzipdir=str(tmp_path / "fmu"))
    _, loaded = run_bare(hosts[3], host_args(3, str(unzipdir), md, md.instantiationToken),
                         tmp_path, {"PYTHONPATH": os.pathsep.join([*site.getsitepackages(),
                                                                    str(ROOT)])})
    assert any("libpython" in Path(lib).name for lib in loaded), loaded


@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_fmpy_runs_the_fmi3_build_like_the_fmi2_build(native, identifier):
    """``fmpy.simulate_fmu`` with its defaults and the probe inputs: the same series."""
    paths = native(identifier)
    md = read_model_description(str(paths[2]))
    names = {v.valueReference: v.name for v in md.modelVariables}
    start = {names[vr]: value for vr, value in probe(md)[0].items()}
    two = fmpy.simulate_fmu(str(paths[2]), start_values=start)
    three = fmpy.simulate_fmu(str(paths[3]), start_values=start)
    assert two.dtype.names == three.dtype.names and len(two) > 1
    for name in two.dtype.names:
        np.testing.assert_array_equal(three[name], two[name], err_msg=name)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_compliance_suite_passes(native, identifier, version):
    """cosim.interop.compliance (what ``cosim validate --native --fmi all`` runs), strict: no
    error and no warning, for every native model in both FMI versions (the one place each
    native build's compliance is asserted; the command itself:
    test_cli_validates_native_builds_of_both_versions)."""
    from cosim.interop.compliance import ERROR, WARNING, check_fmu, format_report

    path = native(identifier)[version]
    problems = check_fmu(path)
    assert not [p for p in problems if p.severity in (ERROR, WARNING)], \
        format_report(path, problems)
    assert (f"FMI {version}.0" in format_report(path, problems))


def _shipped_scenario(identifier: str) -> tuple[Path, str] | None:
    """The first shipped scenario (by name) with a component of FMU ``identifier``."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]
    from cosim.run.scenario import scenario_files

    for path in scenario_files().values():
        for name, spec in tomllib.loads(path.read_text()).get("fmus", {}).items():
            if spec.get("fmu") == identifier:
                return path, name
    return None


@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_libcosim_runs_the_fmi2_build_in_a_shipped_loop(native, identifier):
    """The first shipped scenario that uses the model, with the native FMU in its place
    (first 20 s): libcosim's fixed-step master gives our master's Jacobi run of the same FMUs
    exactly (both deliver every output to the next step unchanged). libcosim runs in this
    process (``isolated=False``, the same frame as in its child: tests/test_other_masters.py
    tests the child)."""
    from cosim.build.python import build_stale, catalog
    from cosim.interop.libcosim import compare_frames, run_libcosim
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import run_scenario

    found = _shipped_scenario(identifier)
    if found is None:
        pytest.skip(f"no shipped scenario uses {identifier}")
    path, component = found
    sc = load_scenario(path, {f"{component}.fmu": str(native(identifier)[2]),
                              "simulation.stop_time": 20.0})
    others = {c.fmu for c in sc.components.values() if c.name != component}
    build_stale([catalog()[name] for name in others if name in catalog()])
    theirs = run_libcosim(sc, isolated=False)
    ours = run_scenario(sc, algorithm="jacobi", plot=False).frame
    diffs = compare_frames(ours, theirs)
    assert diffs and not theirs.drop(columns="time").isna().to_numpy().any()
    h = sc.simulation.base_step or sc.simulation.output_interval
    assert len(theirs) == round(sc.simulation.stop_time / h)
    assert max(diffs.values()) == 0.0, diffs


TIMING_KEYS = ("wall_time", "real_time_factor", "fmu_wall", "solve_time")  # clock readings


@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_shipped_loop_with_the_fmi3_build_equals_the_fmi2_build(native, identifier):
    """The same shipped scenario (first 20 s) under our master: with ``fmi_version = 3`` and
    the native FMI 3 build in the model's place (the other components' FMI 3 builds, Event
    Mode for the controllers) the recorded series and the summary equal the FMI 2 run's; only
    the wall-clock figures differ."""
    from cosim.build.python import build_stale, catalog
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import run_scenario

    found = _shipped_scenario(identifier)
    if found is None:
        pytest.skip(f"no shipped scenario uses {identifier}")
    path, component = found
    runs = {}
    for version in VERSIONS:
        sc = load_scenario(path, {f"{component}.fmu": str(native(identifier)[version]),
                                  "simulation.stop_time": 20.0,
                                  "simulation.fmi_version": version})
        build_stale([catalog()[c.fmu] for c in sc.components.values()
                     if c.name != component and c.fmu in catalog()], fmi_version=version)
        runs[version] = run_scenario(sc, plot=False)
    two, three = runs[2], runs[3]
    assert two.completed and three.completed
    assert three.frame.equals(two.frame)
    assert ({k: v for k, v in three.summary.items() if not any(t in k for t in TIMING_KEYS)}
            == {k: v for k, v in two.summary.items() if not any(t in k for t in TIMING_KEYS)})


@pytest.mark.parametrize("version", [pytest.param(2, marks=pytest.mark.slow), 3])
@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_sources_build_with_fmpy_and_run_the_same(native, identifier, version, tmp_path):
    """``sources/`` is complete: fmpy's build (CMake, from buildDescription.xml, without our
    compiler options) compiles it into a binary whose results equal ours (the x86-64 baseline
    has no fused multiply-add to contract to, and nothing reassociates without fast math)."""
    from fmpy.build import build_platform_binary

    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed: fmpy cannot build from sources")
    path = native(identifier)[version]
    (config,) = read_build_description(str(path))  # validated against the FMI 3.0 schema
    assert config.modelIdentifier == identifier
    unzipdir = Path(extract(str(path), unzipdir=str(tmp_path / "fmu")))
    listed = [f for s in config.sourceFileSets for f in s.sourceFiles]
    assert listed and all((unzipdir / "sources" / f).is_file() for f in listed)
    ours = fmpy.simulate_fmu(str(unzipdir), start_values={})
    shutil.rmtree(unzipdir / "binaries")
    (tmp_path / "build").mkdir()
    build_platform_binary(unzipdir, build_dir=tmp_path / "build")
    theirs = fmpy.simulate_fmu(str(unzipdir), start_values={})
    for name in ours.dtype.names:
        np.testing.assert_array_equal(theirs[name], ours[name], err_msg=name)


@pytest.mark.slow
@pytest.mark.parametrize("identifier", by_model(IDENTIFIERS))
def test_windows_binaries_under_wine(identifier, tmp_path):
    """binaries/win64/<id>.dll (FMI 2) and binaries/x86_64-windows/<id>.dll (FMI 3), built with
    mingw-w64, loaded and stepped under Wine by the C hosts built with mingw
    (tests/c_host/fmu_host_win.c, tests/c_host/fmu3_host.c). The FMI 3 DLL gives the FMI 2
    DLL's results exactly (same model code and libm); against the Linux binary the results
    differ only by the libms' rounding of transcendental functions, reported here and bounded
    for BrakeDelayTrain in tests/test_native_fmu.py."""
    for tool in ("x86_64-w64-mingw32-gcc", "wine"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} not installed (apt-get install mingw-w64 wine64): the Windows "
                        "binaries are not run")
    paths = dict(zip(VERSIONS, build_natives(identifier, VERSIONS, tmp_path / "fmu",
                                             windows=True)))
    md2 = read_model_description(str(paths[2]))
    exes = {2: compile_host("fmu_host_win.c", tmp_path / "host2.exe", windows=True),
            3: compile_host("fmu3_host.c", tmp_path / "host3.exe", windows=True)}
    rows = {}
    for version, path in paths.items():
        unzipdir = extract(str(path), unzipdir=str(tmp_path / f"fmi{version}"))
        windows_dir = "Z:" + str(unzipdir).replace("/", "\\")
        done = subprocess.run(["wine", str(exes[version]),
                               *host_args(version, windows_dir, md2, md2.guid)],
                              capture_output=True, text=True, timeout=600,
                              env=dict(os.environ, WINEDEBUG="-all"))
        assert done.returncode == 0, done.stderr
        rows[version] = parse_rows(done.stdout, version)
        if version == 2:
            linux = fmpy_rows(path, unzipdir)
    assert rows[2].shape == (N_STEPS, 1 + len(probe(md2)[1]))
    np.testing.assert_array_equal(rows[3], rows[2])
    assert np.isfinite(rows[2]).all() == np.isfinite(linux).all()
    np.testing.assert_array_equal(rows[2][:, 0], linux[:, 0])
    scale = np.maximum(np.abs(linux[:, 1:]), np.finfo(float).tiny)
    ulps = np.abs(rows[2][:, 1:] - linux[:, 1:]) / (scale * np.finfo(float).eps)
    print(f"{identifier}: Windows against Linux, largest difference {np.nanmax(ulps):.3g} ulp")


def _cosim(*args: str) -> subprocess.CompletedProcess:
    import sys

    return subprocess.run([sys.executable, "-m", "cosim.cli", *args], capture_output=True,
                          text=True, timeout=600, cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))


def test_cli_validates_native_builds_of_both_versions():
    """``cosim validate --native --fmi all ID`` checks fmus/native/ID.fmu with the FMI 2.0
    checks and fmus/native/fmi3/ID.fmu with the FMI 3.0 ones (building what is missing)."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    identifier = IDENTIFIERS[0]
    done = _cosim("validate", "--native", "--fmi", "all", identifier)
    assert done.returncode == 0, done.stdout + done.stderr
    reports = re.split(r"^FMU ", done.stdout, flags=re.M)[1:]
    assert [r.split()[0] for r in reports] == [str(native_path(identifier, 2)),
                                               str(native_path(identifier, 3))]
    assert "[FMI 2.0.4" in reports[0] and "fmi3-event-mode" in reports[1]
    assert all("PASSED: 0 error(s), 0 warning(s)" in r for r in reports)


@pytest.mark.parametrize("args,message", [
    (("build", "--native", "--fmi", "4"), "--fmi '4': expected one of 2, 3, all"),
    (("validate", "--native", "NoSuchTrain"), "no native model of 'NoSuchTrain'; native: "),
    (("build", "--native", "NoSuchTrain"), "no native model of 'NoSuchTrain'; native: "),
])
def test_cli_native_errors_name_the_value(monkeypatch, args, message):
    from tests.cli_inproc import cosim_inproc

    monkeypatch.chdir(ROOT)
    done = cosim_inproc(*args)
    assert done.exit_code == 2
    assert message in done.stderr.replace("\n", " "), done.stderr


def test_windows_build_without_mingw_names_it(monkeypatch, tmp_path):
    import cosim.build.native as nb

    real = shutil.which
    monkeypatch.setattr(nb.shutil, "which", lambda name: None if name == nb.WINDOWS_CC
                        else real(name))
    if real(nb.LINUX_CC) is None:
        pytest.skip("gcc not installed")
    with pytest.raises(nb.CompilerMissing, match=r"'x86_64-w64-mingw32-gcc'.*mingw-w64"):
        build_natives(IDENTIFIERS[0], dest=tmp_path, windows=True)
    with pytest.raises(ValueError, match=r"fmi_version 4: expected one of \[2, 3\]"):
        build_natives(IDENTIFIERS[0], (2, 4), dest=tmp_path)
    assert not list(tmp_path.iterdir())  # refused before anything was written


def test_building_several_refuses_before_writing(monkeypatch, tmp_path):
    """build_all_natives (what ``cosim build --native`` calls) names the missing compiler, the
    unknown model and the unknown FMI version before any model is built."""
    import cosim.build.native as nb

    real = shutil.which
    monkeypatch.setattr(nb.shutil, "which", lambda name: None if name == nb.LINUX_CC
                        else real(name))
    with pytest.raises(nb.CompilerMissing, match=r"'gcc'.*apt-get install gcc"):
        nb.build_all_natives(IDENTIFIERS, dest=tmp_path)
    monkeypatch.setattr(nb.shutil, "which", real)
    with pytest.raises(ValueError, match=r"no native model of 'NoSuchTrain'"):
        nb.build_all_natives([IDENTIFIERS[0], "NoSuchTrain"], dest=tmp_path)
    with pytest.raises(ValueError, match=r"fmi_version 4: expected one of \[2, 3\]"):
        nb.build_all_natives(IDENTIFIERS, (2, 4), dest=tmp_path)
    assert not list(tmp_path.iterdir())


def test_fmi3_packaging_refuses_an_fmu_without_our_fmi2_front(tmp_path):
    """package_fmi3 derives from our native FMI 2 FMUs only, and says which file is missing."""
    import zipfile

    from cosim.build.native import package_fmi3

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed")

    other = tmp_path / "Other.fmu"
    with zipfile.ZipFile(other, "w") as z:
        z.writestr("modelDescription.xml",
                   '<fmiModelDescription fmiVersion="2.0" modelName="Other" guid="{0}">'
                   '<CoSimulation modelIdentifier="Other"/><ModelVariables/>'
                   "</fmiModelDescription>")
        z.writestr("binaries/linux64/Other.so", b"")
        z.writestr("sources/model.c", "int x;\n")
    with pytest.raises(ValueError, match=r"Other.fmu: no sources/fmi2_front.c"):
        package_fmi3(other, tmp_path / "out.fmu", windows=False)
    assert not (tmp_path / "out.fmu").exists()


def test_build_key_native_in_fmi3_builds_and_runs_the_native_fmi3_fmu():
    """``[fmus.NAME] build = "native"`` with ``fmi_version = 3`` resolves to
    fmus/native/fmi3/<Id>.fmu, builds it when stale, and runs as the FMI 2 native loop does
    (first 5 s of the first shipped scenario of the first native model)."""
    from cosim.run.scenario import load_scenario
    from cosim.run.simulate import run_scenario

    if shutil.which("gcc") is None:
        pytest.skip("gcc not installed: native FMUs cannot be built")
    found = _shipped_scenario(IDENTIFIERS[0])
    if found is None:
        pytest.skip(f"no shipped scenario uses {IDENTIFIERS[0]}")
    path, component = found
    runs = {}
    for version in VERSIONS:
        sc = load_scenario(path, [f"{component}.build=native", "simulation.stop_time=5.0",
                                  f"simulation.fmi_version={version}"])
        assert sc.components[component].fmu_path == native_path(IDENTIFIERS[0], version)
        runs[version] = run_scenario(sc, plot=False)
        assert native_path(IDENTIFIERS[0], version).is_file()
    assert runs[3].frame.equals(runs[2].frame)
