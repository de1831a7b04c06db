"""FMU-authoring side: what is bundled into the FMUs (time ticks, core state, declarations,
reference profiles, the slave base, the literals of a core's build-time data for C) and the C
an FMU holds (the Python FMUs' shim, the FMI fronts, the native models); the builders are
:mod:`cosim.build`.

The lowest layer: its modules import only the standard library, numpy and pythonfmu, and
nothing else of this project (``tests/test_layering.py``).
"""
