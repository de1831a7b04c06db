"""FMU-authoring side: what is bundled into every FMU (time ticks, core state, declarations,
reference profiles, the slave base) and the builder that bundles it.

The lowest layer: its modules import only the standard library, numpy and pythonfmu, and
nothing else of this project (``tests/test_layering.py``).
"""
