"""The names other modules of :mod:`cosim.run` read here: the reproduction itself is the package
:mod:`cosim.reproduce`."""

from __future__ import annotations

from cosim.run.figures import reference_curve

__all__ = ["reference_curve"]
