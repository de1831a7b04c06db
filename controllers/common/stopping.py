"""Declarations shared by the seed 000 stopping controllers (PID, MPC, RMPC, RSMPC)."""

from __future__ import annotations

from cosim.fmu.declare import Var, group, param
from plants.resistance import Davis


def u_min_param(default: float = 0.0) -> float:
    return param(default, "%", "lowest brake command")


def u_max_param(default: float = 100.0) -> float:
    return param(default, "%", "highest brake command")


MEASURED_SPEED_POSITION: tuple[Var, ...] = (
    Var.input("v", "m/s", "measured speed"),
    Var.input("s", "m", "measured position"),
)


def mass_param() -> float:
    """The train mass of a controller's resistance model (seed 000 Table 1)."""
    return param(490e3, "kg", "train mass (resistance model)", min=1.0)


def davis_group() -> Davis:
    """The nominal Davis resistance of a controller's model (seed 000 Table 1, kN with v in
    km/h), FMU names ``davis_*``."""
    return group(Davis.from_kn_kmh(5.4, 0.0098, 0.00163), "davis_")


def route_param() -> str:
    """The route whose grades a controller's resistance model knows."""
    return param("seed000_stop", description="route (grade profile): bundled name or path")
