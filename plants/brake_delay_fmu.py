"""FMU wrapper of :class:`plants.brake_delay.BrakeDelayTrain` (seed 000 plant)."""

from __future__ import annotations

from cosim.fmu.slave import PlantSlave, Var
from cosim.fmu.state import to_seconds
from plants.brake_delay import BrakeDelayParams, BrakeDelayTrain
from plants.resistance import Davis
from plants.route import load_route

_D = BrakeDelayParams()


class BrakeDelayTrainFmu(PlantSlave):
    """High-speed train, brake command through first-order lag plus dead time (seed 000)."""

    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2
    variables = (
        Var("mass", "parameter", _D.mass, "kg", "train mass", min=1.0),
        Var("davis_a", "parameter", _D.davis.a, "N", "Davis constant term a", min=0.0),
        Var("davis_b", "parameter", _D.davis.b, "N.s/m", "Davis linear term b", min=0.0),
        Var("davis_c", "parameter", _D.davis.c, "N.s2/m2", "Davis quadratic term c", min=0.0),
        Var("brake_gain", "parameter", _D.brake_gain, "m/s2/%",
            "c: brake deceleration per % of command (100 % -> 1.07 m/s2)", min=0.0),
        Var("brake_time_constant", "parameter", _D.brake_time_constant, "s",
            "tau: first-order brake lag", min=1e-6),
        Var("brake_delay", "parameter", _D.brake_delay, "s", "Td: brake dead time", min=0.0),
        Var("max_step", "parameter", _D.max_step, "s", "longest internal integration sub-step",
            min=1e-6),
        Var("v0", "parameter", 20.0, "m/s", "initial speed", min=0.0),
        Var("s0", "parameter", 0.0, "m", "initial position"),
        Var("initial_command", "parameter", 0.0, "%",
            "brake command held before the start (brake in equilibrium with it)", min=0.0,
            max=100.0),
        Var("route", "parameter", "seed000_stop", description=
            "bundled route name or path of a route TOML file (grade profile)"),
        Var("brake_command", "input", 0.0, "%", "brake command u (0..100 %)", min=0.0, max=100.0),
        Var("v", "output", 0.0, "m/s", "speed"),
        Var("s", "output", 0.0, "m", "position"),
        Var("a", "output", 0.0, "m/s2", "acceleration dv/dt"),
        Var("a_c", "output", 0.0, "m/s2", "acceleration produced by the brakes (<= 0)"),
        Var("applied_command", "output", 0.0, "%", "command acting now: u(t - Td)"),
        Var("grade", "output", 0.0, "1", "grade at the train position (permille, uphill > 0)"),
    )

    def make_core(self) -> BrakeDelayTrain:
        val = self.values
        params = BrakeDelayParams(
            mass=val["mass"],
            davis=Davis(val["davis_a"], val["davis_b"], val["davis_c"]),
            brake_gain=val["brake_gain"],
            brake_time_constant=val["brake_time_constant"],
            brake_delay=val["brake_delay"],
            max_step=val["max_step"],
        )
        route = load_route(val["route"], self.resource_path("plants", "routes"))
        return BrakeDelayTrain(params, route, v0=val["v0"], s0=val["s0"],
                               initial_command=val["initial_command"],
                               t0=to_seconds(self.start_ticks))
