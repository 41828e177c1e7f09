"""Intra-primitive generalisation (paper, *Experimental Results*, Figs. "Convergence of the loss").

A random 20% of the samples (drawn per primitive, so every primitive is in both parts)
fit the decoder's weights θ and their codes Z; the other 80% get codes by inference with
θ frozen. Each latent initialisation (zero, random, projection, PCA) and latent size q is
one run of the grid ``intra/<init>-q<q>-s<seed>``. The figures are the paper's two
convergence plots: the loss over the fitting epochs and over the inference epochs.

The same runs also give the latent-space figure (first principal components of one
primitive's codes coloured by block position, the paper's "latent encoding" figure) and
generated-vs-recorded motions (Appendix B): their arrays are written as results
(``intra_latent.json`` / ``.npz``) and the figures drawn from them
(:mod:`primspace.experiments.figures`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from primspace.experiments import figures
from primspace.experiments.animations import write_animations
from primspace.experiments.appendix_a import run_appendix_a
from primspace.experiments.presets import ExperimentPreset
from primspace.experiments.probe import run_probe
from primspace.experiments.runs import (
    all_frame_losses,
    curves,
    fit_and_infer,
    focus_runs,
    load_codes,
    load_run_data,
    pack_grid_runs,
    shared_fits_last,
)
from primspace.experiments.sweep import GridPoint, complete_result
from primspace.experiments.workspace import ExperimentDir
from primspace.results.layout import LATENT_RESULTS, intra_key, intra_run_dir, phase_dir

__all__ = ["split_indices", "run_intra", "run_intra_point"]


def split_indices(labels: np.ndarray, train_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A random split with ``train_fraction`` of every label's samples in the first part.

    Each label keeps at least one sample on each side (when it has two or more).
    Returns sorted ``(train, eval)`` index arrays.
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 20]))
    train = []
    for label in np.unique(labels):
        members = np.flatnonzero(labels == label)
        rng.shuffle(members)
        k = int(round(train_fraction * len(members)))
        k = min(max(k, 1), max(len(members) - 1, 1))
        train.extend(members[:k].tolist())
    train = np.sort(np.array(train, dtype=np.int64))
    evaluation = np.setdiff1d(np.arange(len(labels)), train)
    return train, evaluation


def run_intra_point(
    run_dir: Path, data_path: str, train_idx: list, eval_idx: list, init: str, latent_dim: int, seed: int, preset: dict
) -> dict:
    """One grid point: fit θ and Z on the train part, then infer Z on the eval part.

    Both phases resume from their checkpoints if the point was interrupted.
    """
    preset_obj = ExperimentPreset.from_dict(preset)
    data, use_images = load_run_data(data_path, preset_obj)
    start = time.perf_counter()
    fitted, inferred, fit_seconds = fit_and_infer(
        run_dir, data, preset_obj, init, latent_dim, seed, train_idx, eval_idx, use_images
    )
    return {
        "init": init,
        "latent_dim": latent_dim,
        "seed": seed,
        "n_train": len(train_idx),
        "n_eval": len(eval_idx),
        "fit": curves(fitted.history),
        "infer": curves(inferred.history),
        "final": all_frame_losses(fitted, inferred, data) if use_images else None,
        # the fit's map from initial to fitted codes (projection / pca fits; calibrated uses projection's)
        "calibration": None if fitted.calibration is None else fitted.calibration.diagnostics(),
        "fit_seconds": round(fit_seconds, 2),
        "seconds": round(time.perf_counter() - start, 2),
    }


def run_intra(exp: ExperimentDir) -> dict:
    """Run (or finish) the intra-primitive grid; write results/intra.json, the arrays of
    the latent figures, the Appendix A check, and the figures."""
    preset = exp.preset
    data = exp.dataset()
    points, splits, packed = [], {}, []
    for seed in preset.seeds:
        train, evaluation = split_indices(data.labels, preset.train_fraction, seed)
        splits[str(seed)] = {"train": train.tolist(), "eval": evaluation.tolist()}
        for q in preset.latent_dims:
            for init in preset.inits:
                args = (str(exp.data_path), train.tolist(), evaluation.tolist(), init, q, seed, preset.to_dict())
                points.append(GridPoint(intra_key(init, q, seed), args))
                packed.append((intra_run_dir(exp.path, init, q, seed), init, q, seed, train, evaluation))
    with exp.stage("intra"):
        if exp.pack > 1:  # the unfinished runs trained packed first: the grid then finds them finished
            _pack_runs(exp, packed)
        grid = exp.grid(run_intra_point, shared_fits_last(points), "intra-primitive runs")
    _complete_final_losses(exp, grid.results)
    runs = [grid.results[p.key] | {"key": p.key} for p in points if p.key in grid.results]
    results = {
        "runs": runs,
        "failures": grid.failures,
        "splits": {s: {"n_train": len(v["train"]), "n_eval": len(v["eval"])} for s, v in splits.items()},
        "label_names": list(data.label_names),
    }
    exp.write_results("intra", results)
    if runs:
        _write_latent_results(exp, results)
        run_probe(exp, results)
    run_appendix_a(exp)
    figures.draw_intra(exp.path)
    write_animations(exp, results)
    return results


def _pack_runs(exp: ExperimentDir, points: list[tuple]) -> None:
    """The grid's unfinished fits and inferences trained packed, ``exp.pack`` at once
    (:func:`~primspace.experiments.runs.pack_grid_runs`), on the data as the grid's points load it."""
    data, use_images = load_run_data(str(exp.data_path), exp.preset)
    pack_grid_runs(points, data, exp.preset, use_images, exp.pack, progress=exp.progress)


def _complete_final_losses(exp: ExperimentDir, results: dict) -> None:
    """Give each finished run that lacks them (finished by primspace < 0.3.1) its
    :func:`all_frame_losses`, stored in its result once."""
    from primspace.train import load_run

    missing = [key for key, result in results.items() if "final" not in result]
    if not missing:
        return
    data, use_images = load_run_data(str(exp.data_path), exp.preset)
    for key in missing:
        r = results[key]
        fitted, inferred = (
            load_run(phase_dir(exp.path, r["init"], r["latent_dim"], r["seed"], p)) for p in ("fit", "infer")
        )
        final = all_frame_losses(fitted, inferred, data) if use_images else None
        results[key] = complete_result(exp.path, key, {"final": final})


# ----------------------------------------------------------- arrays of the figures


def _write_latent_results(exp: ExperimentDir, results: dict) -> None:
    """The codes of the focus runs (all samples) and one reconstructed eval sample of
    the primitives the paper shows: ``results/intra_latent.json`` and ``.npz``."""
    data = exp.dataset()
    q, seed, inits = focus_runs(exp, results)
    if not inits:
        return
    arrays: dict[str, np.ndarray] = {"labels": np.asarray(data.labels)}
    if data.params is not None:
        arrays["params"] = np.asarray(data.params)
    for init in inits:
        arrays[f"codes_{init}"] = load_codes(exp, init, q, seed)[0]
    init = "projection" if "projection" in inits else inits[0]
    recons = _reconstructions(exp, intra_run_dir(exp.path, init, q, seed) / "infer", arrays)
    meta = {
        "latent_dim": q,
        "seed": seed,
        "inits": inits,
        "label_names": list(data.label_names),
        # the paper's figure shows one primitive's codes: the first label that has samples
        "primitive": int(min((lab for lab in data.labels if lab >= 0), default=0)),
        "reconstructions": recons,
    }
    exp.write_results(LATENT_RESULTS, meta)
    exp.write_arrays(LATENT_RESULTS, arrays)


def _reconstructions(exp: ExperimentDir, infer_dir: Path, arrays: dict) -> list[dict]:
    """Appendix B: the first eval sample of grasp, push and circle_cw (else of the first
    three primitives), recorded and generated by ``infer_dir``; arrays go into ``arrays``."""
    from primspace.train import decode_keypoints, load_run, reconstruct

    data = exp.dataset()
    run = load_run(infer_dir)
    wanted = [n for n in ("grasp", "push", "circle_cw") if n in data.label_names] or list(data.label_names[:3])
    out = []
    for name in wanted:
        members = run.indices[data.labels[run.indices] == data.label_names.index(name)]
        if not members.size:
            continue
        sample = int(members[0])
        row = int(np.flatnonzero(run.indices == sample)[0])
        motor, frames = reconstruct(run, run.latents[row : row + 1])
        truth = data.subset([sample])
        arrays[f"recon_{name}_motor"] = np.asarray(truth.motor[0])
        arrays[f"recon_{name}_generated_motor"] = motor[0]
        if truth.images is not None:
            arrays[f"recon_{name}_images"] = np.asarray(truth.images)[0]
            if frames is not None:
                arrays[f"recon_{name}_generated_images"] = frames[0]
        points = decode_keypoints(run, run.latents[row : row + 1])
        if points is not None:  # (T, K, 2): what the generated frames were drawn through
            arrays[f"recon_{name}_generated_keypoints"] = points[0]
        out.append(
            {
                "name": name,
                "sample": sample,
                "primitive": name,
                "kind": run.kind,
                "init": run.init,
                "latent_dim": run.model_config.latent_dim,
                "joint_names": list(truth.joint_names),
                "dt": truth.dt,
            }
        )
    return out
