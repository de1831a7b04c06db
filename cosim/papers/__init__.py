"""Paper-specific metrics: one module per paper, called from :mod:`cosim.run.metrics`."""
