"""Paper-specific metrics: pure functions of a run's recorded arrays, one module per paper."""
