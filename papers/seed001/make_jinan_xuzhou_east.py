"""Generate the synthetic Jinan West - Xuzhou East line and its 300 km/h reference profile.

    python papers/seed001/make_jinan_xuzhou_east.py
    # writes plants/routes/jinan_xuzhou_east.toml, jinan_xuzhou_east_reference.csv (the
    # reserve TRACTION_RESERVE) and jinan_xuzhou_east_reference_reserve_0p045.csv,
    # ..._reserve_0p18.csv (the variant reserves VARIANT_RESERVES)
    python papers/seed001/make_jinan_xuzhou_east.py --reserve 0.045
    # writes only the reference at that reserve, beside the line's existing TOML

How the line is made (seed 001 only names the section; its Fig. 4 is not in the text):

* Length and stations: chainage of the Beijing-Shanghai high-speed railway (public station
  table: Jinan West km 419.445, Tai'an 462.730, Qufu East 533.165, Tengzhou East 589.175,
  Zaozhuang West 625.280, Xuzhou East 688.700), so the section is 269.255 km long.
* Grade follows an elevation profile: the track elevation is interpolated linearly between
  approximate ground elevations of the stations (:data:`STATION_ELEVATION_M`, rounded public
  topographic figures: the line starts and ends low on the North China / Huang-Huai plain and
  climbs to about 140 m at Tai'an), plus a random undulation that vanishes at every station
  (amplitude 10 m on the plain, 30 m in the hilly Tai'an - Qufu stretch, half-sine window
  between stations). Segments of 1.5-6 km get the grade of that profile (0.5 permille steps,
  the rounding carried into the next segment, capped at the line's design maximum of 20), so
  the integrated elevation meets every station's and the section ends 5 m above its start
  instead of drifting (independent random grades wander like a random walk: a draw of them
  can end Xuzhou East 305 m below Jinan West, a mostly downhill run).
* Curves and tunnels are synthetic, drawn with a fixed seed within the line's public design
  figures (minimum curve radius mostly 7,000 m): curves of 7,000-12,000 m every 8-15 km;
  tunnels in the hilly Tai'an - Qufu stretch.
* Speed limits: 160 km/h over the first and last 2.5 km (station throats), 350 km/h line
  speed, and one 250 km/h temporary restriction (km 150-156 from Jinan West).
* Neutral sections (200 m) about every 25 km, none in the last 10 km.

How the reference profile is made: a single-mass run of the CRH380A (seed 001 masses,
resistance and the traction/brake envelope of :mod:`plants.emu`, summed over the units) on this
line, computed on a 25 m grid: traction at the envelope minus a reserve (and at most 0.5 m/s^2)
up to the cruise speed of 300 km/h or the speed limit minus 5 km/h; cruise (speed falls where
the envelope minus the reserve cannot hold it uphill); coasting (no traction) from 300 m before each
neutral section until the tail has passed it by 100 m; service braking at 0.4 m/s^2 ahead of
lower limits and 0.5 m/s^2 to the stop at Xuzhou East (backward pass). The reserve,
:data:`TRACTION_RESERVE` = 0.09 m/s^2 of the whole train's mass, is 3 sigma of the slowly
varying disturbance the seed 001 reproduction applies (0.03 m/s^2 per unit mass, the main rows
of papers/seed001/entry.toml): a real ATO plans its profile with a traction reserve, and
with it a retarding disturbance exceeds what is left above the profile in 0.13 % of the time
even if the three units' disturbances were fully correlated (they are independent, so the
train's mean is 5 sigma inside). A profile at 85 % of the envelope would leave only
0.033 m/s^2 at 300 km/h (the disturbance's own sigma): every controller would sit on the power
limit alike when accelerating at high speed, and the comparison would measure the envelope,
not the laws. The reserve is our open choice (the paper gives no profile), so profiles at half
and twice it, :data:`VARIANT_RESERVES` = 0.045 and 0.18 m/s^2, are written too
(``jinan_xuzhou_east_reference_reserve_0p045.csv``, ``..._0p18.csv``: the decimal point
spelled ``p``, since a bundled name has no suffix; the variant rows of
papers/seed001/entry.toml set them as the controllers' ``reference``). Braking needs no
reserve: the brake envelope gives at least 0.70 m/s^2 up to 300 km/h, above 0.5 m/s^2 plus
the largest reserve. The CSV stores ``position_m, speed_kmh``; between points the
acceleration is constant (see plants/route.py).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # papers/NAME/ -> the repository
sys.path.insert(0, str(ROOT))

from plants.emu import emu_config  # noqa: E402
from plants.route import GRAVITY, KMH, load_reference, load_route  # noqa: E402

NAME = "jinan_xuzhou_east"
SEED = 2011
CHAINAGE_KM = [("Jinan West", 419.445), ("Tai'an", 462.730), ("Qufu East", 533.165),
               ("Tengzhou East", 589.175), ("Zaozhuang West", 625.280),
               ("Xuzhou East", 688.700)]
# approximate ground elevation (m) at each station, rounded public topographic figures
STATION_ELEVATION_M = {"Jinan West": 35.0, "Tai'an": 140.0, "Qufu East": 65.0,
                       "Tengzhou East": 65.0, "Zaozhuang West": 70.0, "Xuzhou East": 40.0}
GRID_M = 25.0
CRUISE_KMH = 300.0
TRACTION_RESERVE = 0.09  # m/s^2 of the train's mass: 3 x 0.03 m/s^2 (seed 001 main rows)
VARIANT_RESERVES = (0.045, 0.18)  # m/s^2: half and twice TRACTION_RESERVE (variant rows)
MAX_REF_ACCEL = 0.5  # m/s^2
LIMIT_MARGIN_KMH = 5.0
DECEL_LIMIT = 0.4  # m/s^2, ahead of a lower speed limit
DECEL_STOP = 0.5  # m/s^2, to the final stop


def _round(x: float, step: float) -> float:
    return round(x / step) * step


def make_line(rng: np.random.Generator) -> dict:
    origin = CHAINAGE_KM[0][1]
    stations = [[name, round((km - origin) * 1000.0, 1)] for name, km in CHAINAGE_KM]
    length = stations[-1][1]
    hilly = (20e3, 120e3)
    st_pos = np.array([pos for _, pos in stations])
    st_elev = np.array([STATION_ELEVATION_M[name] for name, _ in stations])

    def target(x: float, bump: float) -> float:
        """Station-interpolated elevation plus ``bump`` x a half-sine vanishing at stations."""
        k = min(int(np.searchsorted(st_pos, x, side="right")) - 1, st_pos.size - 2)
        frac = (x - st_pos[k]) / (st_pos[k + 1] - st_pos[k])
        return float(np.interp(x, st_pos, st_elev)) + bump * math.sin(math.pi * frac)

    bounds, s = [0.0], 0.0
    while s < length:
        s += _round(rng.uniform(1.5e3, 6e3), 100.0)
        bounds.append(min(s, length))
    if bounds[-1] - bounds[-2] < 500.0 and len(bounds) > 2:
        del bounds[-2]  # no sliver at the end
    grade, elev = [], st_elev[0]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        amp = 30.0 if hilly[0] <= b < hilly[1] else 10.0
        goal = target(b, amp * rng.uniform(-1.0, 1.0)) if b < length else st_elev[-1]
        g = float(np.clip(_round((goal - elev) / (b - a) * 1000.0, 0.5), -20.0, 20.0))
        grade.append([round(a, 1), g])
        elev += g * (b - a) / 1000.0
    curves, s = [], 5e3
    while s < length - 8e3:
        s += _round(rng.uniform(8e3, 15e3), 100.0)
        end = s + _round(rng.uniform(1.5e3, 4e3), 100.0)
        if end < length - 5e3:
            curves.append([s, end, float(rng.choice([7000.0, 8000.0, 9000.0, 10000.0, 12000.0]))])
        s = end
    tunnels, s = [], hilly[0] + 10e3
    while s < hilly[1] - 5e3:
        s += _round(rng.uniform(6e3, 18e3), 100.0)
        tunnels.append([s, s + _round(rng.uniform(300.0, 2000.0), 10.0)])
        s = tunnels[-1][1]
    neutral, s = [], 12e3
    while s < length - 10e3:
        neutral.append([s, s + 200.0])
        s += _round(rng.uniform(22e3, 28e3), 100.0)
    limits = [[0.0, 160.0 * KMH], [2500.0, 350.0 * KMH], [150e3, 250.0 * KMH],
              [156e3, 350.0 * KMH], [length - 2500.0, 160.0 * KMH]]
    return dict(name=NAME, length_m=length, stations=stations, grade=grade, curves=curves,
                tunnels=tunnels, neutral_sections=neutral, speed_limits=limits)


def write_toml(line: dict, path: Path) -> None:
    def rows(key: str, fmt) -> str:
        body = ",\n".join("    " + fmt(r) for r in line[key])
        return f"{key} = [\n{body},\n]\n"

    text = [
        "# Synthetic Jinan West - Xuzhou East section of the Beijing-Shanghai high-speed line\n"
        "# (seed 001). Generated by papers/seed001/make_jinan_xuzhou_east.py (seed "
        f"{SEED}); see plants/routes/README.md.\n",
        f'name = "{line["name"]}"\n',
        f"length_m = {line['length_m']}\n",
        f'reference = "{NAME}_reference.csv"\n',
        rows("stations", lambda r: f'["{r[0]}", {r[1]}]'),
        "# [start_m, permille], uphill > 0\n" + rows("grade", lambda r: f"[{r[0]}, {r[1]}]"),
        "# [start_m, end_m, radius_m]\n"
        + rows("curves", lambda r: f"[{r[0]}, {r[1]}, {r[2]}]"),
        "# [start_m, end_m]\n" + rows("tunnels", lambda r: f"[{r[0]}, {r[1]}]"),
        "# [start_m, end_m], no traction power\n"
        + rows("neutral_sections", lambda r: f"[{r[0]}, {r[1]}]"),
        "# [start_m, limit_m_per_s] (160, 350, 250, 350, 160 km/h)\n"
        + rows("speed_limits", lambda r: f"[{r[0]}, {r[1]!r}]"),
    ]
    path.write_text("\n".join(text))


def reference_name(reserve: float) -> str:
    """Bundled name of the reference planned with ``reserve`` (m/s^2): the main one for
    :data:`TRACTION_RESERVE`, else ``<NAME>_reference_reserve_<reserve>`` with the decimal
    point spelled ``p`` (0.045 -> ``0p045``)."""
    if reserve == TRACTION_RESERVE:
        return f"{NAME}_reference"
    return f"{NAME}_reference_reserve_{reserve:g}".replace(".", "p")


def make_reference(route_path: Path, reserve: float = TRACTION_RESERVE
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Positions (m) and speeds (m/s) of the reference on the 25 m grid, accelerating at the
    traction envelope minus ``reserve`` (m/s^2 of the train's mass)."""
    route = load_route(route_path)
    p = emu_config("crh380a_3unit")
    mass = sum(p.masses)
    train_length = sum(p.lengths)
    a, b, c = sum(p.davis_a), sum(p.davis_b), sum(p.davis_c)
    ft, pt = sum(p.max_traction_force), sum(p.max_traction_power)
    s = np.arange(0.0, route.length_m + GRID_M / 2, GRID_M)
    s[-1] = route.length_m
    limit = np.minimum(route.speed_limit.at_array(s) - LIMIT_MARGIN_KMH * KMH, CRUISE_KMH * KMH)
    w_add = route.additional_resistance(s, train_length)  # N/kN over the train length
    coast = np.zeros(s.size, dtype=bool)
    starts, values = route.neutral.starts, route.neutral.values
    for i in range(1, starts.size - 1):
        if values[i] > 0:
            coast |= (s >= starts[i] - 300.0) & (s <= starts[i + 1] + train_length + 100.0)
    v = np.zeros(s.size)
    for i in range(s.size - 1):
        vi = v[i]
        resist = (a + b * vi + c * vi * vi + mass * GRAVITY * w_add[i] / 1000.0) / mass
        if coast[i]:
            acc = -resist
        else:
            traction = min(ft, pt / max(vi, 1e-3)) / mass - reserve
            acc = min(traction - resist, MAX_REF_ACCEL)
        ds = s[i + 1] - s[i]
        v[i + 1] = math.sqrt(max(min(vi * vi + 2.0 * acc * ds, limit[i + 1] ** 2), 0.0))
    v[-1] = 0.0
    for i in range(s.size - 2, -1, -1):  # braking: to lower limits and to the stop
        decel = DECEL_STOP if s[i] > route.length_m - 12e3 else DECEL_LIMIT
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * decel * (s[i + 1] - s[i])))
    return s, v


def write_reference(toml_path: Path, reserve: float) -> Path:
    """Write the reference planned with ``reserve`` (m/s^2) beside the line ``toml_path``,
    print its run time, and return its path."""
    csv_path = toml_path.parent / f"{reference_name(reserve)}.csv"
    s, v = make_reference(toml_path, reserve)
    lines = [f"# Reference speed-distance profile of {NAME} (CRH380A, 300 km/h class);",
             "# generated by papers/seed001/make_jinan_xuzhou_east.py, see plants/routes/README.md",
             "position_m,speed_kmh"]
    if reserve != TRACTION_RESERVE:
        lines.insert(2, f"# traction reserve {reserve:g} m/s^2 (the main profile's is "
                        f"{TRACTION_RESERVE:g} m/s^2)")
    lines += [f"{si:.1f},{vi / KMH:.4f}" for si, vi in zip(s, v, strict=True)]
    csv_path.write_text("\n".join(lines) + "\n")
    print(f"{csv_path.name}: reserve {reserve:g} m/s^2, run time "
          f"{load_reference(csv_path).run_time():.1f} s, max {v.max() / KMH:.1f} km/h")
    return csv_path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reserve", type=float, action="append",
                        help="write only the reference at this traction reserve (m/s^2), "
                             "beside the existing line TOML; repeatable")
    args = parser.parse_args()
    out = ROOT / "plants" / "routes"
    toml_path = out / f"{NAME}.toml"
    if args.reserve:
        for reserve in args.reserve:
            write_reference(toml_path, reserve)
        return
    rng = np.random.default_rng(SEED)
    line = make_line(rng)
    write_toml(line, toml_path)
    csv_path = out / f"{NAME}_reference.csv"
    csv_path.write_text("position_m,speed_kmh\n0.0,0.0\n1.0,0.0\n")  # placeholder to load route
    # the reference itself: load_route keeps the route parsed above (with the placeholder)
    print(f"{toml_path}: {line['length_m'] / 1e3:.3f} km")
    for reserve in (TRACTION_RESERVE, *VARIANT_RESERVES):
        write_reference(toml_path, reserve)


if __name__ == "__main__":
    main()
