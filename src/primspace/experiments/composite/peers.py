"""The composite experiment's peers and upper bounds, per seed, on the runs' held-out demonstrations.

For each seed, on the same held-out demonstrations as that seed's runs (the split of
:func:`~primspace.experiments.composite.experiment.split_sequences`), their joints scaled as every run
scales them (:func:`~primspace.experiments.runs.experiment_scaler`) and cut to their valid
steps:

* ``methods``: every :data:`~primspace.segmentation.peers.PEERS` (ruptures change points,
  a Gaussian HMM), scored like primspace's segmentation (boundary F1 within one window,
  per-step labelling accuracy); peers whose package is missing are listed in ``missing``.
* ``bounds`` (:mod:`primspace.segmentation.bounds`): on the true segments, classifiers
  given the labels (cross-validated) and the clustering without labels, from the raw
  joints, the joints minus each segment's start pose, and each run's window codes
  (inferred, and untrained; their mean over the segment, and their trajectory through it).

A block is kept in ``results/composite.json`` under ``peers`` and reused by a rerun while
the seed's runs and the peers' version are the same and no peer was missing.
"""

from __future__ import annotations

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.runs import experiment_scaler

__all__ = ["peers_block", "score_found", "held_out_sequences"]


def held_out_sequences(data: MotionDataset, eval_idx) -> tuple[MotionDataset, list[np.ndarray]]:
    """The held-out part, and its joints scaled as the runs scale them, one ``(L_i, J)`` array each."""
    held = data.subset(np.asarray(eval_idx))
    scaled = experiment_scaler(data).transform(held.motor)
    return held, [np.asarray(scaled[i, : int(n)], dtype=np.float64) for i, n in enumerate(held.lengths)]


def score_found(held: MotionDataset, boundaries, step_labels, tolerance: int) -> dict:
    """Boundary precision / recall / F1 within ``tolerance`` steps (and within it of the
    transition, for data with transitions), per-step labelling accuracy, and the number of
    segments found (``step_labels``: one array per demonstration)."""
    from primspace.segmentation import boundaries_from_segments, boundary_f1, step_labelling_accuracy
    from primspace.sim.composite import transition_steps

    truth = boundaries_from_segments(held.step_segments, held.lengths)
    found = np.full(held.step_labels.shape, -1)
    for i, labels in enumerate(step_labels):
        found[i, : len(labels)] = labels
    transition = transition_steps(held)
    within = {"boundary_transition": boundary_f1(truth, boundaries, tolerance, extent=transition)} if transition else {}
    return within | {
        "boundary": boundary_f1(truth, boundaries, tolerance),
        "accuracy": step_labelling_accuracy(held.step_labels, found),
        "segments_found": int(sum(len(b) + 1 for b in boundaries)),
    }


def _methods(held: MotionDataset, seqs: list, n_primitives: int, window: int, seed: int) -> tuple[dict, dict]:
    from primspace.segmentation import boundaries_from_segments
    from primspace.segmentation.peers import run_peers

    counts = [len(b) for b in boundaries_from_segments(held.step_segments, held.lengths)]
    found, missing = run_peers(seqs, n_primitives, window, true_counts=counts, random_state=seed)
    methods = {
        name: score_found(held, r.boundaries, r.step_labels, window) | {"seconds": r.seconds, "note": r.note}
        for name, r in found.items()
    }
    return methods, missing


def _bound(features, segments, held: MotionDataset, n_primitives: int, seed: int) -> dict:
    from primspace.segmentation.bounds import clustered_bound, supervised_bound

    return {
        "supervised": supervised_bound(features, segments, n_primitives, random_state=seed),
        "clustered": clustered_bound(features, segments, held.step_labels, n_primitives, random_state=seed),
    }


def peers_block(data: MotionDataset, eval_idx, window: int, seed: int, codes: dict) -> dict:
    """The peers and bounds of one seed.

    Parameters
    ----------
    data : MotionDataset
        The experiment's data (with ``step_segments``, ``step_labels``, ``lengths``).
    eval_idx : array-like of int
        The seed's held-out demonstrations.
    window : int
        W: the boundary tolerance, the peers' fewest steps per segment and the code window.
    seed : int
        Seeds the peers' clustering, the HMM and the folds.
    codes : dict
        ``{init: (inferred, untrained, q)}``: each run's code rows of the held-out
        demonstrations (``(n_eval, K*q)``, in ``eval_idx`` order).

    Returns
    -------
    dict
        ``version`` (:data:`~primspace.segmentation.peers.PEERS_VERSION`), ``n_eval``,
        ``tolerance``, ``segments_true``, ``inits``, ``methods`` (name -> scores
        and seconds), ``missing`` (name -> why it did not run) and ``bounds`` (features ->
        ``supervised``, ``clustered``).
    """
    from primspace.segmentation.bounds import CODE_WINDOWS, segment_features, true_segments, window_code_features

    held, seqs = held_out_sequences(data, eval_idx)
    n_primitives = max(len(data.label_names), 1)
    segments = true_segments(held.step_segments, held.step_labels, held.lengths)
    methods, missing = _methods(held, seqs, n_primitives, window, seed)
    bounds = {
        kind: _bound(segment_features(seqs, segments, kind), segments, held, n_primitives, seed)
        for kind in ("raw", "relative")
    }
    for init, (inferred, untrained, q) in codes.items():
        for which, rows in (("codes", inferred), ("untrained codes", untrained)):
            seq = np.asarray(rows, dtype=np.float64).reshape(len(held), -1, q)
            if np.ptp(seq) == 0:
                continue  # e.g. untrained zero codes: nothing to read
            for how, n in (("", None), (" trajectory", CODE_WINDOWS)):
                feats = window_code_features(seq, segments, window, n)
                bounds[f"{which}{how} {init}"] = _bound(feats, segments, held, n_primitives, seed)
    from primspace.segmentation.peers import PEERS_VERSION

    return {
        "version": PEERS_VERSION,
        "n_eval": len(held),
        "tolerance": int(window),
        "segments_true": len(segments),
        "inits": sorted(codes),
        "methods": methods,
        "missing": missing,
        "bounds": bounds,
    }
