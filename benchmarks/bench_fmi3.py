"""Master overhead of the FMI 3.0 path against the FMI 2.0 path on the same scenario.

Our FMUs' FMI 3.0 builds are not used here: the pair is the plain-C test FMUs of
tests/third_party, one per standard, of the same trivial model (a clock x = t feeding a
feedthrough y = u; FMI 2: Terminator and Feedthrough, FMI 3: Terminator3 and Feedthrough3),
so the FMUs' own work is negligible and the time is the master's (unit calls, exchange,
recording, events). Both scenarios: event algorithm, the same grid, the same two recorded
variables. Runs alternate FMI 2 / FMI 3 ``repeat`` times after a warm-up of both; reported:
median loop wall time (communication points alone) per scenario and the ratio FMI 3 / FMI 2.

    python benchmarks/bench_fmi3.py [--repeat N] [--stop S]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests" / "third_party")]

from third_party_fmus import build_all  # noqa: E402
from third_party_fmus3 import build_all3  # noqa: E402

from cosim.run.master import Master  # noqa: E402
from cosim.run.scenario import load_scenario  # noqa: E402


def scenario(tmp: Path, name: str, clock: Path, ft: Path, u: str, y: str, extra: str,
             stop: float, step: float) -> Path:
    path = tmp / f"{name}.toml"
    path.write_text(f"""[simulation]
stop_time = {stop!r}
output_interval = {step!r}
algorithm = "event"
[fmus.clock]
fmu = "{clock}"
[fmus.clock.parameters]
stop_at = {2 * stop!r}
[fmus.ft]
fmu = "{ft}"
{extra}
[connections]
"ft.{u}" = "clock.x"
[record]
variables = ["clock.x", "ft.{y}"]
""")
    return path


def loop_time(path: Path) -> float:
    master = Master(load_scenario(path))
    master.run()
    return master.loop_wall_time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--stop", type=float, default=200.0)
    args = parser.parse_args()
    step = 0.0078125  # binary-exact: the same points in both
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        f2, f3 = build_all(tmp / "fmi2"), build_all3(tmp / "fmi3")
        consts = "\n".join(
            f'{k} = {v}' for k, v in (("u_Float32", 0.5), ("u_Int8", 1), ("u_UInt8", 1),
                                      ("u_Int16", 1), ("u_UInt16", 1), ("u_Int32", 1),
                                      ("u_UInt32", 1), ("u_Int64", 1), ("u_UInt64", 1),
                                      ("u_Boolean", "false"), ("u_String", '"s"'),
                                      ("u_Binary", '"00"'), ("u_Enumeration", 1),
                                      ('"ua[1]"', 0.0), ('"ua[2]"', 0.0), ('"ua[3]"', 0.0)))
        s2 = scenario(tmp, "fmi2", f2["Terminator"], f2["Feedthrough"], "u", "y",
                      "[fmus.ft.parameters]\nk = 1.0", args.stop, step)
        s3 = scenario(tmp, "fmi3", f3["Terminator3"], f3["Feedthrough3"], "u_Float64",
                      "y_Float64", f"[fmus.ft.inputs]\n{consts}", args.stop, step)
        loop_time(s2), loop_time(s3)  # warm-up
        t2, t3 = [], []
        for _ in range(args.repeat):
            t2.append(loop_time(s2))
            t3.append(loop_time(s3))
    m2, m3 = statistics.median(t2), statistics.median(t3)
    points = int(args.stop / step)
    print(f"{points} communication points, median of {args.repeat} "
          f"({time.strftime('%Y-%m-%d %H:%M')})")
    print(f"FMI 2.0 path: {m2:.3f} s ({1e6 * m2 / points:.1f} us/point)")
    print(f"FMI 3.0 path: {m3:.3f} s ({1e6 * m3 / points:.1f} us/point)")
    print(f"ratio FMI 3 / FMI 2: {m3 / m2:.2f}")


if __name__ == "__main__":
    main()
