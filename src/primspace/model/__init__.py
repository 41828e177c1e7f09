"""The generative model (paper, *RNN Architecture* and *Initialization of Latent Vectors*).

- :mod:`~primspace.model.config`: :class:`~primspace.model.config.ModelConfig`, the decoder's
  sizes (torch-free, so configs and the command line's defaults load without torch);
- :mod:`~primspace.model.decoder`: :class:`~primspace.model.decoder.MTRNNDecoder`, the MTRNN
  decoder d(θ, z) of joint angles and camera frames;
- :mod:`~primspace.model.latent`: the codes and how they start (zero, random, the random
  projection z = P m, PCA) and the per-sample code table;
- :mod:`~primspace.model.calibration`: the calibrated start, a ridge map from a run's initial
  codes to its fitted codes.

Import from the modules; this package imports nothing, so ``import primspace.model.config``
does not load torch.
"""
