"""Build-time side: what makes the FMUs and runs in none. :mod:`cosim.build.python` is the
catalog of the wrappers (``plants/**/*_fmu.py``, ``controllers/**/*_fmu.py``) and the builder of
their Python FMUs, :mod:`cosim.build.fmi3` their FMI 3.0 builds, :mod:`cosim.build.native`
the native C FMUs (FMI 2.0, and FMI 3.0 derived from them) from the C of ``cosim/fmu/native``
(its folders ``runtime``, ``numerics``, ``plants`` and ``controllers``) and the fronts of
``cosim/fmu/front``, the Python wrappers' declarations and the data
the cores compute at build time, :mod:`cosim.build.solvers` the C sources of the numerical
solvers they link, taken from the solvers' published source distributions, and
:mod:`cosim.build.reference` the FMU reference page.

Nothing here is bundled into an FMU (:func:`cosim.build.python.bundled_files`). It stands
above the cores, as its import statements say: the native builder imports ``plants`` (the
route data every native model reads) and reaches each model's core through the catalog, whose
``native_data`` says what that core ships to its C twin. ``cosim.run`` imports it to build
what a scenario needs (``tests/test_layering.py``).
"""
