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


@dataclass
class Write:
    """One fmi2Set<family> (``batch``); ``copy``: (position in the batch, read buffer,
    position there) of each value, or None when the batch shares its read's buffer (it takes
    all that read's values, in order)."""

    batch: Any
    copy: list[tuple[int, Any, int]] | None


@dataclass
class Stage:
    """The reads, then the writes, of one Gauss-Seidel level; ``sources``: each connection
    with the buffer and position its value is read into (for the change counts)."""

    reads: list[Any]
    writes: list[Write]
    sources: list[tuple[Any, Any, int]] = field(default_factory=list)

    def read(self) -> None:
        """Read every output this stage moves (into the read buffers)."""
        for batch in self.reads:
            batch.get()

    def write(self) -> None:
        """Set every destination input from the read buffers, counting value changes."""
        for link, buf, i in self.sources:
            value = buf[i]
            if link.last is not None and value != link.last:
                link.changes += 1
            if link.history is not None and (link.last is None or value != link.last):
                link.history.append(value)  # every new value of the summary's command
            link.last = value
        for w in self.writes:
            if w.copy is not None:
                out = w.batch.buf
                for j, buf, i in w.copy:
                    out[j] = buf[i]
            w.batch.set()

    def run(self) -> None:
        self.read()
        self.write()


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
    """One stage moving ``links``: each source variable read once (one batch per source FMU
    and function family, in first-use order), one write batch per destination and family.
    Units provide ``batch(family, vrs, setter, buffer=None)`` (:class:`cosim.run.fmi_batch.
    Batch`)."""
    reads: dict[tuple[str, str], tuple[Any, list[int]]] = {}
    slots: dict[tuple[str, str], tuple[tuple[str, str], int]] = {}
    for lk in links:
        key = (lk.src.name, lk.src_name)
        if key in slots:
            continue
        var = lk.src.vars[lk.src_name]
        group = (lk.src.name, var.family)
        vrs = reads.setdefault(group, (lk.src, []))[1]
        slots[key] = (group, len(vrs))
        vrs.append(var.vr)
    batches = {group: unit.batch(group[1], vrs, False) for group, (unit, vrs) in reads.items()}
    wanted: dict[tuple[str, str], tuple[Any, list[int], list[tuple[tuple[str, str], int]]]] = {}
    sources = []
    for lk in links:
        var = lk.dst.vars[lk.dst_name]
        group, pos = slots[(lk.src.name, lk.src_name)]
        entry = wanted.setdefault((lk.dst.name, var.family), (lk.dst, [], []))
        entry[1].append(var.vr)
        entry[2].append((group, pos))
        sources.append((lk, batches[group].buf, pos))
    writes = []
    for (_, family), (unit, vrs, taken) in wanted.items():
        group = taken[0][0]
        # a buffer is shared only between C functions of one value type (an FMI 2 Boolean
        # is an int, an FMI 3 Boolean a bool)
        same_memory = (getattr(batches[group], "ctype", None)
                       is getattr(unit, "C_TYPES", {}).get(family))
        if same_memory and taken == [(group, i) for i in range(len(reads[group][1]))]:
            writes.append(Write(unit.batch(family, vrs, True, buffer=batches[group].buf), None))
        else:
            batch = unit.batch(family, vrs, True)
            writes.append(Write(batch, [(j, batches[g].buf, i)
                                        for j, (g, i) in enumerate(taken)]))
    return Stage(list(batches.values()), writes, sources)


def plan(links: Sequence[Any]) -> list[Stage]:
    """The stages moving ``links`` (in value-flow order), Gauss-Seidel: stage k reads outputs
    after stage k - 1 set the inputs they depend on."""
    lv = levels(links)
    return [stage([lk for lk, k in zip(links, lv) if k == level])
            for level in range(max(lv) + 1)] if links else []
