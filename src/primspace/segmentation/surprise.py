"""Boundaries from prediction error: a single-primitive model follows a long demonstration
step by step, and a boundary is where its prediction of the next steps fails.

The paper's Background describes predictive coding (shared/paper.tex, verbatim):
"Predicted information is compared with the real one and internal state is corrected based
on the error." Here the internal state is the model's hypothesis of the primitive under
way, and the error is that of its prediction of the next steps. Inside a primitive the
model predicts well; when the primitive ends and another begins, the motion leaves every
continuation the model can generate and the error jumps: the model is *surprised*.

1. **Hypotheses** (:func:`hypotheses`): each decoded fitted code of the model (a template,
   :func:`primspace.segmentation.synthesis.run_templates`) resampled to every duration
   ``d`` of the segment bounds (a primitive's duration in the long demonstration need not be
   the model's ``T1``), held at its last pose after its end.
2. **Following a segment** (:func:`follow`): from the current segment's start ``s``, at
   each step ``s + k`` the hypothesis whose first ``k`` steps are nearest the observed ones
   (mean squared distance, the start offset faded out or kept as synthesis's offset model
   says) predicts the
   next ``horizon`` steps; the **surprise** at ``k`` is the mean squared error of that
   prediction once those steps have arrived (a delay of ``horizon`` steps). This is the
   fast form of the online inference of :meth:`primspace.predict.MixturePredictor.predict_online`: the
   posterior over the model's codes given the prefix, taken at its mode, with the
   duration as one more unknown.
3. **Boundaries**: the first ``k >= min_steps`` whose surprise exceeds the threshold ends
   the segment at ``s + k`` (and only where the rest can still hold a segment); without one
   by ``max_steps``, the segment ends where the surprise was largest. The next segment
   starts there and the following restarts (the inference window restarts after each
   boundary).
4. **The threshold, chosen without labels** (:func:`surprise_threshold`): the model is run
   on its own primitives, each template followed (resampled to durations spread over the
   bounds) by the hypotheses of the *other* templates; the threshold is the
   :data:`QUANTILE` quantile of the surprise inside them at the steps where a boundary may
   fall (``k >= min_steps``), times :data:`MARGIN`: how surprised the model is by
   primitives like those it knows, before they end. (A first version also counted the
   first steps, where a prefix of one or two steps fits many hypotheses; its threshold was
   set by that ambiguity: docs/sequences.md gives both measurements.)
5. **Labels**: as synthesis (:func:`primspace.segmentation.synthesis.labelled_segments`):
   each found segment's code is the code of the template nearest it (resampled to ``T1``),
   clustered by affine LRSC with τ chosen without labels.

Greedy and causal, unlike synthesis (which sees a whole demonstration and partitions it by
dynamic programming): surprise decides each boundary from the steps up to ``horizon`` past
it, so it can run as the motion arrives.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from primspace.data import MotionDataset, resample
from primspace.segmentation.result import SegmentationResult
from primspace.segmentation.synthesis import (
    DEFAULT_GRID,
    FADE,
    SynthesisSettings,
    by_offset,
    candidate_costs,
    demonstrations,
    labelled_segments,
    model_inputs,
    with_codes,
)
from primspace.utils.errors import UserError

__all__ = [
    "HORIZON",
    "QUANTILE",
    "MARGIN",
    "Hypotheses",
    "hypotheses",
    "follow",
    "surprise_threshold",
    "segment_by_surprise_templates",
    "segment_by_surprise",
]

#: Steps ahead the model predicts; the surprise is the mean squared error over them.
HORIZON = 3
#: Quantile of the model's surprise inside its own primitives that sets the threshold...
QUANTILE = 0.99
#: ... times this margin.
MARGIN = 2.0


@dataclass(frozen=True)
class Hypotheses:
    """Templates resampled to every duration: ``motion`` ``(H, D, J)`` (held at the last pose
    after ``duration``), ``duration`` ``(H,)``, ``template`` ``(H,)`` (index into the templates)."""

    motion: np.ndarray
    duration: np.ndarray
    template: np.ndarray

    def without(self, template: int) -> Hypotheses:
        keep = self.template != template
        return Hypotheses(self.motion[keep], self.duration[keep], self.template[keep])


def hypotheses(templates: np.ndarray, settings: SynthesisSettings) -> Hypotheses:
    """Every template ``(M, T1, J)`` at every duration of ``settings`` (module docstring, 1)."""
    m, _, j = templates.shape
    durations = np.arange(settings.min_steps, settings.max_steps + 1, settings.grid)
    longest = int(durations[-1]) + HORIZON
    motion = np.empty((m * len(durations), longest, j))
    for a, d in enumerate(durations):
        block = resample(templates, int(d))
        motion[a * m : (a + 1) * m, :d] = block
        motion[a * m : (a + 1) * m, d:] = block[:, -1:]
    return Hypotheses(motion, np.repeat(durations, m), np.tile(np.arange(m), len(durations)))


def follow(x: np.ndarray, hyp: Hypotheses, fade: float = FADE) -> np.ndarray:
    """The surprise at each step of a segment starting at ``x[0]`` (module docstring, 2).

    Parameters
    ----------
    x : ndarray (n, J)
        The demonstration from the segment's start (scaled as the templates).
    hyp : Hypotheses

    Returns
    -------
    ndarray (n,)
        ``surprise[k]``: mean squared error over steps ``k .. k + HORIZON - 1`` of the
        prediction by the hypothesis nearest steps ``0 .. k - 1``; NaN where ``k < 1`` or
        fewer than ``HORIZON`` steps follow.
    """
    n = min(len(x), hyp.motion.shape[1])
    steps = np.arange(n)
    ramp = np.clip(1.0 - steps[None, :] / (fade * hyp.duration[:, None]), 0.0, 1.0)  # (H, n)
    offset = x[0][None, :] - hyp.motion[:, 0]  # (H, J)
    diff = x[None, :n] - hyp.motion[:, :n] - ramp[:, :, None] * offset[:, None, :]
    err = np.mean(diff * diff, axis=2)  # (H, n)
    prefix = np.cumsum(err, axis=1) / (steps + 1)  # mean over steps 0..k
    ahead = np.cumsum(np.pad(err, ((0, 0), (1, 0))), axis=1)
    out = np.full(len(x), np.nan)
    for k in range(1, n - HORIZON + 1):
        h = int(np.argmin(prefix[:, k - 1]))
        out[k] = (ahead[h, k + HORIZON] - ahead[h, k]) / HORIZON
    return out


def _cut(surprise: np.ndarray, threshold: float, settings: SynthesisSettings, rest: int) -> int:
    """Steps of the segment whose surprise is ``surprise`` (module docstring, 3); ``rest``:
    the steps left in the demonstration from the segment's start."""
    if rest <= settings.max_steps and not np.any(
        surprise[settings.min_steps : rest - settings.min_steps + 1] > threshold
    ):
        return rest
    last = min(settings.max_steps, rest - settings.min_steps)
    span = surprise[settings.min_steps : last + 1]
    if len(span) == 0 or not np.isfinite(span).any():
        return min(rest, max(settings.min_steps, last))
    above = np.flatnonzero(span > threshold)
    return settings.min_steps + int(above[0] if len(above) else np.nanargmax(span))


def surprise_threshold(
    templates: np.ndarray, settings: SynthesisSettings, quantile: float = QUANTILE, margin: float = MARGIN
) -> float:
    """The threshold chosen without labels (module docstring, 4): each template, at
    durations spread over the bounds, followed by the other templates' hypotheses."""
    if len(templates) < 2:
        raise UserError("the surprise threshold needs a model with at least 2 fitted codes")
    hyp = hypotheses(templates, settings)
    durations = np.unique(np.linspace(settings.min_steps + HORIZON + 1, settings.max_steps, 3).round().astype(int))
    inside = []
    for j in range(len(templates)):
        others = hyp.without(j)
        for d in durations:
            own = resample(templates[j], int(d))
            inside.append(follow(own, others, settings.fade)[settings.min_steps : int(d) - HORIZON + 1])
    values = np.concatenate(inside)
    return float(margin * np.quantile(values[np.isfinite(values)], quantile))


def segment_by_surprise_templates(
    sequences,
    lengths,
    templates: np.ndarray,
    codes: np.ndarray,
    n_primitives: int,
    settings: SynthesisSettings,
    threshold: float | None = None,
    random_state: int = 0,
) -> SegmentationResult:
    """Segment scaled demonstrations ``(N, T, J)`` (valid ``lengths``) where the templates'
    prediction fails; label the segments by their nearest templates' codes. ``penalties``
    of the result holds each demonstration's mean cost per step (as synthesis's: how well
    the segments found are explained), ``chosen["threshold"]`` the threshold."""
    threshold = surprise_threshold(templates, settings) if threshold is None else float(threshold)
    hyp = hypotheses(templates, settings)
    segments, costs = [], []
    for i, length, x in demonstrations(sequences, lengths, settings):
        keys, s = [], 0
        while s < length:
            e = s + _cut(follow(x[s:], hyp, settings.fade), threshold, settings, length - s)
            keys.append((s, e))
            s = e
        keys = np.asarray(keys, dtype=np.int64)
        cost, nearest = candidate_costs(x, keys, templates, settings.fade)
        segments.append([(i, int(a), int(b), int(t)) for (a, b), t in zip(keys, nearest)])
        costs.append(float(np.sum(cost * (keys[:, 1] - keys[:, 0]))) / length)
    result = labelled_segments(segments, codes, n_primitives, np.asarray(costs), random_state)
    result.chosen = {"threshold": threshold}
    return result


def segment_by_surprise(
    run,
    data: MotionDataset,
    n_primitives: int,
    *,
    min_steps=None,
    max_steps=None,
    grid: int = DEFAULT_GRID,
    offset: str = "auto",
    threshold: float | None = None,
    infer_epochs: int = 0,
    random_state: int = 0,
) -> SegmentationResult:
    """Segment the long demonstrations ``data`` where a single-primitive ``run``'s prediction
    fails (module docstring). ``offset`` as :func:`~primspace.segmentation.synthesis.segment_by_synthesis`
    (``auto``: the offset model whose segments are explained better), and ``infer_epochs``
    (segment codes inferred with θ frozen). The data's joints must be the run's (names and order)."""
    inputs = model_inputs(run, data, min_steps, max_steps, grid)
    sequences, lengths, templates, codes, settings = inputs

    def segment(fade: float) -> SegmentationResult:
        return segment_by_surprise_templates(
            sequences, lengths, templates, codes, n_primitives, replace(settings, fade=fade), threshold, random_state
        )

    return with_codes(run, inputs, by_offset(segment, offset), n_primitives, infer_epochs, random_state)
