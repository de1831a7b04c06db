"""Running side: scenarios, the co-simulation master, results, metrics and sweeps."""
