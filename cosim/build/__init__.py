"""Build-time side: what makes the FMUs and runs in no FMU. :mod:`cosim.build.native` writes
the native C FMUs (FMI 2.0, and FMI 3.0 derived from them) from the C models and fronts of
``cosim/fmu/native`` and ``cosim/fmu/front``, the Python wrappers' declarations and the data
the cores compute at build time; :mod:`cosim.build.solvers` takes the C sources of the
numerical solvers they link from the solvers' published source distributions.

Nothing here is bundled into an FMU (``cosim.fmu.build.bundled_files``). It stands above
the cores, as its import statements say: it imports ``cosim.fmu`` and ``plants`` (the route
data every native model reads), and reaches each model's core through the catalog
(``cosim.fmu.build.catalog``), whose ``native_data`` says what that core ships to its C twin.
``cosim.run`` imports it to build what a scenario needs (``tests/test_layering.py``).
"""
