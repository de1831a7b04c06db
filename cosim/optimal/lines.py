"""A line for :mod:`cosim.optimal` from a TTOBench track JSON or a project route (TOML path or
bundled name, :func:`plants.route.load_route`)."""

from __future__ import annotations

from pathlib import Path

from cosim.optimal.ttobench import load_track
from plants.route import Route, load_route


def load_line(name_or_path: str | Path) -> tuple[Route, list[float]]:
    """(route, stop positions in m): a TTOBench track's stops, a route's stations (or its two
    ends)."""
    if str(name_or_path).endswith(".json"):
        track = load_track(name_or_path)
        return track.route, list(track.stops)
    route = load_route(name_or_path)
    return route, [x for _, x in route.stations] or [0.0, route.length_m]
