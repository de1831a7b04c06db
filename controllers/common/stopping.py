"""Declarations shared by the seed 000 stopping controllers (PID, MPC, RMPC, RSMPC)."""

from __future__ import annotations

from cosim.fmu.declare import Var, param


def u_min_param(default: float = 0.0) -> float:
    return param(default, "%", "lowest brake command")


def u_max_param(default: float = 100.0) -> float:
    return param(default, "%", "highest brake command")


MEASURED_SPEED_POSITION: tuple[Var, ...] = (
    Var.input("v", "m/s", "measured speed"),
    Var.input("s", "m", "measured position"),
)
