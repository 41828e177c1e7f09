"""The paper's experiments (Experimental Results), as resumable grids of runs.

Data flows one way: each experiment trains, clusters or judges and writes its results
(``OUT/results/<name>.json`` and arrays); its figures are drawn from those results alone;
the report (:mod:`primspace.report`) reads them and computes nothing.

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

Reading results (import no experiment; the report uses only these):

- :mod:`~primspace.experiments.results`: file names, readers, tables and the qualitative verdict.
- :mod:`~primspace.experiments.calibration_results`: the calibrated start's table and verdict.
- :mod:`~primspace.experiments.claims`: the paper's sentences, verbatim, checked against results.
- :mod:`~primspace.experiments.claim_verdicts`: a rule's outcome, its verdict counted over seeds.
- :mod:`~primspace.experiments.figures`: every experiment figure, drawn from results files.

This package's ``__init__`` imports nothing, so reading results never loads an experiment.
"""
