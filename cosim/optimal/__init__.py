"""Energy-optimal train control on any line and any train (offline planning).

:mod:`cosim.optimal.model` is the train and line model (the project's physics:
:class:`plants.resistance.Davis`, :class:`plants.route.Route`, the CRH3 data of
:mod:`plants.crh3`), :mod:`cosim.optimal.pontryagin` the optimum by the theory of optimal train
control, :mod:`cosim.optimal.ttobench` the reader of TTOBench's JSON tracks, trains and journeys,
and :mod:`cosim.optimal.output` the CSV and figure of a profile (``cosim optimal``).

No FMU core and nothing under ``cosim/run`` imports this package: it plans profiles, it does not
run in co-simulation.
"""
