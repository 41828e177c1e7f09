"""Long demonstrations made of several primitives: a sequence of codes per demonstration.

The paper's next step (*Summary and Discussion*): "To model more complex behaviours
composed of many consecutive primitives, instead of using a single latent vector
$\\mathbf{z}$ of fixed dimension usually a sequence of such vectors is used." Each run of
the grid ``composite/<init>-q<q>-s<seed>`` fits the decoder (one code per window of
``model.code_window`` steps, :class:`~primspace.model.decoder.MTRNNDecoder`) and the codes of a
random ``train_fraction`` of the long demonstrations, then infers the codes of the others
with θ frozen, starting from the convolutional random projection (``projection``), zero,
random or PCA codes. The inferred code sequences are then segmented and labelled without
labels (:mod:`primspace.segmentation`) and scored against the simulator's ground truth:
boundary F1 within one window, per-step labelling accuracy (Hungarian) and the held-out
loss. The untrained codes of each init are segmented and scored too (the projection's
``P m`` windows need no training at all).

Beside them, per seed on the same held-out demonstrations, the peers (ruptures change
points, a Gaussian HMM, on the scaled joints) and the upper bounds (classifiers given the
labels, and clustering given the true boundaries; :mod:`primspace.experiments.composite.peers`).

Per seed too, a model of single primitives segments the same held-out demonstrations by
synthesis and by surprise (:mod:`primspace.experiments.composite.primitives`).

Results: ``results/composite.json`` (one row per run, ``peers``: a block per seed, and
``primitives``: a row per seed) and
``results/composite.npz`` (the code sequences and boundaries of a few held-out
demonstrations of the first seed's runs, for the timeline figure).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments import figures
from primspace.experiments.composite.primitives import run_primitives
from primspace.experiments.composite.timeline import TIMELINE_SAMPLES, padded_boundaries
from primspace.experiments.presets import ExperimentPreset
from primspace.experiments.runs import curves, fit_and_infer, load_run_data, shared_fits_last
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import run_dir_of
from primspace.utils.errors import UserError

__all__ = ["composite_key", "split_sequences", "segment_codes", "run_composite_point", "run_composite"]


def composite_key(init: str, latent_dim: int, seed: int) -> str:
    """The grid key (and ``OUT/runs/`` folder) of one composite run."""
    return f"composite/{init}-q{latent_dim}-s{seed}"


def split_sequences(n: int, train_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random ``train_fraction`` of ``n`` demonstrations (at least one on each side),
    sorted ``(train, eval)`` index arrays."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 15]))
    order = rng.permutation(n)
    k = min(max(int(round(train_fraction * n)), 1), max(n - 1, 1))
    return np.sort(order[:k]), np.sort(order[k:])


def segment_codes(
    codes: np.ndarray,
    data: MotionDataset,
    window: int,
    latent_dim: int,
    *,
    tolerance: int | None = None,
    n_primitives: int | None = None,
):
    """Segment and label code sequences; score them when ``data`` has the ground truth.

    Parameters
    ----------
    codes : ndarray (n, K*q)
        One row per demonstration of ``data`` (a run's ``latents``), window-major.
    data : MotionDataset
        The same demonstrations, with ``lengths`` (and, to score, ``step_segments`` and
        ``step_labels``).
    window, latent_dim : int
        W and q of the run.
    tolerance : int, optional
        Steps within which a found boundary matches a true one (default: one window, W).
    n_primitives : int, optional
        Clusters of segment codes (default: the data's label names).

    Returns
    -------
    (SegmentationResult, dict)
        The segmentation and its scores: ``boundary`` (precision, recall, f1, tp, fp, fn),
        ``accuracy`` (per step), ``tolerance``, ``segments_true``, ``segments_found``.
    """
    from primspace.segmentation import segment_sequences, segmentation_scores
    from primspace.sim.composite import transition_steps

    lengths = data.valid_lengths
    sequences = np.asarray(codes, dtype=np.float64).reshape(len(data), -1, latent_dim)
    n_primitives = n_primitives or max(len(data.label_names), 1)
    result = segment_sequences(sequences, window, lengths, n_primitives)
    tol = window if tolerance is None else int(tolerance)
    if tol < 0:
        raise UserError(f"tolerance (--tolerance) must be at least 0 steps, got {tol}")
    given = (
        {}
        if data.step_segments is None
        else {"accuracy_true_boundaries": _accuracy_given_boundaries(sequences, data, window, n_primitives)}
    )
    return result, segmentation_scores(result, data, tol, transition_steps(data), **given)


def _accuracy_given_boundaries(
    sequences: np.ndarray, data: MotionDataset, window: int, n_primitives: int
) -> float | None:
    """Per-step labelling accuracy when the true boundaries are given: each true segment's
    code is the mean of the windows it touches, clustered as :func:`segment_codes` does.
    Separates labelling from finding the boundaries."""
    from primspace.segmentation import label_segments, step_labelling_accuracy

    codes, owners = [], []
    for i, segments in enumerate(data.step_segments):
        valid = segments[segments >= 0]
        for s in np.unique(valid):
            steps = np.flatnonzero(segments == s)
            codes.append(sequences[i, steps[0] // window : steps[-1] // window + 1].mean(axis=0))
            owners.append((i, steps))
    labels, note = label_segments(np.asarray(codes), n_primitives)
    if note is not None:
        return None  # nothing to cluster (e.g. untrained zero codes)
    found = np.full(data.step_labels.shape, -1)
    for (i, steps), label in zip(owners, labels):
        found[i, steps] = label
    return step_labelling_accuracy(data.step_labels, found)


def run_composite_point(
    run_dir: Path, data_path: str, train_idx: list, eval_idx: list, init: str, latent_dim: int, seed: int, preset: dict
) -> dict:
    """One grid point: fit θ and the code sequences on the train part, infer the eval
    part's code sequences with θ frozen, segment and score them (and the untrained ones)."""
    preset_obj = ExperimentPreset.from_dict(preset)
    data, use_images = load_run_data(data_path, preset_obj)
    start = time.perf_counter()
    fitted, inferred, _ = fit_and_infer(
        run_dir, data, preset_obj, init, latent_dim, seed, train_idx, eval_idx, use_images
    )
    held_out = data.subset(np.asarray(eval_idx))
    window = preset_obj.model.code_window
    _, scores = segment_codes(inferred.latents, held_out, window, latent_dim)
    _, untrained = segment_codes(inferred.initial_latents, held_out, window, latent_dim)
    return {
        "init": init,
        "latent_dim": latent_dim,
        "seed": seed,
        "window": window,
        "n_train": len(train_idx),
        "n_eval": len(eval_idx),
        "fit": curves(fitted.history),
        "infer": curves(inferred.history),
        "segmentation": scores,
        "segmentation_untrained": untrained,
        "seconds": round(time.perf_counter() - start, 2),
    }


def run_composite(exp: ExperimentDir) -> dict:
    """Run (or finish) the composite grid; write results/composite.json, the timeline
    arrays and the figures."""
    preset = exp.preset
    if preset.model.code_window is None:
        raise UserError(f"preset {preset.name!r} has no code window (model.code_window); use --preset demo or paper")
    data = exp.dataset()
    if data.step_segments is None:
        raise UserError(
            f"{exp.data_path}: the composite experiment needs long demonstrations with step_segments "
            "(primspace generate --preset composite-demo)"
        )
    points, splits, held_out = [], {}, {}
    for seed in preset.seeds:
        train, evaluation = split_sequences(len(data), preset.train_fraction, seed)
        splits[str(seed)] = {"n_train": len(train), "n_eval": len(evaluation)}
        held_out[seed] = evaluation.tolist()
        for q in preset.latent_dims:
            for init in preset.inits:
                args = (str(exp.data_path), train.tolist(), evaluation.tolist(), init, q, seed, preset.to_dict())
                points.append(GridPoint(composite_key(init, q, seed), args))
    with exp.stage("composite"):
        grid = exp.grid(run_composite_point, shared_fits_last(points), "composite runs")
    runs = _rescored(exp, [grid.results[p.key] | {"key": p.key} for p in points if p.key in grid.results])
    previous = exp.read_results("composite") or {}
    with exp.stage("composite peers"):
        peers = _peers_by_seed(exp, data, runs, previous.get("peers", {}))
    results = {
        "runs": runs,
        "failures": grid.failures,
        "splits": splits,
        "window": preset.model.code_window,
        "label_names": list(data.label_names),
        "peers": peers,
        "primitives": run_primitives(exp, held_out),
    }
    exp.write_results("composite", results)
    if runs:
        _write_timelines(exp, runs)
    figures.draw_composite(exp.path)
    return results


def _rescored(exp: ExperimentDir, runs: list[dict]) -> list[dict]:
    """Runs scored before 0.8 lack the F1 within the transition: segment their stored codes
    again (the same segmentation, scored anew) and complete their stored results."""
    from primspace.experiments.sweep import complete_result
    from primspace.sim.composite import transition_steps
    from primspace.train import load_run

    data = exp.dataset()
    if not transition_steps(data):
        return runs
    out = []
    for r in runs:
        if "boundary_transition" not in r["segmentation"]:
            run = load_run(run_dir_of(exp.path, r["key"]) / "infer")
            held = data.subset(run.indices)
            extra = {
                "segmentation": segment_codes(run.latents, held, r["window"], r["latent_dim"])[1],
                "segmentation_untrained": segment_codes(run.initial_latents, held, r["window"], r["latent_dim"])[1],
            }
            r = complete_result(exp.path, r["key"], extra) | {"key": r["key"]}
        out.append(r)
    return out


def _peers_by_seed(exp: ExperimentDir, data: MotionDataset, runs: list[dict], previous: dict) -> dict:
    """Per seed with finished runs, :func:`~primspace.experiments.composite.peers.peers_block`
    on its held-out demonstrations, with every run's codes; a stored block is reused while
    the seed's runs and the peers' version are the same and no peer was missing."""
    from primspace.experiments.composite.peers import peers_block
    from primspace.segmentation.peers import PEERS, PEERS_VERSION
    from primspace.train import load_run

    out = {}
    for seed in exp.preset.seeds:
        mine = [r for r in runs if r["seed"] == seed]
        if not mine:
            continue
        names = sorted(f"{r['init']}-q{r['latent_dim']}" for r in mine)
        old = previous.get(str(seed))
        same = old and old.get("inits") == names and old.get("version") == PEERS_VERSION
        if same and set(old["methods"]) == set(PEERS):
            out[str(seed)] = old
            continue
        codes, held = {}, None
        for r in mine:
            run = load_run(run_dir_of(exp.path, r["key"]) / "infer")
            held = run.indices if held is None else held
            codes[f"{r['init']}-q{r['latent_dim']}"] = (run.latents, run.initial_latents, r["latent_dim"])
        out[str(seed)] = peers_block(data, held, mine[0]["window"], seed, codes)
    return out


def _write_timelines(exp: ExperimentDir, runs: list[dict]) -> None:
    """The code sequences, true and found boundaries and labels of the first
    :data:`~primspace.experiments.composite.timeline.TIMELINE_SAMPLES` held-out
    demonstrations, per init of the first seed and q. The found ones are those of the scored
    segmentation (all held-out demonstrations at once: one noise level, one clustering), sliced."""
    from primspace.train import load_run

    data = exp.dataset()
    first = runs[0]
    chosen = [r for r in runs if (r["seed"], r["latent_dim"]) == (first["seed"], first["latent_dim"])]
    held_out = data.subset(load_run(run_dir_of(exp.path, first["key"]) / "infer").indices)
    n = min(TIMELINE_SAMPLES, len(held_out))
    arrays: dict[str, np.ndarray] = {}
    for r in chosen:
        run = load_run(run_dir_of(exp.path, r["key"]) / "infer")
        result, _ = segment_codes(run.latents, held_out, r["window"], r["latent_dim"])
        arrays[f"codes_{r['init']}"] = run.latents[:n].reshape(n, -1, r["latent_dim"])
        arrays[f"found_{r['init']}"] = result.padded_step_labels(data.length)[:n]
        arrays[f"bounds_{r['init']}"] = padded_boundaries(result.boundaries[:n])
    arrays |= {
        "samples": run.indices[:n],
        "lengths": held_out.lengths[:n],
        "step_labels": held_out.step_labels[:n],
        "step_segments": held_out.step_segments[:n],
    }
    exp.write_arrays("composite", arrays)
    exp.write_results(
        "composite_timeline",
        {
            "inits": [r["init"] for r in chosen],
            "window": first["window"],
            "latent_dim": first["latent_dim"],
            "seed": first["seed"],
            "label_names": list(data.label_names),
        },
    )
