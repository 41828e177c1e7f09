"""Segment codes by inference with θ frozen: each segment found by a model of single primitives
gets a code of its own, and the segments are labelled by clustering those codes.

Synthesis and surprise (:mod:`~primspace.segmentation.synthesis`,
:mod:`~primspace.segmentation.surprise`) give each segment the code of its nearest template:
a few dozen distinct codes (one per fitted primitive) stand for hundreds of segments, and a
segment is labelled by which template it is nearest. This module gives each segment an inferred
code instead (the segment resampled to the model's length, warm-started): the paper's evaluation
(``infer``, θ frozen) run on the segments themselves, so that each segment's code places it
in the single-primitive latent space, where the paper's clustering works (Summary and
Discussion, verbatim: "Moreover, these manifolds are close enough to affine subspaces, which
enables us to use subspace clustering algorithm for labeling a collection of motion in
unsupervised manner.").

1. Each segment is resampled to the model's ``T1`` steps and moved into the model's frame:
   its start offset from its nearest template removed as the offset model says (faded out,
   or kept throughout: ``x_t - c_t (x_0 - y_0)``), then unscaled by the run's scaler.
2. :func:`primspace.train.infer` finds the codes with θ frozen, ``epochs`` epochs, each
   started from its nearest template's code (warm start).
3. The inferred codes are clustered by affine LRSC, τ chosen without labels
   (:func:`~primspace.segmentation.result.label_segments`).
"""

from __future__ import annotations

import numpy as np

from primspace.data import MotionDataset, resample
from primspace.segmentation.result import SegmentationResult, label_segments
from primspace.utils.errors import UserError

__all__ = ["in_model_frame", "infer_segment_codes", "relabel_by_inference"]


def in_model_frame(
    sequences, result: SegmentationResult, templates: np.ndarray, nearest: np.ndarray, fade: float
) -> np.ndarray:
    """Every segment of ``result`` resampled to ``T1`` steps with its start offset from its
    nearest template removed (module docstring, 1): ``(S, T1, J)``, scaled units."""
    t1 = templates.shape[1]
    ramp = np.clip(1.0 - np.arange(t1) / (fade * t1), 0.0, 1.0)[:, None]
    pieces = resample(
        [
            np.asarray(sequences[i][a:b], dtype=np.float64)
            for i, a, b in zip(result.segment_sample, result.segment_start, result.segment_stop)
        ],
        t1,
    )
    offsets = pieces[:, :1] - templates[nearest][:, :1]
    return pieces - ramp[None] * offsets


def infer_segment_codes(run, pieces: np.ndarray, start_codes: np.ndarray, epochs: int, joint_names=None) -> np.ndarray:
    """Codes of ``pieces`` (scaled, ``(S, T1, J)``) inferred with the run's θ frozen for
    ``epochs`` epochs from ``start_codes`` ``(S, q)``."""
    from primspace.train import infer

    if int(epochs) < 1:
        raise UserError(f"inference epochs must be at least 1, got {epochs}")
    motor = run.scaler.inverse_transform(pieces)
    names = list(joint_names) if joint_names is not None else None
    segments = MotionDataset(motor=motor, joint_names=names)
    inferred = infer(
        run, segments, epochs=int(epochs), initial_latents=np.asarray(start_codes, dtype=np.float32), progress=False
    )
    return np.asarray(inferred.latents, dtype=np.float64)


def relabel_by_inference(
    run, inputs: tuple, result: SegmentationResult, n_primitives: int, epochs: int, fade: float, random_state: int = 0
) -> SegmentationResult:
    """``result`` with each segment's code inferred (module docstring) and the segments
    labelled by clustering those codes; its nearest templates (``segment_templates``) and
    their codes are the warm start. ``inputs``: what
    :func:`~primspace.segmentation.synthesis.model_inputs` read for ``result``; ``fade``: the
    fade of the offset model ``result`` was found with
    (:data:`primspace.segmentation.synthesis.OFFSETS`)."""
    sequences, _, templates, codes, _ = inputs
    nearest = result.segment_templates
    if nearest is None:
        raise UserError(
            "the segments have no nearest templates (segment codes are inferred for synthesis and surprise)"
        )
    pieces = in_model_frame(sequences, result, templates, nearest, fade)
    names = (run.config or {}).get("data", {}).get("joint_names")
    inferred = infer_segment_codes(run, pieces, codes[nearest], epochs, names)
    labels, note = label_segments(inferred, n_primitives, random_state=random_state)
    sample, start, stop = result.segment_sample, result.segment_start, result.segment_stop
    result.segment_codes, result.segment_labels, result.note = inferred, labels, note
    result.step_labels = [
        np.repeat(labels[sample == i], (stop - start)[sample == i]) for i in range(len(result.step_labels))
    ]
    result.chosen = dict(result.chosen) | {"codes": f"inferred, {int(epochs)} epochs"}
    return result
