"""Boundaries by synthesis: the partition of a long demonstration into segments that a
single-primitive model explains best.

The paper's future work names the difficulty (shared/paper.tex, Summary and Discussion,
verbatim): "There are some challenges such as primitives might have different number of
timesteps and not clear borderline between primitives." A change-point detector on window codes (:mod:`primspace.segmentation`) or on
the joints looks for where the motion *changes*; inside a primitive it changes as much
(approach, contact, hold). This module asks instead where a *primitive* is: a model trained
on single primitives (one code per demonstration, ``T1`` steps) generates motions, and a
stretch of a long demonstration that is one primitive is explained by one of them.

1. **Templates.** The model's decoded fitted codes ``d(θ, z_j)`` (:func:`run_templates`),
   scaled by the run's scaler: what the model can generate, each with its code.
2. **Candidate segments.** Every ``[s, e)`` with ``s`` on a grid of ``grid`` steps and
   ``min_steps <= e - s <= max_steps`` (the last ending exactly at the demonstration's
   length), resampled to ``T1`` steps (:func:`primspace.data.resample`; a primitive's
   duration may differ from the model's).
3. **Cost of a candidate**: the mean squared distance to the nearest template, after the
   candidate's start offset is faded out over the first ``fade * T1`` steps: a primitive
   after the first starts where the one before ended, not where the model's primitives
   start (``x_t - y_t - c_t (x_0 - y_0)``, ``c_t = max(0, 1 - t / (fade T1))``). Two offset
   models (:data:`OFFSETS`): ``fade`` (:data:`FADE` = 0.35: the arm leaves the last pose for
   its own path, as the simulator's primitives go to the block) and ``translate`` (``c_t = 1``:
   the whole primitive is shifted to start where the last ended, as the chained LASA strokes
   are); ``auto`` (default) segments with both and keeps the one whose partition explains
   the demonstrations better (the lower mean cost per step): one offset parameter each, so
   the costs compare fairly, and no label is read.
4. **Partition**: dynamic programming over the candidates, minimising the sum of
   ``cost x duration`` (each step counted once); the duration bounds are the prior.
5. **Labels**: each segment's code is its nearest template's code; all segments' codes are
   clustered by the affine :class:`~primspace.cluster.LowRankSubspaceClustering`, τ chosen
   without labels (:func:`primspace.segmentation.label_segments`), where the paper's
   clustering works (single-primitive codes).

What it needs that the window-code method does not: a model of single primitives, trained
on demonstrations of one primitive each (the simulator's ``demo`` or ``paper`` data, LASA's
single strokes). A segment's code may instead be inferred with θ frozen
(``infer_epochs``, :mod:`primspace.segmentation.inferred`; measured not to help, so off by
default). What it does not do: learn the duration bounds (given, or 0.4 T1 .. 0.85 T1).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from primspace.data import MotionDataset, resample
from primspace.segmentation.inferred import relabel_by_inference
from primspace.segmentation.result import SegmentationResult, label_segments
from primspace.utils.errors import DataError, UserError

__all__ = [
    "FADE",
    "TRANSLATE",
    "OFFSETS",
    "by_offset",
    "with_codes",
    "DEFAULT_GRID",
    "SynthesisSettings",
    "run_templates",
    "candidate_segments",
    "candidate_costs",
    "best_partition",
    "demonstrations",
    "labelled_segments",
    "segment_by_templates",
    "segment_by_synthesis",
    "model_inputs",
]

#: Fraction of the model's steps over which a candidate's start offset is faded out.
FADE = 0.35
#: The start offset kept over the whole segment: a translated copy of a template.
TRANSLATE = float("inf")
#: The offset models by name (module docstring, 3); ``auto`` chooses between them.
OFFSETS = {"fade": FADE, "translate": TRANSLATE}
#: Steps between candidate segment starts.
DEFAULT_GRID = 2
_BLOCK = 1 << 24  # the most floats of one block of candidate-template differences


@dataclass(frozen=True)
class SynthesisSettings:
    """Where candidates start and how long they may last (steps of the long demonstrations)."""

    min_steps: int
    max_steps: int
    grid: int = DEFAULT_GRID
    fade: float = FADE

    @classmethod
    def for_model(
        cls, model_steps: int, min_steps=None, max_steps=None, grid: int = DEFAULT_GRID, fade: float = FADE
    ) -> SynthesisSettings:
        """Defaults from the model's ``T1``: 0.4 T1 to 0.85 T1 steps per primitive."""
        lo = int(round(0.4 * model_steps)) if min_steps is None else int(min_steps)
        hi = int(round(0.85 * model_steps)) if max_steps is None else int(max_steps)
        if not 2 <= lo <= hi:
            raise UserError(f"segment durations must satisfy 2 <= min_steps <= max_steps, got {lo} and {hi}")
        if int(grid) < 1 or not (0 < float(fade) <= 1 or float(fade) == TRANSLATE):
            raise UserError(f"grid must be >= 1 step and fade in (0, 1] or inf (translate), got {grid} and {fade}")
        return cls(lo, hi, int(grid), float(fade))

    def capped(self, length: int) -> SynthesisSettings:
        """These settings for data of ``length`` (T) steps: no segment outlasts the data, so a larger
        ``max_steps`` only made candidates to skip (a hang at 1e20) and surprise's memory grow."""
        return replace(self, max_steps=max(self.min_steps, min(self.max_steps, int(length))))


def run_templates(run) -> tuple[np.ndarray, np.ndarray]:
    """The decoded fitted codes of a single-primitive run, scaled: ``(M, T1, J)``, and the codes ``(M, q)``."""
    from primspace.train import reconstruct

    if run.model_config.code_window is not None:
        raise UserError(
            "synthesis needs a model of single primitives (one code per demonstration); this run "
            "was trained with --code-window"
        )
    motor, _ = reconstruct(run, images=False)
    return run.scaler.transform(np.asarray(motor, dtype=np.float64)), np.asarray(run.latents, dtype=np.float64)


def candidate_segments(length: int, settings: SynthesisSettings) -> np.ndarray:
    """``(K, 2)`` candidates ``[s, e)`` of a demonstration of ``length`` steps (module docstring, 2)."""
    keys = []
    for s in range(0, length - settings.min_steps + 1, settings.grid):
        ends = [
            s + d
            for d in range(settings.min_steps, settings.max_steps + 1, settings.grid)
            if s + d <= length - settings.min_steps
        ]
        if settings.min_steps <= length - s <= settings.max_steps:
            ends.append(length)
        keys.extend((s, e) for e in ends)
    return np.asarray(keys, dtype=np.int64).reshape(-1, 2)


def candidate_costs(x: np.ndarray, keys: np.ndarray, templates: np.ndarray, fade: float = FADE):
    """Each candidate's cost and nearest template (module docstring, 3).

    Parameters
    ----------
    x : ndarray (L, J)
        One demonstration's valid steps, scaled as the templates.
    keys : ndarray (K, 2)
        Candidates ``[s, e)``.
    templates : ndarray (M, T1, J)

    Returns
    -------
    (cost (K,), nearest (K,) int)
    """
    m, t1, _ = templates.shape
    ramp = np.clip(1.0 - np.arange(t1) / (fade * t1), 0.0, 1.0)[:, None]
    candidates = resample([x[s:e] for s, e in keys], t1)  # (K, T1, J)
    cost, nearest = np.full(len(keys), np.inf), np.zeros(len(keys), dtype=np.int64)
    step = max(1, _BLOCK // max(1, m * templates[0].size))
    shaped = templates - ramp * templates[:, :1]  # y_t - c_t y_0
    for a in range(0, len(candidates), step):
        c = candidates[a : a + step]
        diff = (c - ramp * c[:, :1])[:, None] - shaped[None]  # (k, M, T1, J)
        err = np.mean(diff * diff, axis=(2, 3))
        nearest[a : a + step] = err.argmin(axis=1)
        cost[a : a + step] = err[np.arange(len(c)), nearest[a : a + step]]
    return cost, nearest


def best_partition(length: int, keys: np.ndarray, cost: np.ndarray) -> list[int]:
    """The candidates (indices into ``keys``) that tile ``[0, length)`` at the least total
    ``cost x duration`` (module docstring, 4); empty when no tiling exists."""
    best = {0: (0.0, -1)}  # end step -> (least total, the candidate ending there)
    order = np.lexsort((keys[:, 0], keys[:, 1]))
    for k in order:
        s, e = int(keys[k, 0]), int(keys[k, 1])
        if s in best:
            total = best[s][0] + float(cost[k]) * (e - s)
            if e not in best or total < best[e][0]:
                best[e] = (total, int(k))
    if length not in best:
        return []
    chosen, end = [], length
    while end > 0:
        k = best[end][1]
        chosen.append(k)
        end = int(keys[k, 0])
    return chosen[::-1]


def demonstrations(sequences, lengths, settings: SynthesisSettings):
    """``(i, length, x)`` per demonstration: its valid steps ``x`` ``(length, J)`` as float64;
    refuses one shorter than a segment's fewest steps."""
    for i, length in enumerate(np.asarray(lengths, dtype=np.int64)):
        length = int(length)
        if length < settings.min_steps:
            raise UserError(
                f"demonstration {i} has {length} steps, fewer than a segment's least ({settings.min_steps})"
            )
        yield i, length, np.asarray(sequences[i][:length], dtype=np.float64)


def segment_by_templates(
    sequences,
    lengths,
    templates: np.ndarray,
    codes: np.ndarray,
    n_primitives: int,
    settings: SynthesisSettings,
    random_state: int = 0,
) -> SegmentationResult:
    """Segment scaled demonstrations ``sequences`` ``(N, T, J)`` (valid steps ``lengths``) by
    the ``templates`` and label the segments by clustering their templates' ``codes``."""
    segments, costs = [], []
    for i, length, x in demonstrations(sequences, lengths, settings):
        keys = candidate_segments(length, settings)
        cost, nearest = candidate_costs(x, keys, templates, settings.fade)
        chosen = best_partition(length, keys, cost)
        if not chosen:  # no tiling within the bounds: the whole demonstration is one segment, scored as one
            keys = np.array([[0, length]])
            cost, nearest = candidate_costs(x, keys, templates, settings.fade)
            chosen = [0]
        segments.append([(i, int(keys[k, 0]), int(keys[k, 1]), int(nearest[k])) for k in chosen])
        costs.append(float(np.sum(cost[chosen] * (keys[chosen, 1] - keys[chosen, 0]))) / length)
    return labelled_segments(segments, codes, n_primitives, np.asarray(costs), random_state)


def labelled_segments(
    segments: list, codes: np.ndarray, n_primitives: int, penalties: np.ndarray, random_state: int = 0
) -> SegmentationResult:
    """The result of a partition: ``segments`` holds per demonstration its ``(sample, start,
    stop, template)`` rows in time order; each segment's code is its template's row of
    ``codes``, and all are clustered by :func:`~primspace.segmentation.label_segments`
    (module docstring, 5). Shared by synthesis and :mod:`primspace.segmentation.surprise`."""
    rows = np.array([row for seq in segments for row in seq], dtype=np.int64)
    seg_codes = codes[rows[:, 3]]
    labels, note = label_segments(seg_codes, n_primitives, random_state=random_state)
    sample, start, stop = rows[:, 0], rows[:, 1], rows[:, 2]
    return SegmentationResult(
        boundaries=[start[sample == i][1:] for i in range(len(segments))],
        step_labels=[np.repeat(labels[sample == i], (stop - start)[sample == i]) for i in range(len(segments))],
        segment_codes=seg_codes,
        segment_sample=sample,
        segment_start=start,
        segment_stop=stop,
        segment_labels=labels,
        penalties=np.asarray(penalties),
        window=1,
        note=note,
        segment_templates=rows[:, 3],
    )


def segment_by_synthesis(
    run,
    data: MotionDataset,
    n_primitives: int,
    *,
    min_steps=None,
    max_steps=None,
    grid: int = DEFAULT_GRID,
    offset: str = "auto",
    infer_epochs: int = 0,
    random_state: int = 0,
) -> SegmentationResult:
    """Segment the long demonstrations ``data`` with a single-primitive ``run`` (module docstring).

    ``offset``: ``fade``, ``translate`` or ``auto`` (module docstring, 3; ``chosen["offset"]``
    of the result names the one used). ``penalties`` of the result holds each
    demonstration's mean cost per step (how well the model explains it). The data's joints
    must be the run's (names and order). ``infer_epochs > 0``: the segments' codes are
    inferred with θ frozen and clustered (:mod:`primspace.segmentation.inferred`) instead of
    their nearest templates' codes.
    """
    inputs = model_inputs(run, data, min_steps, max_steps, grid)
    sequences, lengths, templates, codes, settings = inputs

    def segment(fade: float) -> SegmentationResult:
        return segment_by_templates(
            sequences, lengths, templates, codes, n_primitives, replace(settings, fade=fade), random_state
        )

    return with_codes(run, inputs, by_offset(segment, offset), n_primitives, infer_epochs, random_state)


def with_codes(
    run, inputs: tuple, result: SegmentationResult, n_primitives: int, infer_epochs: int, random_state: int = 0
) -> SegmentationResult:
    """``result`` as it is (segment codes: the nearest templates'), or with the codes
    inferred for ``infer_epochs > 0`` epochs and the segments labelled by them
    (``inputs``: :func:`model_inputs`'s, read once)."""
    if int(infer_epochs) <= 0:
        return result
    fade = OFFSETS[result.chosen.get("offset", "fade")]
    return relabel_by_inference(run, inputs, result, n_primitives, int(infer_epochs), fade, random_state)


def by_offset(segment, offset: str) -> SegmentationResult:
    """``segment(fade)`` with the offset model ``offset``, or with each and the one whose
    demonstrations' mean cost per step (``penalties``) is lower (``auto``); the result's
    ``chosen["offset"]`` names it (and ``chosen["costs"]`` both costs under ``auto``)."""
    if offset not in (*OFFSETS, "auto"):
        raise UserError(f"offset must be one of {', '.join([*OFFSETS, 'auto'])}, got {offset!r}")
    names = list(OFFSETS) if offset == "auto" else [offset]
    results = {name: segment(OFFSETS[name]) for name in names}
    costs = {name: float(np.mean(r.penalties)) for name, r in results.items()}
    best = min(costs, key=costs.get)
    chosen = results[best]
    chosen.chosen = dict(chosen.chosen) | {"offset": best} | ({"costs": costs} if len(costs) > 1 else {})
    return chosen


def model_inputs(
    run, data: MotionDataset, min_steps=None, max_steps=None, grid: int = DEFAULT_GRID, fade: float = FADE
):
    """What a segmentation by a single-primitive ``run`` reads: the data's joints scaled as
    the run's ``(N, T, J)``, the valid lengths, the templates and codes of
    :func:`run_templates`, and the :class:`SynthesisSettings` (``max_steps`` capped at the
    data's T). Refuses data whose joints are not the run's (names and order)."""
    names = run.config.get("data", {}).get("joint_names") if run.config else None
    if data.n_joints != run.model_config.n_joints or (names is not None and list(data.joint_names) != list(names)):
        raise UserError(
            f"the data's joints {list(data.joint_names)} are not the run's "
            f"{names if names is not None else f'{run.model_config.n_joints} joints'}"
        )
    templates, codes = run_templates(run)
    settings = SynthesisSettings.for_model(templates.shape[1], min_steps, max_steps, grid, fade)
    settings = settings.capped(int(data.length))
    lengths = data.valid_lengths
    short = np.flatnonzero(np.asarray(lengths) < settings.min_steps)
    if short.size:  # named by the file, field and sample, as every data error
        i = int(short[0])
        raise DataError(
            f"{int(lengths[i])} steps, fewer than a segment's least ({settings.min_steps}, --min-steps)",
            path=data.path,
            field="lengths",
            index=i,
        )
    sequences = run.scaler.transform(np.asarray(data.motor, dtype=np.float64))
    return sequences, np.asarray(lengths, dtype=np.int64), templates, codes, settings
