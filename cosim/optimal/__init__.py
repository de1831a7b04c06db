"""Energy-optimal train control on any line and any train (offline planning).

:mod:`cosim.optimal.model` is the train and line model (the project's physics:
:class:`plants.resistance.Davis`, :class:`plants.route.Route`, the CRH3 data of
:mod:`plants.crh3`), :mod:`cosim.optimal.pontryagin` the optimum by the theory of optimal train
control, :mod:`cosim.optimal.ttobench` the reader of TTOBench's JSON tracks, trains and journeys,
:mod:`cosim.optimal.output` the CSV and figure of a profile (``cosim optimal``), and
:mod:`cosim.optimal.closed_loop` the route, reference and scenario with which a shipped
tracking controller follows a profile in co-simulation (``cosim optimal --closed-loop``).

No FMU core and nothing under ``cosim/run`` imports this package, nor does it import the
runner: it plans profiles and writes scenarios; ``cosim optimal`` runs them.
"""
