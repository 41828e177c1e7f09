"""The paper's experiments (Experimental Results), as resumable grids of runs.

- :mod:`~primspace.experiments.intra`: intra-primitive generalisation (20% fit, 80% infer).
- :mod:`~primspace.experiments.clustering`: subspace clustering of learned latents and of raw
  trajectories.
- :mod:`~primspace.experiments.success`: success rates of generated motions, judged by the simulator.
- :mod:`~primspace.experiments.inter`: inter-primitive generalisation (leave one primitive out).
- :mod:`~primspace.experiments.sweep`: the grid runner (local processes or Ray; skips finished runs).
"""
