"""Value exchange at a communication point in as few FMI calls as the dependencies allow.

The connections to move are split into *stages* (Gauss-Seidel levels): a connection is in
stage 0 when the output it reads depends on no input fed by another connection moved at the
same point, else one stage after the latest connection feeding such an input. Within a stage
every output read is independent of every input written, so a stage is one fmi2Get<type> per
source FMU and type, then one fmi2Set<type> per destination FMU and type, all value references
resolved once (FMI 2.0.4 sec. 2.1.7: get/set take arrays of value references). With the usual
plant -> controller -> plant wiring that is two stages of one get and one set each, whatever the
number of connected variables. Reading an output before or after setting an input it does not
depend on (``ModelStructure``) gives the same value, so the results equal those of moving the
connections one at a time in value-flow order (:mod:`cosim.run.dependencies`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from cosim.run.fmi_types import FUNCTIONS


@dataclass
class Read:
    """One fmi2Get<family> of ``vrs`` on ``unit``."""

    unit: Any
    family: str
    vrs: list[int]


@dataclass
class Write:
    """One fmi2Set<family> of ``vrs`` on ``unit``; the values are ``take`` (indices into the
    stage's read values, concatenated in read order; None: all of them, in order), and
    ``links`` the connections they travel along (for the change counts)."""

    unit: Any
    family: str
    vrs: list[int]
    take: list[int] | None
    links: list[Any] = field(default_factory=list)


@dataclass
class Stage:
    """The reads, then the writes, of one Gauss-Seidel level."""

    reads: list[Read]
    writes: list[Write]

    def read(self) -> list[Any]:
        """Every value this stage moves, the reads concatenated."""
        reads = self.reads
        if len(reads) == 1:
            r = reads[0]
            return r.unit.read(r.family, r.vrs)
        values: list[Any] = []
        for r in reads:
            values += r.unit.read(r.family, r.vrs)
        return values

    def write(self, values: list[Any]) -> None:
        """Set every destination input from ``values`` (:meth:`read`), counting changes."""
        for w in self.writes:
            out = values if w.take is None else [values[i] for i in w.take]
            for link, value in zip(w.links, out):
                if link.last is not None and value != link.last:
                    link.changes += 1
                link.last = value
            w.unit.write(w.family, w.vrs, out)

    def run(self) -> None:
        self.write(self.read())


def levels(links: Sequence[Any]) -> list[int]:
    """The stage of each of ``links`` (objects with ``src``, ``src_name``, ``dst``,
    ``dst_name``; units with ``name`` and ``deps``), which must be in value-flow order."""
    fed = {(lk.dst.name, lk.dst_name): i for i, lk in enumerate(links)}
    out: list[int] = []
    for lk in links:
        level = 0
        for inp in lk.src.deps.get(lk.src_name, ()):
            j = fed.get((lk.src.name, inp))
            if j is not None:
                level = max(level, out[j] + 1)
        out.append(level)
    return out


def stage(links: Sequence[Any]) -> Stage:
    """One stage moving ``links``: each source variable read once, in first-use order."""
    reads: dict[tuple[str, str], Read] = {}
    slots: dict[tuple[str, str], tuple[Read, int]] = {}
    for lk in links:
        key = (lk.src.name, lk.src_name)
        if key in slots:
            continue
        var = lk.src.vars[lk.src_name]
        family = FUNCTIONS[var.type]
        read = reads.setdefault((lk.src.name, family), Read(lk.src, family, []))
        slots[key] = (read, len(read.vrs))
        read.vrs.append(var.vr)
    offsets, n = {}, 0
    for read in reads.values():
        offsets[id(read)] = n
        n += len(read.vrs)
    writes: dict[tuple[str, str], Write] = {}
    for lk in links:
        var = lk.dst.vars[lk.dst_name]
        family = FUNCTIONS[var.type]
        write = writes.setdefault((lk.dst.name, family), Write(lk.dst, family, [], []))
        read, pos = slots[(lk.src.name, lk.src_name)]
        write.vrs.append(var.vr)
        write.take.append(offsets[id(read)] + pos)  # type: ignore[union-attr]
        write.links.append(lk)
    for write in writes.values():
        if write.take == list(range(n)):
            write.take = None
    return Stage(list(reads.values()), list(writes.values()))


def plan(links: Sequence[Any]) -> list[Stage]:
    """The stages moving ``links`` (in value-flow order), Gauss-Seidel: stage k reads outputs
    after stage k - 1 set the inputs they depend on."""
    lv = levels(links)
    return [stage([lk for lk, k in zip(links, lv) if k == level])
            for level in range(max(lv) + 1)] if links else []
