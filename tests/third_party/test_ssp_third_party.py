"""SSP export of scenarios with third-party FMUs: every FMI 2.0 type (Enumeration items in
ssd:Enumerations, values by item name), no empty ssd:Connections, and the scenario checked
against its FMUs as ``cosim run`` does. Every SSD is validated against the SSP 1.0 schema."""

from __future__ import annotations

import zipfile

import pytest
from fmpy.ssp.ssd import read_ssd
from test_master_third_party import write_scenario

from cosim.interop.ssp import export_ssp
from cosim.run.scenario import ScenarioError


def test_every_type_exports_and_validates(c_fmus, tmp_path):
    f = c_fmus["AllTypes"]
    conn = {"B.u": "A.y", "B.ui": "A.yi", "B.mode": "A.next_mode", "B.ub": "A.yb",
            "B.us": "A.ys"}
    path = write_scenario(tmp_path, {"A": (f, {"label": "a", "offset": 3, "invert": True,
                                               "level": 2},
                                           {"mode": "fast", "u": 1.0, "ui": 2, "ub": True,
                                            "us": "z"}),
                                     "B": (f, {}, {})}, conn)
    out = export_ssp(path, tmp_path / "types.ssp", build=False)
    ssd = read_ssd(str(out), validate=True)  # raises on a schema violation
    assert len(ssd.system.connections) == 5
    xml = zipfile.ZipFile(out).read("SystemStructure.ssd").decode()
    assert '<ssc:Item name="fast" value="3" />' in xml
    assert '<ssv:Enumeration value="fast" name="Mode" />' in xml  # input constant, by name
    assert '<ssv:Enumeration value="normal" name="Mode" />' in xml  # parameter given as 2
    assert '<ssv:String value="a" />' in xml and '<ssv:Integer value="3" />' in xml
    assert '<ssc:Enumeration name="Mode" />' in xml


def test_no_connections_writes_no_empty_element(c_fmus, tmp_path):
    path = write_scenario(tmp_path, {"e": (c_fmus["Events"], {}, {"u": 1.0})})
    out = export_ssp(path, tmp_path / "alone.ssp", build=False)
    read_ssd(str(out), validate=True)
    assert b"Connections" not in zipfile.ZipFile(out).read("SystemStructure.ssd")


@pytest.mark.parametrize("fmus, connections, message", [
    ({"e": ("Events", {})}, {}, r"input e.u is not connected \(\[simulation\] unconnected"),
    ({"f": ("Feedthrough", {})}, {"f.u": "f.y"}, "algebraic loop"),
    ({"a": ("AllTypes", {"mode": "fastest"})}, {}, "'fastest' is not one of its items"),
])
def test_export_checks_the_scenario_like_run(c_fmus, tmp_path, fmus, connections, message):
    path = write_scenario(tmp_path, {n: (c_fmus[f], {}, i) for n, (f, i) in fmus.items()},
                          connections)
    with pytest.raises(ScenarioError, match=message):
        export_ssp(path, tmp_path / "bad.ssp", ["simulation.unconnected_inputs=error"],
                   build=False)
    assert not (tmp_path / "bad.ssp").exists()


def test_an_fmi3_component_is_refused_not_exported_without_connectors(c_fmus3, tmp_path):
    sc = write_scenario(tmp_path, {"term": (c_fmus3["Terminator3"], {"stop_at": 0.5}, {})})
    out = tmp_path / "out.ssp"
    with pytest.raises(ScenarioError, match=r"\[fmus.term\].*FMI 3.0 FMU.*SSP 1.0"):
        export_ssp(sc, out, build=False)
    assert not out.exists()


def _enumeration_pair(c_fmus, tmp_path):
    f = c_fmus["AllTypes"]
    inputs = {"mode": "fast", "u": 1.0, "ui": 2, "ub": True, "us": "z"}
    return write_scenario(tmp_path, {"A": (f, {}, inputs),
                                     "B": (f, {}, {k: v for k, v in inputs.items()
                                                   if k != "mode"})},
                          {"B.mode": "A.next_mode"})


def test_libcosim_itself_cannot_run_an_enumeration_connector(c_fmus, tmp_path):
    """The reason the refusals below give, observed: libcosim aborts its process on an SSP
    Enumeration connector ("Don't know how to handle Enumeration type!"). The child process
    (``_isolated``) turns the abort into a LibcosimError. If a libcosim release runs it, this
    fails and the refusals should go."""
    from cosim.interop.libcosim import LibcosimError, _isolated

    out = export_ssp(_enumeration_pair(c_fmus, tmp_path), tmp_path / "enum.ssp", build=False)
    with pytest.raises(LibcosimError, match="(?s)ended its process.*Enumeration"):
        _isolated("_run_ssp", str(out), ["B.mode"], 1.0, 0.1)


def test_an_ssp_with_enumerations_is_refused_before_libcosim_starts(c_fmus, tmp_path):
    from cosim.interop.libcosim import ENUMERATION_REASON, LibcosimError, run_ssp

    out = export_ssp(_enumeration_pair(c_fmus, tmp_path), tmp_path / "enum.ssp", build=False)
    with pytest.raises(LibcosimError) as err:
        run_ssp(out, ["B.mode"], 1.0, 0.1)
    message = str(err.value)
    assert "ended its process" not in message and ENUMERATION_REASON in message
    # every Enumeration connector of both components, each named
    for name in ("A.mode", "A.next_mode", "B.mode", "B.next_mode"):
        assert name in message


def test_a_scenario_with_enumerations_is_refused_by_run_libcosim(c_fmus, tmp_path):
    from cosim.interop.libcosim import ENUMERATION_REASON, LibcosimError, run_libcosim

    with pytest.raises(LibcosimError) as err:
        run_libcosim(_enumeration_pair(c_fmus, tmp_path), record=["B.y"])
    message = str(err.value)
    # set (A.mode) and connected (A.next_mode -> B.mode); B.next_mode is neither
    assert "A.mode, A.next_mode, B.mode are Enumerations" in message
    assert ENUMERATION_REASON in message and "B.next_mode" not in message


def test_the_export_notes_name_the_enumerations_libcosim_cannot_run(c_fmus, tmp_path):
    from cosim.interop.ssp import export_notes
    from cosim.run.scenario import load_scenario

    notes = export_notes(load_scenario(_enumeration_pair(c_fmus, tmp_path)))
    assert len(notes) == 1 and notes[0].startswith("A.mode, A.next_mode, B.mode: written as")


def test_a_max_step_is_kept_as_an_annotation_and_named_in_the_notes(c_fmus, tmp_path):
    from cosim.interop.ssp import ANNOTATION_TYPE, export_notes
    from cosim.run.scenario import load_scenario

    f = c_fmus["AllTypes"]
    inputs = {"mode": "fast", "u": 1.0, "ui": 2, "ub": True, "us": "z"}
    path = write_scenario(tmp_path, {"A": (f, {}, inputs)}, {})
    text = path.read_text().replace("[fmus.A]\n", "[fmus.A]\nmax_step = 0.05\n", 1)
    path.write_text(text)
    sc = load_scenario(path)
    assert sc.components["A"].max_step == 0.05
    out = export_ssp(sc, tmp_path / "step.ssp", build=False)
    read_ssd(str(out), validate=True)  # the annotation keeps the SSD schema-valid
    xml = zipfile.ZipFile(out).read("SystemStructure.ssd").decode()
    assert f'type="{ANNOTATION_TYPE}"' in xml and 'maxStep="0.05"' in xml
    notes = export_notes(sc)
    assert "[fmus.A] max_step = 0.05 s" in notes[0]
    assert len(notes) == 2 and notes[1].startswith("A.mode: written as")  # set, Enumeration
