"""Paper reproductions as data plus one command: ``cosim reproduce NAME`` / ``cosim reproduce all``.

One module per job:

- :mod:`cosim.reproduce.entry`: an entry ``papers/NAME/entry.toml`` as typed data and
  its one loader (:func:`cosim.reproduce.entry.load_entry`), of the parts in
  :mod:`cosim.reproduce.parts`, whose fields are TOML keys (:mod:`cosim.reproduce.fields`);
  its ``[ensemble]`` table (:mod:`cosim.reproduce.ensemble`) and its ``[[claims]]``, claim
  families expanded (:mod:`cosim.reproduce.claims`);
- :mod:`cosim.reproduce.schema`: the schema page ``docs/reproduce_schema.md`` written from them;
- :mod:`cosim.reproduce.run`: the simulations an entry needs (the claims' members:
  :mod:`cosim.reproduce.members`), and :mod:`cosim.reproduce.record` their record;
- :mod:`cosim.reproduce.stats`: a claim's statistics and verdict on its members;
  :mod:`cosim.reproduce.verdicts`: every claim of an entry evaluated on the record, adjusted
  for multiplicity, ``claims.csv`` / ``claims.md``;
- :mod:`cosim.reproduce.tables`: the tables (ours beside the paper's, derived figures,
  rankings) and their markdown, in the fixed notation of :mod:`cosim.reproduce.numbers`;
- :mod:`cosim.reproduce.figures`: the figures and sweeps of the page;
- :mod:`cosim.reproduce.page`: the page made from a record alone, and the command end to end.
"""
