"""FMU wrapper of :class:`plants.freight.FreightTrain` (seed 002: HXD1 + 108 loaded C80)."""

from __future__ import annotations

from cosim.fmu.slave import PlantSlave, Var
from cosim.fmu.state import to_seconds
from plants.freight import FreightParams, FreightTrain
from plants.route import load_route

_D = FreightParams()
N_VEHICLES = _D.n_vehicles  # the FMU interface is fixed: 1 locomotive + 108 wagons
PRESSURE_VEHICLES = (1, 28, 55, 82, 109)  # vehicles whose cylinder pressure is an output

_PARAMS: tuple[tuple[str, str, str, float | None], ...] = (
    # name, unit, description, min
    ("loco_mass", "kg", "locomotive mass (HXD1: 200 t)", 1.0),
    ("loco_length", "m", "locomotive length (35.2 m)", 0.1),
    ("wagon_mass", "kg", "loaded wagon mass (C80: 20 t + 77 t)", 1.0),
    ("wagon_length", "m", "wagon length (12 m)", 0.1),
    ("loco_rotating_mass_factor", "1", "gamma of the locomotive", 0.0),
    ("wagon_rotating_mass_factor", "1", "gamma of a wagon", 0.0),
    ("coupler_stiffness", "N/m", "draft-gear stiffness per coupling", 1.0),
    ("coupler_damping", "N.s/m", "draft-gear damping per coupling", 0.0),
    ("coupler_slack", "m", "total free play per coupling (0: none)", 0.0),
    ("max_traction_force", "N", "largest tractive effort (760 kN)", 0.0),
    ("max_traction_power", "W", "traction power at the wheel (9600 kW)", 1.0),
    ("max_ed_force", "N", "largest electric brake force (461 kN)", 0.0),
    ("max_ed_power", "W", "electric brake power (9600 kW)", 1.0),
    ("ed_fade_speed", "m/s", "electric brake fades linearly to 0 below this speed", 0.0),
    ("traction_delay", "s", "tau of eq. (15): dead time of traction/electric brake", 0.0),
    ("traction_time_constant", "s", "t_vb of eq. (15): traction/electric brake lag", 1e-6),
    ("traction_ramp_time", "s", "t3 - t2 of eq. (8) (traction_model = 1)", 1e-6),
    ("brake_propagation_speed", "m/s", "brake-pipe application wave speed (~250 m/s)", 1e-3),
    ("brake_release_propagation_speed", "m/s", "brake-pipe release wave speed", 1e-3),
    ("brake_apply_delay", "s", "valve delay added to the application propagation delay", 0.0),
    ("brake_release_delay", "s", "valve delay added to the release propagation delay", 0.0),
    ("brake_fill_time", "s", "t_max of eq. (9): cylinder 0 -> p_max", 1e-6),
    ("brake_fill_exponent", "1", "lambda of eq. (9)", 1e-6),
    ("brake_release_time", "s", "cylinder p_max -> 0", 1e-6),
    ("brake_release_exponent", "1", "exponent of the release curve", 1e-6),
    ("max_cylinder_pressure", "Pa", "p_max: cylinder pressure at a full service reduction", 1.0),
    ("full_service_reduction", "Pa", "brake-pipe reduction of a full service application", 1.0),
    ("min_reduction", "Pa", "smallest reduction that applies the brakes", 0.0),
    ("loco_braking_ratio", "1", "converted braking ratio of the locomotive at p_max", 0.0),
    ("wagon_braking_ratio", "1", "converted braking ratio of a wagon at p_max", 0.0),
    ("stiction_speed", "m/s", "regularisation of friction forces at standstill", 1e-6),
    ("max_step", "s", "longest internal integration sub-step", 1e-6),
)
_RESISTANCE = (("loco_resistance", _D.loco_resistance, "locomotive"),
               ("wagon_resistance", _D.wagon_resistance, "loaded wagon"))


def _resistance_vars() -> list[Var]:
    out = []
    for name, coeffs, who in _RESISTANCE:
        for suffix, value, what in zip("abc", coeffs, ("N/kN", "N/kN per km/h",
                                                       "N/kN per (km/h)^2")):
            out.append(Var(f"{name}_{suffix}", "parameter", float(value), "1",
                           f"basic resistance of a {who}: {what} (v in km/h)", min=0.0))
    return out


class FreightTrainFmu(PlantSlave):
    """Heavy freight train HXD1 + 108 C80: couplers, traction lag, air-brake wave (seed 002)."""

    default_experiment_stop_time = 60.0
    default_experiment_step = 0.2
    variables = (
        *(Var(name, "parameter", float(getattr(_D, name)), unit, desc, min=lo)
          for name, unit, desc, lo in _PARAMS),
        *_resistance_vars(),
        Var("traction_model", "parameter", _D.traction_model, "1",
            "0: first-order lag with dead time (eq. 15); 1: ramp (eq. 8)", min=0, max=1),
        Var("v0", "parameter", 0.0, "m/s", "initial speed of every vehicle", min=0.0),
        Var("s0", "parameter", 0.0, "m", "initial position of the train front"),
        Var("route", "parameter", "freight_20km", description=
            "bundled route name or path of a route TOML file"),
        Var("force_demand", "input", 0.0, "N",
            "locomotive force demand: > 0 traction, < 0 electric brake"),
        Var("pipe_reduction", "input", 0.0, "Pa",
            "brake-pipe pressure reduction at the driver's brake valve (0 = released)",
            min=0.0),
        Var("v", "output", 0.0, "m/s", "head (locomotive) speed"),
        Var("s", "output", 0.0, "m", "head position (train front)"),
        Var("v_tail", "output", 0.0, "m/s", "tail (last wagon) speed"),
        Var("s_tail", "output", 0.0, "m", "tail position (rear of the last wagon)"),
        Var("a", "output", 0.0, "m/s2", "train acceleration (mass-weighted, last sub-step)"),
        Var("traction_force", "output", 0.0, "N",
            "achieved locomotive force (> 0 traction, < 0 electric brake)"),
        Var("traction_power", "output", 0.0, "W", "traction power at the wheel (< 0 regen)"),
        Var("traction_energy", "output", 0.0, "J", "traction minus regenerated energy"),
        Var("applied_demand", "output", 0.0, "N", "force demand acting now: F_dem(t - tau)"),
        Var("draft_force_max", "output", 0.0, "N", "largest coupler draft force now"),
        Var("buff_force_max", "output", 0.0, "N", "largest coupler buff force now (> 0)"),
        Var("draft_force_peak", "output", 0.0, "N",
            "largest draft force over the last communication step"),
        Var("buff_force_peak", "output", 0.0, "N",
            "largest buff force (> 0) over the last communication step"),
        Var("air_brake_force", "output", 0.0, "N", "total air-brake force"),
        Var("grade", "output", 0.0, "1", "grade at the head (permille, uphill > 0)"),
        Var("speed_limit", "output", 0.0, "m/s", "line speed limit at the head"),
        Var("brake_pipe_reduction", "output", 0.0, "Pa", "brake-pipe reduction commanded"),
        *(Var(f"p_cyl[{i}]", "output", 0.0, "Pa", f"brake-cylinder pressure of vehicle {i}")
          for i in PRESSURE_VEHICLES),
        *(Var(f"v[{i}]", "output", 0.0, "m/s", f"speed of vehicle {i} (1 = locomotive)")
          for i in range(1, N_VEHICLES + 1)),
    )

    def make_core(self) -> FreightTrain:
        val = self.values
        params = FreightParams(
            n_wagons=N_VEHICLES - 1,
            traction_model=int(val["traction_model"]),
            loco_resistance=tuple(val[f"loco_resistance_{c}"] for c in "abc"),
            wagon_resistance=tuple(val[f"wagon_resistance_{c}"] for c in "abc"),
            **{name: val[name] for name, *_ in _PARAMS},
        )
        route = load_route(val["route"], self.resource_path("plants", "routes"))
        return FreightTrain(params, route, v0=val["v0"], s0=val["s0"],
                            t0=to_seconds(self.start_ticks))
