"""Reading an experiment folder's results: what the report, the docs and the command line print.

The experiments (:mod:`primspace.experiments`) compute and write ``OUT/results/<name>.json``
and arrays; this package reads them (or a stored summary of them) and computes nothing
that needs a model, the data set or the simulator. It imports no experiment.

- :mod:`~primspace.results.layout`: the experiment folder's file names, in one module (the
  experiments write with it, the readers read with it).
- :mod:`~primspace.results.readers`: ``experiment.json``, the results and their arrays.
- :mod:`~primspace.results.tables`: the tables and the qualitative verdict of intra,
  clustering, success, inter, tune, predict and scene results.
- :mod:`~primspace.results.calibration`, :mod:`~primspace.results.composite`,
  :mod:`~primspace.results.act`: the tables of the calibrated start, the composite
  experiment and the act experiment.
- :mod:`~primspace.results.summary`: a summary of an experiment folder (``docs/results/NAME.json``).
- :mod:`~primspace.results.codes`: the codes file kept beside a summary, read back.
- :mod:`~primspace.results.claims`: the paper's sentences, verbatim, checked against results;
  each rule version in its own module (:mod:`~primspace.results.claim_rules_v1`, frozen,
  :mod:`~primspace.results.claim_rules_v2`, :mod:`~primspace.results.claim_rules_central`,
  :mod:`~primspace.results.claim_rules_v4`), all over one module of measures
  (:mod:`~primspace.results.measures`); a claim and a rule's outcome and verdict are
  :mod:`~primspace.results.claim_verdicts`'s.

This package's ``__init__`` imports nothing.
"""
