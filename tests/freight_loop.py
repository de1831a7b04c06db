"""Closed loop of a freight controller core and the freight plant core (no FMUs), for tests."""

from __future__ import annotations

from typing import Any

import numpy as np

from cosim.fmu.state import to_ticks
from plants.freight import FreightParams, FreightTrain
from plants.route import Route

COLUMNS = ("t", "s", "v", "v_ref", "force_demand", "pipe_reduction", "traction_force",
           "air_brake_force", "v_mean")


def closed_loop(controller: Any, route: Route, t_end: float, sample_time: float = 0.2,
                s0: float = 0.0, v0: float = 0.0,
                params: FreightParams | None = None,
                extra: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Run ``controller.compute`` every ``sample_time`` on the plant; columns of COLUMNS
    and the controller outputs ``extra`` sampled at the events (plant outputs before the
    event, commands of the event)."""
    train = FreightTrain(params or FreightParams(), route, v0=v0, s0=s0)
    T, t, end = to_ticks(sample_time), 0, to_ticks(t_end)
    m = train.mass / train.mass.sum()
    rows = []
    while t < end:
        out = train.outputs()
        cmd, _ = controller.compute(t / 1e9, {"v": out["v"], "s": out["s"]})
        rows.append((t / 1e9, out["s"], out["v"], cmd["v_ref"], cmd["force_demand"],
                     cmd["pipe_reduction"], out["traction_force"], out["air_brake_force"],
                     float(m @ train.v), *(cmd[name] for name in extra)))
        train.advance(t, T, cmd)
        t += T
    data = np.array(rows)
    return {name: data[:, i] for i, name in enumerate((*COLUMNS, *extra))}
