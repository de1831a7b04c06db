"""The lean master's value exchange (cosim/run/exchange.py): Gauss-Seidel stages from the
output dependencies, one read per source FMU and type and one write per destination and type,
buffers shared when a write takes a whole read; and one BLAS thread inside a run."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from cosim.run import exchange
from cosim.run.master import Variable


@dataclass(eq=False)
class FakeUnit:
    """Outputs are values; every call is logged."""

    name: str
    vars: dict[str, Variable]
    deps: dict[str, set[str]] = field(default_factory=dict)
    values: dict[int, float] = field(default_factory=dict)
    calls: list = field(default_factory=list)

    def batch(self, family, vrs, setter, buffer=None):
        return FakeBatch(self, family, list(vrs), setter, buffer)


class FakeBatch:
    def __init__(self, unit, family, vrs, setter, buffer):
        self.unit, self.family, self.vrs, self.setter = unit, family, vrs, setter
        self.buf = buffer if buffer is not None else [0.0] * len(vrs)

    def get(self):
        self.unit.calls.append(("get", self.family, tuple(self.vrs)))
        self.buf[:] = [self.unit.values[vr] for vr in self.vrs]

    def set(self):
        self.unit.calls.append(("set", self.family, tuple(self.vrs)))
        self.unit.values.update(zip(self.vrs, self.buf))


@dataclass(eq=False)
class FakeLink:
    src: FakeUnit
    src_name: str
    dst: FakeUnit
    dst_name: str
    last: object = None
    changes: int = 0
    history: list | None = None


def unit(name, variables, deps=None):
    vs = {n: Variable(vr, kind, causality) for vr, (n, kind, causality) in enumerate(variables)}
    return FakeUnit(name, vs, deps or {})


def test_plant_controller_plant_is_two_stages_of_one_read_and_one_write():
    plant = unit("plant", [("v", "Real", "output"), ("s", "Real", "output"),
                           ("u", "Real", "input"), ("on", "Boolean", "input")])
    ctrl = unit("ctrl", [("v", "Real", "input"), ("s", "Real", "input"),
                         ("u", "Real", "output"), ("on", "Boolean", "output")],
                deps={"u": {"v", "s"}, "on": set()})
    plant.values.update({0: 20.0, 1: 5.0})
    ctrl.values.update({2: 0.0, 3: 1})
    links = [FakeLink(plant, "v", ctrl, "v"), FakeLink(plant, "s", ctrl, "s"),
             FakeLink(ctrl, "on", plant, "on"), FakeLink(ctrl, "u", plant, "u")]
    assert exchange.levels(links) == [0, 0, 0, 1]  # "on" depends on no input
    stages = exchange.plan(links)
    assert len(stages) == 2
    first, second = stages
    # stage 0: plant [v, s] and ctrl [on] read (two FMUs), then one write to each
    assert [(b.unit.name, b.family, b.vrs) for b in first.reads] == [
        ("plant", "Real", [0, 1]), ("ctrl", "Boolean", [3])]
    assert [(w.batch.unit.name, w.batch.family) for w in first.writes] == [
        ("ctrl", "Real"), ("plant", "Boolean")]
    assert first.writes[0].copy is None  # ctrl [v, s] takes plant's read buffer as it is
    assert first.writes[0].batch.buf is first.reads[0].buf
    for st in stages:
        st.run()
    assert ctrl.values[0] == 20.0 and ctrl.values[1] == 5.0 and plant.values[3] == 1
    ctrl.values[2] = 7.0
    plant.values[0] = 19.0
    for st in stages:
        st.run()
    assert plant.values[2] == 7.0
    assert [lk.changes for lk in links] == [1, 0, 0, 1]
    # per point: ctrl one Boolean get, one Real set, one Real get; in value-flow order
    per_point = ctrl.calls[:3]
    assert sorted(per_point) == sorted([("get", "Boolean", (3,)), ("set", "Real", (0, 1)),
                                        ("get", "Real", (2,))])
    assert per_point.index(("set", "Real", (0, 1))) < per_point.index(("get", "Real", (2,)))


def test_a_chain_of_feedthrough_fmus_is_one_stage_each():
    a = unit("a", [("y", "Real", "output")])
    b = unit("b", [("x", "Real", "input"), ("y", "Real", "output")], deps={"y": {"x"}})
    c = unit("c", [("x", "Real", "input"), ("y", "Real", "output")], deps={"y": {"x"}})
    links = [FakeLink(a, "y", b, "x"), FakeLink(b, "y", c, "x")]
    assert exchange.levels(links) == [0, 1]
    # c not due: only the link into b moves, in stage 0
    assert exchange.levels(links[:1]) == [0]


def test_one_blas_thread_inside_a_run_and_restored_after():
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import numpy  # noqa: F401 - loads the BLAS library

    from cosim.run.threads import one_blas_thread

    def blas_threads():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info()
                if i["user_api"] == "blas"]

    before = blas_threads()
    if not before:
        pytest.skip("no BLAS library found by threadpoolctl")
    with threadpoolctl.threadpool_limits(2, user_api="blas"):
        outside = blas_threads()
        with one_blas_thread() as refresh:
            refresh()
            assert set(blas_threads()) == {1}
        assert blas_threads() == outside
    assert blas_threads() == before
