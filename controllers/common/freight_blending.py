"""Traction / electric-brake / air-brake blending of the heavy freight train (seed 002).

Every freight speed controller (PID, optimal preview, sliding mode, fuzzy PID) produces one
number, the force ``F = M (1 + gamma) a_dem`` (N) the train should get from its brakes and
traction together (eq. 7, resistance already included by the controller). :class:`FreightBlending`
turns it into the two plant commands, ``force_demand`` (locomotive: traction > 0, electric
brake < 0, within the HXD1 envelope at the measured speed) and ``pipe_reduction`` (air brake):

* the air brake is used only when the electric brake is not enough: it is applied when the
  planned braking (reference acceleration now, at the controller's look-ahead and
  ``air_preview_time`` ahead, the air brake being slow, plus resistance) or, at an overspeed
  above ``overspeed``, the demand ``F`` needs more than ``ed_share`` of the electric brake, with a
  pipe reduction in ``reduction_step`` stages giving the missing planned force (an overspeed
  alone: the minimum reduction); it may then be deepened when the planned braking needs more,
  never for an overspeed (the deeper application could not be taken back short of a full
  release, and the train would stop far short of the stop point), never partly released
  (Chinese 120 valves release directly), and is released
  fully when the electric brake alone covers the demand with margin (``release_share``).
  Hold times: once applied it stays at least ``min_apply_time``; once released it is not
  re-applied for ``min_release_time`` (auxiliary reservoirs recharge);
* a stop the reference plans with the air brake (its final braking ramps the electric brake to
  ``stop_ed_share`` and then needs more: ``papers/seed002/make_freight_20km.py``) gets the stage its
  braking needs beyond that share (the smallest on that reference) at the sample nearest to
  the planned onset (:meth:`FreightBlending.planned_onsets`); before it the look-ahead of the
  rule above stops at the onset, so every controller applies the air brake where the plan does;
* while the air brake acts, the locomotive trims it with the electric brake only: the
  locomotive force is ``min(F + F_air, 0)`` as long as the modelled cylinders hold pressure
  (applied, or released but not yet empty); a controller that counts the air brake as a
  disturbance itself (the optimal preview: :meth:`FreightBlending.air_force_ahead`) passes the
  locomotive's part, ``min(F, 0)`` then. It never pulls against the air brake (no power
  braking): where even the minimum reduction brakes too hard the train decelerates more than
  planned. :meth:`FreightBlending.accel_limits` gives the controllers this envelope so their
  integrators and saturations see it;
* at the end of the profile (zero reference, speed under ``stop_speed``, and the reference
  ahead never rising to ``stop_speed`` again: not a planned start's creep) it holds the train
  with ``hold_reduction``; also when the air brake stopped the train short on a braking segment
  (the minimum reduction brakes harder than planned once the electric brake fades below
  ``ed_fade_speed``: without power braking the train stops some metres early).

The air-brake force estimate runs the plant's brake-pipe model (propagation delays, eq. (9)
filling) on the nominal brake data of :class:`plants.freight.FreightParams`.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from controllers.common.mean_observer import MeanSpeedObserver, fed_back_speed
from controllers.preview.design import DelayedModel, lag_delay_model
from cosim.fmu.c_text import ShippedValues, c_array, c_double, c_string
from cosim.fmu.declare import Checked, Declared, Var, build, param
from cosim.fmu.state import StatefulCore
from plants import kernels
from plants.freight import (
    FreightParams,
    FreightTrain,
    friction_coefficient,
    friction_coefficient_at,
)
from plants.route import (
    GRAVITY,
    ROUTES_DIR,
    ReferenceProfile,
    Route,
    load_route,
    route_parameter,
    routes_dir_in,
)

RELEASED_PA = 1.0  # Pa: a modelled cylinder pressure below this is a released brake


@dataclass(frozen=True)
class BlendingParams(Checked):
    """Air-brake decision and hold times (the nominal train ``train`` is the model)."""

    train: FreightParams = field(default_factory=FreightParams)  # nominal model
    air_preview_time: float = param(2.0, "s", "look-ahead of the planned braking for the "
                                    "air-brake decision", min=0.0)
    ed_share: float = param(0.8, "1", "share of the electric brake used before the air brake "
                            "is applied", min=0.0, max=1.0)
    release_share: float = param(0.4, "1", "air brake released when the electric brake alone "
                                 "needs less than this share", min=0.0, max=1.0)
    min_apply_time: float = param(30.0, "s", "shortest air-brake application", min=0.0)
    min_release_time: float = param(60.0, "s", "shortest time released before a new "
                                    "application", min=0.0)
    reduction_step: float = param(10e3, "Pa", "pipe-reduction stage", min=1.0)
    overspeed: float = param(2.0 / 3.6, "m/s", "overspeed above which feedback may call the "
                             "air brake", min=0.0)
    stop_speed: float = param(0.3, "m/s", "below this speed at the end of the profile the "
                              "train is held", min=0.0)
    hold_reduction: float = param(100e3, "Pa", "pipe reduction holding the train at the final "
                                  "stop", min=0.0)
    final_approach_distance: float = param(300.0, "m", "within this distance of a stop the "
                                           "air brake may be released for an electric-brake "
                                           "final approach (0: never)", min=0.0)
    stop_tolerance: float = param(1.0, "m", "final approach: released when the applied air "
                                  "brake alone would stop the train more than this short",
                                  min=0.0)
    stop_ed_share: float = param(0.5, "1", "share of the electric brake the reference's "
                                 "final braking is planned with "
                                 "(papers/seed002/make_freight_20km.py): the smallest "
                                 "reduction is applied where the reference brakes harder "
                                 "than that (0: no planned application)", min=0.0,
                                 max=1.0)

    def check_relations(self) -> None:
        self.train.check()  # the nominal model (a field, not a declared group)
        if not 0 < self.release_share < self.ed_share:
            raise ValueError(f"need 0 < release_share ({self.release_share}) < ed_share "
                             f"({self.ed_share})")


class FreightBlending(StatefulCore):
    """Force demand (N) -> locomotive force demand + pipe reduction, see the module doc."""

    state_fields = ("reduction", "pressure_estimate", "changed_at", "force", "holding",
                    "final_approach", "approach_stop", "brake_model_state")

    def __init__(self, params: BlendingParams, profile: ReferenceProfile, route: Route) -> None:
        params.check()
        if profile.kind != "distance":
            raise ValueError("freight blending needs a speed-distance reference profile")
        self.p = params
        self.profile = profile
        self.route = route
        self.model = FreightTrain(params.train, route)
        self.m_eff = float(self.model.m_eff.sum())  # kg, M (1 + gamma)
        self.weight = float(self.model.mass.sum() * GRAVITY)  # N
        self.brake_scale = float(self.model.brake_scale.sum())  # N per Pa per phi
        self._res_a = float(self.model.res_a.sum())
        self._res_b = float(self.model.res_b.sum())
        self._res_c = float(self.model.res_c.sum())
        steps = route.additional.starts[1:]
        length = self.model.train_length
        knots = np.unique(np.concatenate((steps, steps + length, [0.0])))
        self._add_knots = knots
        self._add_values = (route.additional_resistance(knots, length)
                            * self.weight / 1e3 / self.m_eff)
        self.reduction = 0.0  # Pa, commanded pipe reduction
        self.pressure_estimate = 0.0  # Pa, modelled mean cylinder pressure
        self.changed_at = -math.inf  # s, time of the last apply/release
        self.force = 0.0  # N, locomotive force demand
        self.holding = False  # final-stop holding brake applied
        self.final_approach = False  # air released for the electric-brake final approach
        self.approach_stop = math.inf  # m, its stop point
        self._stops = np.asarray(profile.x, dtype=float)[np.asarray(profile.v) <= 0.0]
        # highest reference speed from each point on (the end of the profile: below stop_speed)
        self._points = np.asarray(profile.x, dtype=float).tolist()
        self._peak_ahead = np.maximum.accumulate(np.asarray(profile.v)[::-1])[::-1].tolist()
        self._onsets = [(onset, self.next_stop(onset)) for onset in self.planned_onsets()]
        self._stop_consts: tuple | None = None  # plain floats for _integrate_stop

    @property
    def brake_model_state(self) -> dict:
        return {"pressure": self.model.pressure.copy(),
                "history": [list(h) for h in self.model.brake_history]}

    @brake_model_state.setter
    def brake_model_state(self, state: dict) -> None:
        self.model.pressure = np.array(state["pressure"], dtype=float)
        self.model.brake_history = [list(h) for h in state["history"]]

    # -- nominal model ---------------------------------------------------------------------
    def peak_ahead(self, s: float) -> float:
        """Highest reference speed (m/s) at the profile's points beyond ``s`` (0 past the
        last): below ``stop_speed`` only on the way into a stop, not in a start's creep."""
        j = bisect_right(self._points, s)
        return self._peak_ahead[j] if j < len(self._points) else 0.0

    def basic_accel(self, v: float | np.ndarray) -> float | np.ndarray:
        """Modelled basic resistance (eqs. 3-4) per unit effective mass (m/s^2)."""
        return (self._res_a + (self._res_b + self._res_c * v) * v) / self.m_eff

    def additional_accel(self, s: float | np.ndarray) -> float | np.ndarray:
        """Grade + curve + tunnel resistance (eq. 5) of the whole train with its front at ``s``,
        per unit effective mass (m/s^2). The length-share mean of a step profile is piecewise
        linear with kinks where a step enters or leaves the train: tabulated there at
        construction, so this is an exact interpolation."""
        out = np.interp(s, self._add_knots, self._add_values)
        return float(out) if np.ndim(s) == 0 else out

    def resistance_accel(self, v: float, s: float) -> float:
        """Modelled running resistance per unit effective mass (m/s^2): eq. (17) with sign +."""
        return self.basic_accel(v) + self.additional_accel(s)

    def air_force(self, pressure: float, v: float) -> float:
        """Air-brake force (N) of the whole train at a uniform cylinder pressure (Pa)."""
        return self.brake_scale * pressure * friction_coefficient_at(v)

    def air_applied(self) -> bool:
        """Applied, or released with pressure still in the (modelled) cylinders."""
        return self.reduction > 0.0 or float(self.model.pressure.max()) > RELEASED_PA

    def accel_limits(self, v: float) -> tuple[float, float]:
        """(lowest, highest) achievable demand ``F / M(1+gamma)`` (m/s^2) at speed ``v`` now:
        full electric + air brake below; traction above, or while the air brake acts only
        the electric brake trimming it (no power braking)."""
        speed = max(v, 0.0)
        trac, ed = self.model.traction_limits(speed)
        full_air = self.air_force(self.p.train.max_cylinder_pressure, speed)
        if self.air_applied():
            hi = -self.air_force(self.pressure_estimate, speed)
        else:
            hi = trac
        return -(ed + full_air) / self.m_eff, hi / self.m_eff

    def _reduction_for(self, force: float, v: float) -> float:
        """Smallest staged pipe reduction (Pa) whose air brake gives ``force`` (N)."""
        tp = self.p.train
        per_pa = self.air_force(1.0, v)
        need = force / per_pa / tp.max_cylinder_pressure * tp.full_service_reduction
        step = self.p.reduction_step
        return min(max(math.ceil(need / step) * step, tp.min_reduction),
                   tp.full_service_reduction)

    # -- planned stop application ----------------------------------------------------------
    def planned_onsets(self) -> np.ndarray:
        """Position (m) of the planned air-brake application of each stop of the profile: the
        start of the run of segments ending at the stop over which the reference brakes harder
        than ``stop_ed_share`` of the electric brake (the reference's final braking ramps the
        electric brake to that share, then adds the smallest air-brake stage; see
        ``papers/seed002/make_freight_20km.py``). Empty when ``stop_ed_share`` is 0."""
        share = self.p.stop_ed_share
        x, v = self.profile.x, self.profile.v
        if share <= 0.0:
            return np.empty(0)
        acc = self.profile.segment_accel
        mid = 0.5 * (x[:-1] + x[1:])
        speed = np.sqrt(0.5 * (v[:-1] ** 2 + v[1:] ** 2))
        ed = np.array([self.model.traction_limits(u)[1] for u in speed])
        need = -(acc + np.array([self.basic_accel(u) for u in speed])
                 + self.additional_accel(mid)) * self.m_eff
        harder = need > share * ed + 1e-3 * self.p.train.max_ed_force
        onsets = []
        for j in np.nonzero((v[1:] <= 0.0) & (v[:-1] > 0.0))[0]:
            k = j
            while k > 0 and harder[k - 1] and v[k] > 0.0:
                k -= 1
            if harder[j]:
                onsets.append(float(x[k]))
        return np.array(onsets)

    def planned_reduction(self, s: float, v: float, a_res: float) -> float:
        """Pipe reduction (Pa) of the planned application at head position ``s`` and speed
        ``v``: the stage giving what the planned braking ``air_preview_time`` ahead needs
        beyond the planned electric-brake share (``a_res`` the resistance, m/s^2)."""
        p = self.p
        ahead = self.profile.accel(s + v * p.air_preview_time)
        extra = -self.m_eff * (min(ahead, self.profile.accel(s)) + a_res)
        return self._reduction_for(extra - p.stop_ed_share * self.model.traction_limits(v)[1],
                                   v)

    def air_force_ahead(self, t: float, times: np.ndarray, speeds: np.ndarray,
                        planned: tuple[float, float] | None = None) -> np.ndarray:
        """Air-brake force (N) of the whole train at ``times`` (s, >= ``t``, the end of the
        last :meth:`blend`) at train speeds ``speeds`` (m/s): the plant's brake-pipe model on the
        nominal data (arrival of each command at each vehicle, eq. (9) filling and its release
        mirror, :meth:`plants.freight.FreightTrain.evolve_pressure`) from the modelled
        cylinder pressures now, the commanded reduction held, plus ``planned`` = (time s,
        reduction Pa), a command still to come (the planned application of a stop)."""
        model = self.model
        hist = [list(h) for h in model.brake_history]
        if planned is not None and planned[1] != hist[-1][1]:
            hist.append([float(planned[0]), float(planned[1])])
        values = np.array([h[1] for h in hist])
        rising = np.concatenate(([True], values[1:] >= values[:-1]))
        arrivals = np.array([h[0] for h in hist])[:, None] + np.where(
            rising[:, None], model.apply_delay[None, :], model.release_delay[None, :])
        times = np.asarray(times, dtype=float)[:, None]
        seen = model.commands_seen(arrivals, t)  # command each vehicle follows now
        target = np.broadcast_to(model.target_pressure(values[seen]), (times.shape[0],
                                                                     seen.size))
        pres = np.broadcast_to(model.pressure, target.shape)
        now = np.full(target.shape, float(t))
        # a command counts at a vehicle from its arrival until a later one arrives (the
        # plant's latest-arrived rule): one overtaken by a later command never acts there
        overtaken = np.minimum.accumulate(arrivals[::-1], axis=0)[::-1]
        for k in range(int(seen.min()) + 1, len(hist)):  # commands still travelling
            arrive = arrivals[k][None, :]
            acts = (k > seen) & ((k == len(hist) - 1) | (arrivals[k] < overtaken[min(
                k + 1, len(hist) - 1)]))
            arrive = np.where(acts[None, :], arrive, np.inf)
            later = (arrive > now) & (arrive <= times)  # reaches the vehicle within the horizon
            pres = np.where(later, model.evolve_pressure(pres, target, arrive - now), pres)
            now = np.where(later, arrive, now)
            target = np.where(arrive <= times, model.target_pressure(values[k]), target)
        pres = model.evolve_pressure(pres, target, np.maximum(times - now, 0.0))
        return (pres @ model.brake_scale) * friction_coefficient(np.asarray(speeds))

    def _onset_ahead(self, s: float) -> tuple[float, float]:
        """(planned application point, its stop) of the next planned stop (inf, inf: none)."""
        for onset, stop in self._onsets:
            if s < stop:
                return onset, stop
        return math.inf, math.inf

    # -- final approach --------------------------------------------------------------------
    def next_stop(self, s: float) -> float:
        """Position (m) of the next zero of the reference at or ahead of ``s`` (inf: none)."""
        ahead = self._stops[self._stops >= s - 1e-6]
        return float(ahead[0]) if ahead.size else math.inf

    def predicted_stop(self, v: float, s: float, release: bool, share: float = 1.0,
                       released_for: float = 0.0, h: float = 0.25,
                       horizon: float = 180.0) -> float:
        """Head position (m) where the train stops with the air brake held as it is now and no
        electric brake (``release`` False), or with the air brake released ``released_for`` s
        ago (each cylinder empties along the release wave,
        :meth:`plants.freight.FreightTrain.evolve_pressure`) and the electric brake going to
        ``share`` of its limit through the eq. (15) lag (``release`` True). One mass (eq. 7)
        with the modelled resistance; explicit midpoint steps of ``h`` s (inf: not stopped
        within ``horizon`` s)."""
        tp = self.p.train
        n = int(horizon / h) + 1
        air_scale = self.air_scale_schedule(release, released_for, h, n)
        decay = math.exp(-h / tp.traction_time_constant)
        force = min(self.force, 0.0)  # N, electric brake now (< 0)
        lag_steps = int(round(tp.traction_delay / h))
        return _integrate_stop(max(v, 0.0), s, h, n, air_scale.tolist(), force, decay,
                               lag_steps, share if release else None, self._stop_constants())

    def air_scale_schedule(self, release: bool, released_for: float, h: float,
                           n: int) -> np.ndarray:
        """Air-brake force per unit friction coefficient (N) at ``k h``, k < n, for
        :meth:`predicted_stop`: held as now, or releasing since ``released_for`` s."""
        model, tp = self.model, self.p.train
        pres = model.pressure
        if not release:
            return np.full(n, float(pres @ model.brake_scale))
        wait = np.maximum(model.release_delay - released_for, 0.0)
        empty = float(np.max(wait + tp.brake_release_time
                             * np.minimum(pres / tp.max_cylinder_pressure, 1.0)))
        n_air = min(int(empty / h) + 2, n)  # every cylinder empty from there on
        dt = np.maximum(np.arange(n_air)[:, None] * h - wait[None, :], 0.0)
        air_scale = np.zeros(n)
        air_scale[:n_air] = model.evolve_pressure(pres[None, :], 0.0, dt) @ model.brake_scale
        return air_scale

    def _stop_constants(self) -> tuple:
        """The plain-float constants of :func:`_integrate_stop`, made once."""
        if self._stop_consts is None:
            tp = self.p.train
            self._stop_consts = (self.m_eff, self._res_a, self._res_b, self._res_c,
                                 self._add_knots.tolist(), self._add_values.tolist(),
                                 tp.max_ed_force, tp.max_ed_power, tp.ed_fade_speed)
        return self._stop_consts

    def _final_approach(self, v: float, s: float) -> float | None:
        """The stop point (m) if the air brake is to be released now for an electric-brake final
        approach, else None: when the applied air brake alone would stop the train more than
        ``stop_tolerance`` short of the next stop (it cannot be partly released and the
        locomotive may not pull against it) and the train, released now with the full electric
        brake, would stop that much before the stop point."""
        p = self.p
        stop = self.next_stop(s)
        if not (self.reduction > 0.0 and 0.0 < stop - s <= p.final_approach_distance):
            return None
        if self.predicted_stop(v, s, release=False) >= stop - p.stop_tolerance:
            return None
        return stop if self.predicted_stop(v, s, release=True) <= stop - p.stop_tolerance \
            else None

    def _approach_force(self, t: float, v: float, s: float) -> float:
        """Final approach: the electric brake force (N, <= 0) whose share ``phi`` of the limit
        makes the predicted stop (:meth:`predicted_stop`, air brake releasing) the stop point,
        ``phi`` interpolated between the predictions with no and with the full electric
        brake and applied afresh every sample (feedback on the predicted stop)."""
        released_for = t - self.changed_at
        gap = self.approach_stop - s
        coast = self.predicted_stop(v, s, True, 0.0, released_for)
        if coast <= self.approach_stop:
            return 0.0
        full = self.predicted_stop(v, s, True, 1.0, released_for)
        if (full >= self.approach_stop or not math.isfinite(coast) or coast - full <= 1e-9
                or gap <= 0.0):
            share = 1.0  # coasting would not stop within the horizon: full electric brake
        else:
            share = (coast - self.approach_stop) / (coast - full)
        return -share * self.model.traction_limits(max(v, 0.0))[1]

    # -- one sample ------------------------------------------------------------------------
    def blend(self, t: float, T: float, v: float, s: float, force: float, v_ref: float,
              a_ref: float, a_res: float, locomotive: bool = False) -> tuple[float, float]:
        """Commands for the sample ``[t, t + T)``: ``(force_demand N, pipe_reduction Pa)``.

        ``force`` (N) is the controller's demand on the whole train (``locomotive``: on the
        locomotive alone, the controller having counted the air brake as a disturbance),
        ``v_ref``/``a_ref`` its reference speed and (look-ahead) acceleration, ``a_res`` the
        resistance (m/s^2)."""
        p = self.p
        speed = max(v, 0.0)
        trac, ed = self.model.traction_limits(speed)
        onset, onset_stop = self._onset_ahead(s)
        if s + 0.5 * speed * T < onset:
            # the planned braking never looks past a planned application (applied there)
            ahead = min(s + speed * p.air_preview_time, onset - 1e-6)
            planned = self.m_eff * (min(self.profile.accel(s), self.profile.accel(ahead))
                                    + a_res)
            if not math.isfinite(onset):
                planned = min(planned, self.m_eff * (a_ref + a_res))
        else:
            planned = self.m_eff * (min(a_ref, self.profile.accel(s),
                                        self.profile.accel(s + speed * p.air_preview_time))
                                    + a_res)
        over = v - v_ref > p.overspeed
        need = max(-planned, -force if over else 0.0)
        applied = self.reduction > 0.0
        since = t - self.changed_at
        # final stop: the reference has come to zero, or the air brake (too strong for the
        # last metres once the electric brake fades, and not partly releasable) stopped the
        # train short on the final braking segment
        self.holding = (v < p.stop_speed and self.profile.accel(s) <= 0.0
                        and (v_ref < p.stop_speed and self.peak_ahead(s) < p.stop_speed
                             or self.reduction > 0.0
                             or self.final_approach
                             and (v <= 0.0 or self.approach_stop - s <= p.stop_tolerance)))
        if self.holding:
            if self.reduction < p.hold_reduction:
                self.reduction, self.changed_at = p.hold_reduction, t
            self.final_approach = False
            force = 0.0
        elif self.final_approach:
            pass  # released for the final approach: no new application before the stop
        elif applied and (stop := self._final_approach(v, s)) is not None:
            self.reduction, self.changed_at, self.final_approach = 0.0, t, True
            self.approach_stop = stop
        elif applied:
            extra = -planned - p.ed_share * ed
            if extra > self.air_force(self.pressure_estimate, speed) and extra > 0:
                self.reduction = max(self.reduction, self._reduction_for(extra, speed))
            elif since >= p.min_apply_time and need < p.release_share * ed:
                self.reduction, self.changed_at = 0.0, t
        elif (since >= p.min_release_time
              and onset <= s + 0.5 * speed * T < min(onset + speed * T, onset_stop)):
            # the planned application of a stop, at the sample nearest to where the reference
            # plans it: the stage giving what the planned braking ``air_preview_time`` ahead
            # needs beyond the planned electric-brake share (the smallest stage on a reference
            # planned with it); a train already past it without the air brake, e.g. started
            # there, gets the generic rule below
            self.reduction = self.planned_reduction(s, speed, a_res)
            self.changed_at = t
        elif since >= p.min_release_time and need > p.ed_share * ed:
            # planned braking: the reduction giving the missing force; an overspeed alone:
            # the smallest application
            self.reduction = (self._reduction_for(-planned - p.ed_share * ed, speed)
                              if -planned > p.ed_share * ed else p.train.min_reduction)
            self.changed_at = t
        pressures = self.model.step_brakes(t, t + T, self.reduction)
        self.pressure_estimate = float(pressures.mean())
        if self.final_approach:
            force = self._approach_force(t, v, s)
        elif not self.holding and self.air_applied():
            # the locomotive trims the (estimated) air brake with the electric brake only:
            # never traction against an applied or not yet released air brake
            air = 0.0 if locomotive else float(np.dot(self.model.brake_scale, pressures)
                                               * friction_coefficient_at(speed))
            force = min(force + air, 0.0)
        self.force = min(max(force, -ed), trac)
        return self.force, self.reduction


def load_tracked_route(values: Mapping[str, Any], data_dir: Path) -> Route:
    """The route named by the ``route`` parameter; it must carry a reference profile."""
    route = load_route(values["route"], routes_dir_in(data_dir))
    if route.reference is None:
        raise ValueError(f"route {values['route']!r} has no reference profile")
    return route


def tracker_outputs(demand_description: str) -> tuple[Var, ...]:
    """Outputs of every freight speed controller (``accel_demand`` described per family)."""
    return (
        Var.output("force_demand", "N", "locomotive force demand (> 0 traction, < 0 electric "
                   "brake)"),
        Var.output("pipe_reduction", "Pa", "brake-pipe reduction (0 = released)"),
        Var.output("accel_demand", "m/s2", demand_description),
        Var.output("v_ref", "m/s", "reference speed at the measured position"),
        Var.output("a_ref", "m/s2", "reference acceleration (with preview)"),
        Var.output("speed_error", "m/s", "v - v_ref"),
        Var.output("air_brake_estimate", "Pa", "modelled mean cylinder pressure"),
        Var.output("v_mean_estimate", "m/s", "observed train-mean (centre-of-mass) speed"),
    )


class FreightTracker(StatefulCore, Declared):
    """Base of the freight speed controllers: measured head speed ``v`` and position ``s``,
    a core computing the acceleration demand ``a_dem`` (:meth:`accel_demand`, resistance
    included), the shared blending turning ``M (1 + gamma) a_dem`` into the plant commands.

    Every controller measures the locomotive (head) speed and position and tracks the
    reference at the head position; ``params_class`` needs ``blending``, ``sample_time``,
    ``mean_weight`` and ``observer_correction_time``. Every family feeds back the same speed,
    :attr:`v_feedback` = ``(1 - w) v_head + w v_c``, ``v_c`` of the train-mean speed observer
    (:class:`controllers.common.mean_observer.MeanSpeedObserver`) on :meth:`design_model`.
    """

    state_fields = ("blending", "v_ref", "a_ref", "demand", "speed_error", "observer",
                    "v_feedback")
    setup_vars = (route_parameter("freight_20km", "its reference profile is tracked"),)
    input_vars = (
        Var.input("v", "m/s", "measured head speed"),
        Var.input("s", "m", "measured head position"),
    )
    output_vars = tracker_outputs("acceleration demand a_dem (resistance included)")

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any], data_dir: Path,
                        t0: float = 0.0) -> FreightTracker:
        route = load_tracked_route(values, data_dir)
        return cls(build(cls.params_class, values), route.reference, route)

    def __init__(self, params: Any, profile: ReferenceProfile, route: Route) -> None:
        params.check()
        if not 0.0 <= params.mean_weight <= 1.0:
            raise ValueError(f"mean_weight = {params.mean_weight} must be in [0, 1]")
        self.p = params
        self.profile = profile
        self.route = route
        self.blending = FreightBlending(params.blending, profile, route)
        self.m_eff = self.blending.m_eff
        self.v_ref = 0.0
        self.a_ref = 0.0
        self.demand = 0.0  # m/s^2
        self.speed_error = 0.0  # m/s, v - v_ref
        self.observer = MeanSpeedObserver(self.design_model(), self.blending, self.sample_time,
                                          params.observer_correction_time)
        self.v_feedback = 0.0  # m/s, the fed-back speed (1 - w) v_head + w v_mean

    @property
    def sample_time(self) -> float:
        return float(self.p.sample_time)

    def design_model(self) -> DelayedModel:
        """Eq. (15)/(18) on the sample time with the nominal train's traction dead time and
        lag (the observer's model; the preview has its own design parameters)."""
        train = self.p.blending.train
        return lag_delay_model(self.sample_time, train.traction_delay,
                               train.traction_time_constant)

    @classmethod
    def native_data(cls, identifier: str, shipped: ShippedValues) -> dict[str, str]:
        """The build-time data of the native twin (:mod:`cosim.build.native`):
        ``sources/ato_freight_tracker.h``, what the core derives from the nominal train
        (``BlendingParams.train``, not an FMU parameter) at construction, computed by the core
        itself: the sums ``M (1 + gamma)``, weight, brake scale and the Davis terms (numpy's
        pairwise sums), each vehicle's brake scale and application / release delays, the
        brake-pipe and traction data, per bundled route with a distance reference profile the
        knots and values of the length-mean additional resistance and the reference's name,
        and the observer's design model (:meth:`design_model`) at the declared default sample
        time, 0.2 s (a native FMU refuses another one)."""
        params = BlendingParams()
        tp = params.train
        lines = ["/* generated by cosim/build/native.py from controllers.common.freight_blending"
                 " (the nominal train of BlendingParams); do not edit */",
                 "#ifndef ATO_FREIGHT_TRACKER_H", "#define ATO_FREIGHT_TRACKER_H"]
        routes = []
        model = None
        for toml in sorted(ROUTES_DIR.glob("*.toml")):
            try:
                route = load_route(toml.stem)
            except ValueError:  # a reference-profile TOML beside the routes
                continue
            if route.reference is None or route.reference.kind != "distance":
                continue
            b = FreightBlending(params, route.reference, route)
            model = b.model
            reference = Path(str(tomllib.loads(toml.read_text())["reference"])).stem
            routes.append((toml.stem, b, reference))
        if model is None:
            raise RuntimeError("no bundled route with a reference profile")
        b = routes[0][1]
        n = model.m_eff.size
        scalars = {
            "M_EFF": b.m_eff, "WEIGHT": b.weight, "BRAKE_SCALE_SUM": b.brake_scale,
            "RES_A": b._res_a, "RES_B": b._res_b, "RES_C": b._res_c, "KMH": kernels.KMH,
            "MAX_TRACTION_FORCE": tp.max_traction_force,
            "MAX_TRACTION_POWER": tp.max_traction_power, "MAX_ED_FORCE": tp.max_ed_force,
            "MAX_ED_POWER": tp.max_ed_power, "ED_FADE_SPEED": tp.ed_fade_speed,
            "TRACTION_DELAY": tp.traction_delay,
            "TRACTION_TIME_CONSTANT": tp.traction_time_constant,
            "MAX_CYLINDER_PRESSURE": tp.max_cylinder_pressure, "FILL_TIME": tp.brake_fill_time,
            "FILL_EXPONENT": tp.brake_fill_exponent, "RELEASE_TIME": tp.brake_release_time,
            "RELEASE_EXPONENT": tp.brake_release_exponent,
            "FULL_SERVICE_REDUCTION": tp.full_service_reduction,
            "MIN_REDUCTION": tp.min_reduction, "STICTION_SPEED": tp.stiction_speed,
            "RELEASED_PA": RELEASED_PA}
        lines.append(f"#define FT_N_VEHICLES {n}")
        lines += [f"#define FT_{k} {c_double(float(v))}" for k, v in scalars.items()]
        lines += [c_array("FT_BRAKE_SCALE", model.brake_scale),
                  c_array("FT_APPLY_DELAY", model.apply_delay),
                  c_array("FT_RELEASE_DELAY", model.release_delay)]
        T = 0.2  # the default sample time of the laws
        dm = lag_delay_model(T, tp.traction_delay, tp.traction_time_constant)
        lines += [f"#define FT_DESIGN_SAMPLE_TIME {c_double(T)}", f"#define FT_NZ {dm.n}",
                  c_array("FT_A", dm.A), c_array("FT_B", dm.B[:, 0]),
                  c_array("FT_E", dm.E[:, 0])]
        rows = []
        for k, (name, rb, reference) in enumerate(routes):
            lines += [c_array(f"FT_KNOTS_{k}", rb._add_knots),
                      c_array(f"FT_VALUES_{k}", rb._add_values)]
            rows.append(f"    {{{c_string(name)}, {c_string(reference)}, "
                        f"{rb._add_knots.size}, FT_KNOTS_{k}, FT_VALUES_{k}}},")
        lines += ["typedef struct { const char* route; const char* reference; int n;"
                  " const double* knots; const double* values; } ft_route;",
                  f"#define FT_N_ROUTES {len(rows)}",
                  "static const ft_route FT_ROUTES[FT_N_ROUTES] = {", *rows, "};", "#endif"]
        return {"sources/ato_freight_tracker.h": "\n".join(lines) + "\n"}

    #: a family that counts the air brake as a disturbance sets its locomotive's part of
    #: the demand (m/s^2) here in :meth:`accel_demand`; the blending then passes it on as it
    #: is (electric brake only while the air brake acts) instead of trimming the air brake
    locomotive_demand: float | None = None

    def accel_demand(self, t: float, v: float, s: float, a_res: float, lo: float,
                     hi: float) -> float:
        """The family's demand (m/s^2) within ``[lo, hi]``; sets ``self.a_ref``."""
        raise NotImplementedError

    def compute(self, t: float, inputs: dict[str, float]) -> tuple[dict[str, float], int]:
        """Observer update, the family's demand on the fed-back speed, blending; then the
        sample's locomotive force and modelled air brake go to the observer."""
        v, s = float(inputs["v"]), float(inputs["s"])
        self.v_feedback = fed_back_speed(v, self.observer.update(v, s), self.p.mean_weight)
        before = self.blending.model.pressure.copy()
        self._track(t, v, s)
        self.observer.record(self.blending.force, 0.5 * (before + self.blending.model.pressure),
                             s)
        return self.outputs(), 1

    def _track(self, t: float, v: float, s: float) -> None:
        speed = max(v, 0.0)
        self.v_ref = self.profile.speed(s)
        self.speed_error = v - self.v_ref
        a_res = self.blending.resistance_accel(speed, s)
        lo, hi = self.blending.accel_limits(speed)
        self.demand = self.accel_demand(t, v, s, a_res, lo, hi)
        loco = self.locomotive_demand
        self.blending.blend(t, self.sample_time, v, s,
                            self.m_eff * (self.demand if loco is None else loco), self.v_ref,
                            self.a_ref, a_res, locomotive=loco is not None)

    def outputs(self) -> dict[str, float]:
        b = self.blending
        return {"force_demand": b.force, "pipe_reduction": b.reduction,
                "accel_demand": self.demand, "v_ref": self.v_ref, "a_ref": self.a_ref,
                "speed_error": self.speed_error,
                "air_brake_estimate": b.pressure_estimate,
                "v_mean_estimate": self.observer.speed}


def interp_at(x: float, xp: list[float], fp: list[float]) -> float:
    """``np.interp(x, xp, fp)`` of one float on strictly increasing ``xp``, in plain floats
    with numpy's operations (its binary search, slope ``(fp[j+1] - fp[j]) / (xp[j+1] - xp[j])``
    and ``slope (x - xp[j]) + fp[j]``), so the result is the same float
    without numpy's per-call overhead."""
    if x <= xp[0]:
        return fp[0]
    if x >= xp[-1]:
        return fp[-1]
    j = bisect_right(xp, x) - 1
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    return slope * (x - xp[j]) + fp[j]


def _integrate_stop(v: float, s: float, h: float, n: int, air_scale: list[float],
                    force: float, decay: float, lag_steps: int, share: float | None,
                    consts: tuple) -> float:
    """The explicit-midpoint loop of :meth:`FreightBlending.predicted_stop` in plain floats:
    the same operations in the same order as its decel (eq. 7 with the modelled resistance,
    :func:`plants.freight.friction_coefficient_at`, the electric-brake limit of
    :meth:`plants.freight.FreightTrain.traction_limits`), inlined (``share`` None: the air
    brake held, no electric brake)."""
    m_eff, ra, rb, rc, knots, values, ed_force, ed_power, fade = consts
    release = share is not None
    vk, sk = v, s
    for k in range(n - 1):
        if release and k >= lag_steps:
            speed = abs(vk)
            ed = min(ed_force, ed_power / speed) if speed > 0 else ed_force
            if fade > 0 and speed < fade:
                ed *= speed / fade
            target = -share * ed
            force = target + (force - target) * decay
        air = air_scale[k]
        # decel at (vk, sk), then at the midpoint (the same expression twice, inlined)
        mu = friction_coefficient_at(vk)
        a0 = ((air * mu - force) / m_eff
              + ((ra + (rb + rc * vk) * vk) / m_eff + interp_at(sk, knots, values)))
        if a0 <= 0.0 and vk <= 0.0:
            return sk
        vm = vk - 0.5 * h * a0
        if vm <= 0.0:
            return sk + vk * vk / (2.0 * a0)
        mu = friction_coefficient_at(vm)
        am = ((air * mu - force) / m_eff
              + ((ra + (rb + rc * vm) * vm) / m_eff + interp_at(sk + 0.5 * h * vk, knots, values)))
        v1 = vk - h * am
        if v1 <= 0.0:
            return sk + vk * vk / (2.0 * am)
        sk += 0.5 * h * (vk + v1)
        vk = v1
    return math.inf
