"""Co-simulation master, scenarios, results and CLI for train/ATO FMUs.

Kept import-free: ``cosim.fmu.slave`` is bundled into FMUs that do not have this package.
"""

__version__ = "0.1.0"
