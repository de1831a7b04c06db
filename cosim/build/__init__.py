"""Build-time side: what makes the FMUs and runs in no FMU. :mod:`cosim.build.native` writes
the native C FMUs (FMI 2.0, and FMI 3.0 derived from them) from the C models and fronts of
``cosim/fmu/native`` and ``cosim/fmu/front``, the Python wrappers' declarations and the data
the cores compute at build time; :mod:`cosim.build.solvers` takes the C sources of the
numerical solvers they link from the solvers' published source distributions.

Nothing here is bundled into an FMU (``cosim.fmu.build.bundled_files``). Its import
statements name ``cosim.fmu`` only; the native builder loads the wrappers through the catalog
(``cosim.fmu.build.catalog``) and the modules of ``plants`` and ``controllers`` whose data it
exports (and ``cosim.run.scenario`` for the shipped scenarios) by name with ``importlib``.
``cosim.run`` imports it to build what a scenario needs (``tests/test_layering.py``).
"""
