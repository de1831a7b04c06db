"""Running side: scenarios, the co-simulation master, results, metrics and sweeps."""

# runs a sweep starts unless allowed more (cosim sweep --max-runs); here, not in
# cosim.run.grid, so the CLI gets the default without importing the scenario module
MAX_RUNS = 10_000
