"""The paper's experiments (Experimental Results), as resumable grids of runs.

Data flows one way: each experiment trains, clusters or judges and writes its results
(``OUT/results/<name>.json`` and arrays, named by :mod:`primspace.results.layout`); its
figures are drawn from those results alone; the report (:mod:`primspace.report`) reads
them and computes nothing.

Compute (each writes results, then draws its figures):

- :mod:`~primspace.experiments.intra`: intra-primitive generalisation (20% fit, 80% infer).
- :mod:`~primspace.experiments.clustering`: subspace clustering of learned latents and of raw
  trajectories.
- :mod:`~primspace.experiments.success`: success rates of generated motions, judged by the simulator.
- :mod:`~primspace.experiments.inter`: inter-primitive generalisation (leave one primitive out).
- :mod:`~primspace.experiments.appendix_a`: the paper's Appendix A, sampled on the data.

Shared by them:

- :mod:`~primspace.experiments.presets`: the settings (a ModelConfig and a TrainConfig inside).
- :mod:`~primspace.experiments.runs`: run keys, per-run configurations, data, codes.
- :mod:`~primspace.experiments.workspace`: the experiment directory (data, stages, grids).
- :mod:`~primspace.experiments.sweep`: the grid runner (local processes or Ray; skips finished runs).
- :mod:`~primspace.experiments.summary_codes`: the codes of the runs, gathered beside a summary.

Drawing:

- :mod:`~primspace.experiments.figures`: every experiment figure, drawn from results files.

Reading results is :mod:`primspace.results`'s (the folder's layout, readers, tables, the
claims); the experiments write with its layout and read back with its readers, and the
report reads only it.

This package's ``__init__`` imports nothing, so reading results never loads an experiment.
"""
