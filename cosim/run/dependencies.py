"""Value flow between FMUs ordered by a per-variable dependency graph (FMI 2.0.4 sec. 2.2.8).

An output depends on the inputs its ``ModelStructure/Outputs/Unknown`` lists; an output whose
``dependencies`` attribute is absent depends on *every* input of its FMU. Nodes are (FMU,
variable); edges run from a connected output to the input it feeds, and from an input to every
output of the same FMU that depends on it. A cycle is an algebraic loop (also through a single
FMU wired to itself) and is rejected; otherwise the connections are transferred in topological
order, so every input is set before an output that depends on it is read.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def output_dependencies(md: Any) -> dict[str, set[str]]:
    """Output name -> names of the inputs it depends on at the same instant (fmpy
    ``ModelDescription``; absent attribute = all inputs)."""
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    out: dict[str, set[str]] = {}
    listed = set()
    for unknown in md.outputs:
        name = unknown.variable.name
        listed.add(name)
        if unknown.dependencies is None:
            out[name] = set(inputs)
        else:
            out[name] = {d.name for d in unknown.dependencies if d.name in inputs}
    for v in md.modelVariables:  # an output not listed at all: assume the worst
        if v.causality == "output" and v.name not in listed:
            out[v.name] = set(inputs)
    return out


def order_connections(connections: Sequence[Any], deps: dict[str, dict[str, set[str]]],
                      where: str = "") -> list[int]:
    """Indices of ``connections`` (objects with ``src, src_var, dst, dst_var``) in value-flow
    order; ``deps``: component -> :func:`output_dependencies`. Raises ``ValueError`` naming the
    loop if the connections and feedthrough dependencies form an algebraic loop."""
    feeding = {(c.dst, c.dst_var): i for i, c in enumerate(connections)}
    state: dict[int, int] = {}
    order: list[int] = []

    def visit(i: int, path: list[int]) -> None:
        if state.get(i) == 2:
            return
        if state.get(i) == 1:
            loop = path[path.index(i):] + [i]
            chain = " -> ".join(f"{connections[j].src}.{connections[j].src_var}" for j in loop)
            raise ValueError(f"{where}algebraic loop through outputs with direct feedthrough: "
                             f"{chain} (each output depends on the input the previous one "
                             "feeds; break it with an FMU without direct feedthrough)")
        state[i] = 1
        c = connections[i]
        for inp in sorted(deps.get(c.src, {}).get(c.src_var, ())):
            j = feeding.get((c.src, inp))
            if j is not None:
                visit(j, [*path, i])
        state[i] = 2
        order.append(i)

    for i in range(len(connections)):
        visit(i, [])
    return order
