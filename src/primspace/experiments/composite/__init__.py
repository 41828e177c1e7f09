"""The composite experiment: long demonstrations of several primitives, segmented and scored.

- :mod:`~primspace.experiments.composite.experiment`: the experiment (``primspace experiment
  composite``): the grid of window-code runs, their segmentation and scores, then the peers
  and the model of single primitives per seed.
- :mod:`~primspace.experiments.composite.peers`: the peers (ruptures, a Gaussian HMM) and the
  upper bounds per seed, on the runs' held-out demonstrations.
- :mod:`~primspace.experiments.composite.primitives`: segmentation by a model of single
  primitives (synthesis and surprise) per seed.
- :mod:`~primspace.experiments.composite.timeline`: the arrays of the timeline figures.

Each module imports only those listed after it (``timeline`` none of them). The tables of
its results are :mod:`primspace.results.composite` (read by the report, the command line
and the docs). This package's ``__init__`` imports nothing.
"""
