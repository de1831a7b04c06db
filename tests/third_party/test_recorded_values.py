"""What the master records and reports is what the FMUs give: 64-bit integer outputs exactly
(beyond 2**53, where float64 rounds), Binary outputs as the hexadecimal text scenarios take,
and FMI 2 log messages formatted with their printf arguments (FMI 2.0.4 sec. 2.1.5)."""

from __future__ import annotations

import gc

import pandas as pd
import pytest
from test_master_fmi3 import VALUES
from test_master_third_party import write_scenario

from cosim.run.master import SimulationError
from cosim.run.simulate import run_scenario

BEYOND_FLOAT = 2**53 + 1  # the first integer float64 cannot hold
INT64_MAX = 2**63 - 1


def test_64_bit_integers_and_binary_are_recorded_exactly(c_fmus3, tmp_path):
    inputs = {**{f"u_{k}": v for k, v in VALUES.items()}, "u_Int64": INT64_MAX,
              "u_UInt64": BEYOND_FLOAT, "u_Int32": -7, "u_Binary": "00ff10",
              "u_Enumeration": "fast", **{f"\"ua[{i}]\"": 0.0 for i in (1, 2, 3)}}
    record = ["ft.y_Int64", "ft.y_UInt64", "ft.y_Int32", "ft.y_Binary", "ft.y_Enumeration",
              "ft.y_Float64"]
    sc = write_scenario(tmp_path, {"ft": (c_fmus3["Feedthrough3"], {}, inputs)}, stop=0.5,
                        record=record)
    out = tmp_path / "out"
    frame = run_scenario(sc, build=False, out_dir=out, plot=False).frame
    assert frame["ft.y_Int64"].dtype == "int64" and frame["ft.y_UInt64"].dtype == "uint64"
    assert frame["ft.y_Enumeration"].dtype == "int64"  # FMI 3 Enumerations are Int64
    assert frame["ft.y_Int32"].dtype == frame["ft.y_Float64"].dtype == "float64"
    assert [int(v) for v in frame["ft.y_Int64"]] == [INT64_MAX] * len(frame)
    assert [int(v) for v in frame["ft.y_UInt64"]] == [BEYOND_FLOAT] * len(frame)
    assert set(frame["ft.y_Enumeration"]) == {3}
    assert set(frame["ft.y_Binary"]) == {"00ff10"}
    text = (out / "results.csv").read_text()
    assert str(BEYOND_FLOAT) in text and str(INT64_MAX) in text
    assert "b'" not in text and ",00ff10" in text
    back = pd.read_csv(out / "results.csv", dtype={"ft.y_Binary": str})
    assert (back["ft.y_UInt64"] == BEYOND_FLOAT).all() and (back["ft.y_Int64"] == INT64_MAX).all()
    assert bytes.fromhex(back["ft.y_Binary"].iloc[-1]) == bytes.fromhex("00ff10")


def test_fmi2_log_messages_are_formatted_with_their_arguments(c_fmus, tmp_path):
    """The Discarder logs ``"step %g at t = %g is longer than max_step = %g"`` with its three
    arguments (tests/third_party/discarder.c): the error shows the numbers, not the format."""
    path = write_scenario(tmp_path, {"d": (c_fmus["DiscarderFixed"], {}, {"u": 1.0})},
                          algorithm="fixed", base_step=0.25, output=0.25)
    with pytest.raises(SimulationError) as caught:
        run_scenario(path, build=False, plot=False)
    assert "step 0.25 at t = 0 is longer than max_step = 0.125" in str(caught.value)
    assert "%g" not in str(caught.value)


def test_messages_of_two_fmus_reach_their_own_listeners():
    """Every FMI 2 unit's logger is fmpy's formatting proxy, which calls the one dispatcher;
    each message, formatted, reaches the listener of the callbacks it came through, and the
    listener goes with its callbacks."""
    from cosim.run.master.fmi2 import _LISTENERS, logging_callbacks

    heard: dict[str, list[tuple[int, str]]] = {"a": [], "b": []}
    a = logging_callbacks(lambda status, text: heard["a"].append((status, text)))
    b = logging_callbacks(lambda status, text: heard["b"].append((status, text)))
    a.logger(a.componentEnvironment, b"x", 1, b"log", b"from a, 50 %% braking")
    b.logger(b.componentEnvironment, b"x", 3, b"log", b"from b")
    assert heard == {"a": [(1, "from a, 50 % braking")], "b": [(3, "from b")]}  # formatted
    key = b.componentEnvironment
    del b
    gc.collect()
    assert key not in _LISTENERS and a.componentEnvironment in _LISTENERS
